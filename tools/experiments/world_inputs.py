"""Issue 25's third ablation: world-space position and normal as network inputs beside the view-space buffers.

Usage:
  python tools/experiments/world_inputs.py derive SRC OUT --source-width 228 [--center 0,1,0 --half 1.2]
  python tools/experiments/world_inputs.py train [--like BASE_RUN] -- --data OUT --out RUN [TRAIN_ARGS...]
  python tools/experiments/world_inputs.py score --data OUT --split test --object-albedo 0.8
         --run base=RUN_A --run world=RUN_B [--out JSON]

derive: a copy of a crops dataset (`crop_dataset.py`) with two more channels, ``world_pos`` (the surface's
world position, (p - center) / half, clipped to [-1, 1]; 0 on the background) and ``world_normal`` (the view
normal turned into world space; 0 on the background), reconstructed from each frame's stored depth, normal,
camera and crop offset exactly as direct.glsl reconstructs a surface (`pixel_rays_view` of the source frame's
width, the crop's columns and rows). A per-scene network can then key its indirect light on where a surface
is, as a radiance cache does. Resumable: frames already written (checked) are kept.

train: `diviewer train` in this process with the generator taking 16 channels: the 10 encoded inputs of
`split_batch` followed by the 6 world channels as stored (square frames only: no aspect crops, no padding).
``--like BASE_RUN`` takes every setting from the base run's checkpoint (as a recipe file in RUN), so that the
two differ in the inputs alone (today's default recipe is not the one the base run trained with).

score: the runs' best checkpoints on a split, in torch (so that a run without an ONNX path scores through the
same code as the base): the whole frame (PSNR and SSIM after `diviewer.metrics.tonemap`) and, as
`object_regions.py` defines them, the object's pixels and those of them without direct light (per-frame mean
of the region PSNR over frames with >= 50 such pixels). One tone map for all runs (`fit_exposure` on the
direct light of the first 200 train frames). A run whose checkpoint has 16 input channels gets the world
channels; one with 10 gets the usual inputs.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.data.dataset import Dataset, write_frame
from diviewer.scene.camera import look_at, pixel_rays_view, view_to_world

WORLD_CHANNELS = (("world_pos", 3), ("world_normal", 3))
"""The channels `derive` appends, in this order."""


def world_buffers(depth: np.ndarray, normal: np.ndarray, camera: dict, source_size: tuple[int, int],
                  crop_xy: tuple[int, int], center: np.ndarray, half: float) -> tuple[np.ndarray, np.ndarray]:
    """(world position normalised to [-1, 1], world normal), each (H, W, 3) float32, 0 where depth <= 0.

    depth: (H, W) linear view depth (-z); normal: (H, W, 3) view-space normal; camera: position, target,
    up, fov (vertical, degrees); source_size: (width, height) of the render the frame was cropped from;
    crop_xy: the crop's left column and top row in it.
    """
    h, w = depth.shape
    sw, sh = source_size
    x0, y0 = crop_xy
    rays = pixel_rays_view(sw, sh, float(camera["fov"]))[y0:y0 + h, x0:x0 + w]
    inv = view_to_world(look_at(camera["position"], camera["target"], camera["up"]))
    p_view = depth[..., None].astype(np.float64) * rays
    p = p_view @ inv[:3, :3].T + inv[:3, 3]
    n = normal.astype(np.float64) @ inv[:3, :3].T
    geo = (depth > 0)[..., None]
    pos = np.where(geo, np.clip((p - center) / half, -1.0, 1.0), 0.0)
    return pos.astype(np.float32), np.where(geo, n, 0.0).astype(np.float32)


def derive(src_dir: Path, out: Path, source_width: int, center: np.ndarray, half: float, log=print) -> int:
    src = Dataset(src_dir)
    manifest = json.loads(json.dumps(src.manifest))
    manifest["channels"] = [*manifest["channels"], *[list(c) for c in WORLD_CHANNELS]]
    manifest["derived_world"] = {"from": str(src_dir), "from_hash": src.hash, "source_width": source_width,
                                 "center": center.tolist(), "half": half, "tool": "tools/experiments/world_inputs.py"}
    (out / "frames").mkdir(parents=True, exist_ok=True)
    imageio.write_text(out / "manifest.json", json.dumps(manifest, indent=1))
    dst = Dataset(out)
    done = 0
    for f in src.frames:
        i = f["index"]
        if src.check_frame(i, False) is not None or dst.check_frame(i, False) is None:
            continue
        arr = np.load(src.path(i))
        fr = src.load(i)
        pos, nrm = world_buffers(fr["depth"], fr["normal"], f["config"]["camera"], (source_width, src.height),
                                 tuple(f.get("crop_xy", (0, 0))), center, half)
        write_frame(dst, i, np.concatenate([arr, pos.astype(arr.dtype), nrm.astype(arr.dtype)], -1),
                    {"index": i, "split": f["split"]})
        done += 1
        if done % 500 == 0:
            log(f"derive: {done} frames written")
    log(f"derive: {done} frames written, {len(dst.indices())} of {len(dst.frames)} present")
    return done


def world_split_batch(original):
    """`split_batch` with the stored world channels appended to the network's input (square frames only)."""
    def split_batch(x16, slices, enc, cfg, scale=None, multiple: int = 1, crop=None):
        import torch

        b = original(x16, slices, enc, cfg, scale=scale, multiple=multiple, crop=crop)
        if crop is not None or b["mask"] is not None:
            raise SystemExit("world_inputs.py trains on square frames of the model's multiple only "
                             "(no --aspect-crops, no padding)")
        x = x16.permute(0, 3, 1, 2).float()
        extra = [x[:, slices[name]] for name, _ in WORLD_CHANNELS]
        b["real_A"] = torch.cat([b["real_A"], *extra], 1)
        return b
    return split_batch


def patch_world_inputs() -> None:
    """Make this process's trainer feed the world channels and build 16-channel generators."""
    from diviewer.train import networks, report, targets, trainer

    patched = world_split_batch(targets.split_batch)
    trainer.split_batch = report.split_batch = patched
    networks.INPUT_CHANNEL_COUNT = 10 + sum(n for _, n in WORLD_CHANNELS)


def score(data: Path, split: str, runs: dict[str, Path], object_albedo: float) -> dict:
    import torch

    from diviewer import metrics
    from diviewer.metrics import tonemap
    from diviewer.train.checkpoint import build_generator_from_checkpoint, load_checkpoint
    from diviewer.train.config import TrainConfig
    from diviewer.train.encoding_torch import decode_radiance
    from diviewer.train.targets import compose_radiance, split_batch

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from object_regions import _psnr, fit_exposure_for

    ds = Dataset(data)
    idx = ds.indices(split)
    _, arr = ds.array(split, idx)
    exposure = fit_exposure_for(ds)
    result = {"data": str(data), "split": split, "frames": len(idx), "exposure": exposure, "runs": {}}
    for name, run in runs.items():
        ckpt = load_checkpoint(run / "best.ckpt")
        netG, enc, meta = build_generator_from_checkpoint(ckpt)
        cfg = TrainConfig(**{k: v for k, v in ckpt["config"].items() if k in TrainConfig.__dataclass_fields__})
        world = ckpt["model_args"]["in_channels"] > 10
        split_fn = world_split_batch(split_batch) if world else split_batch
        rows = {"frame_psnr": [], "frame_ssim": [], "object": [], "shaded": []}
        with torch.no_grad():
            for k in range(len(idx)):
                x16 = torch.from_numpy(arr[k:k + 1])
                b = split_fn(x16, ds.slices, enc, cfg)
                radiance = decode_radiance(netG(b["real_A"]).float(), enc)
                pred = compose_radiance(radiance, b["direct"], b["albedo"], meta["target"], meta["divide_albedo"])
                p = pred[0].permute(1, 2, 0).numpy()
                t = b["pt"][0].permute(1, 2, 0).numpy()
                albedo, direct = b["albedo"][0].permute(1, 2, 0).numpy(), b["direct"][0].permute(1, 2, 0).numpy()
                depth = x16[0, ..., ds.slices["depth"]].float().numpy()[..., 0]
                p_tm, t_tm = tonemap(p, exposure), tonemap(t, exposure)
                rows["frame_psnr"].append(metrics.psnr(p_tm, t_tm))
                rows["frame_ssim"].append(metrics.ssim(p_tm, t_tm))
                obj = (np.abs(albedo - object_albedo).max(axis=-1) < 0.004) & (depth > 0)
                for region, mask in (("object", obj), ("shaded", obj & (direct.mean(axis=-1) < 1e-4))):
                    if mask.sum() >= 50:
                        rows[region].append(_psnr(p_tm[mask], t_tm[mask]))
        result["runs"][name] = {"run": str(run), "step": ckpt["step"], "in_channels": ckpt["model_args"]["in_channels"],
                                **{k: {"frames": len(v), "mean": float(np.mean(v)) if v else None} for k, v in rows.items()}}
    return result


def recipe_like(run: Path, path: Path) -> Path:
    """A recipe file holding ``run``'s own train settings (its best checkpoint's config), written to ``path``:
    `diviewer train --recipe` fills every setting from it, not from today's shipped recipe."""
    from diviewer.train.checkpoint import load_checkpoint

    config = load_checkpoint(run / "best.ckpt")["config"]
    skip = {"data", "out", "device", "num_workers", "init_from", "train_frames", "recipe", "d_lr", "aspect_crops"}
    lines = [f"# {run}'s settings (its best.ckpt's config), written by tools/experiments/world_inputs.py",
             "[recipe]", f'description = "the settings of {run}"', 'scene = "cornell"', "", "[train]"]
    for k, v in config.items():
        if k not in skip and v is not None:
            lines.append(f"{k} = " + json.dumps(v))
    if "light_scale" not in config:  # runs from before encoding 2 used encoding 1
        lines.append("light_scale = false")
    imageio.write_text(path, "\n".join(lines) + "\n")
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("derive")
    d.add_argument("src", type=Path)
    d.add_argument("out", type=Path)
    d.add_argument("--source-width", type=int, required=True)
    d.add_argument("--center", default="0,1,0")
    d.add_argument("--half", type=float, default=1.2)
    t = sub.add_parser("train")
    t.add_argument("--like", type=Path, help="take every train setting from this run (its best.ckpt), as a recipe")
    t.add_argument("rest", nargs=argparse.REMAINDER)
    s = sub.add_parser("score")
    s.add_argument("--data", type=Path, required=True)
    s.add_argument("--split", default="test")
    s.add_argument("--object-albedo", type=float, required=True)
    s.add_argument("--run", action="append", required=True, help="NAME=RUN_DIR")
    s.add_argument("--out", type=Path)
    a = ap.parse_args()
    if a.cmd == "derive":
        derive(a.src, a.out, a.source_width, np.array([float(v) for v in a.center.split(",")]), a.half)
    elif a.cmd == "train":
        from diviewer.train.cli import main as train_main

        rest = [x for x in a.rest if x != "--"]
        if a.like is not None:
            out = Path(rest[rest.index("--out") + 1])
            out.mkdir(parents=True, exist_ok=True)
            rest += ["--recipe", str(recipe_like(a.like, out / "like_recipe.toml"))]
        patch_world_inputs()
        sys.exit(train_main(rest))
    else:
        runs = dict((kv.split("=", 1)[0], Path(kv.split("=", 1)[1])) for kv in a.run)
        text = json.dumps(score(a.data, a.split, runs, a.object_albedo), indent=1)
        print(text)
        if a.out:
            imageio.write_text(a.out, text)


if __name__ == "__main__":
    main()
