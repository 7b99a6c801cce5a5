"""What dynamic resolution costs in accuracy: the viewer's frame at each render scale against full resolution.

Usage: python tools/experiments/scale_accuracy.py [--scene cornell] [--model assets/models/cornell.onnx] [--size 768x768]
       [--scales 1,0.875,0.75,0.625,0.5] (2: supersampled) [--frames 6] [--spp 0] [--gi-res model] [--exposure X]
       [--out runs/<scene>/scale_accuracy.json] [--truth-cache TRUTH.npz]

The successor of tools/fullres_accuracy.py (which compared the full-resolution frame with the old stretched
one). For each frame (drawn from the sampler's train and test splits with seeds no capture uses) and each
scale s: the G-buffer, shadow lookup and direct light at s times the window's size, the network at the GI
resolution the viewer picks (``--gi-res``, as `diviewer view`: ``model`` keeps the model's rows at the
window's shape), its indirect light upsampled by the joint bilateral filter over the direct light
(gl/neural.py, the viewer's pass), then upscaled to the window bilinearly (GL's LINEAR magnification, which
the viewer's display applies). Each is scored against the scale-1 frame with `diviewer eval`'s metrics
(PSNR/SSIM linear and tone-mapped at the model's exposure, or ``--exposure``); with ``--spp N`` also against
Mitsuba at the window's size and N spp. The table goes to stdout and, with every frame's scores, to the JSON.
Long on a 2-core CPU with --spp: run it on a quiet machine.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # tools/experiments/ -> the repository
sys.path.insert(0, str(ROOT))

STREAM = 0x5CA1E  # seeds of their own: SeedSequence([STREAM, split, i])


def bilinear(img: np.ndarray, w: int, h: int) -> np.ndarray:
    """GL's LINEAR magnification of an (H, W, C) image to (h, w, C): texel centres, clamped to the edge."""
    H, W = img.shape[:2]
    ys = np.clip((np.arange(h) + 0.5) * H / h - 0.5, 0, H - 1)
    xs = np.clip((np.arange(w) + 0.5) * W / w - 0.5, 0, W - 1)
    y0, x0 = np.floor(ys).astype(int), np.floor(xs).astype(int)
    y1, x1 = np.minimum(y0 + 1, H - 1), np.minimum(x0 + 1, W - 1)
    fy, fx = (ys - y0)[:, None, None], (xs - x0)[None, :, None]
    top = img[y0][:, x0] * (1 - fx) + img[y0][:, x1] * fx
    bottom = img[y1][:, x0] * (1 - fx) + img[y1][:, x1] * fx
    return (top * (1 - fy) + bottom * fy).astype(np.float32)


def parse_scales(text: str) -> list[float]:
    from diviewer.viewer.settings import check_render_scale

    scales = sorted({check_render_scale(float(x)) for x in text.split(",") if x.strip()}, reverse=True)
    return [1.0] + [s for s in scales if s != 1.0]  # the full-resolution frame first: the others are scored on it


def _truth(ref, scene, config, size, spp: int, seed: int, cache: Path | None, key: str) -> np.ndarray:
    """Mitsuba's frame at ``size`` and ``spp``; kept in the ``cache`` npz (written atomically) under ``key``, so
    that several models are scored against the same renders."""
    held = dict(np.load(cache)) if cache is not None and cache.is_file() else {}
    if key not in held:
        held[key] = ref.load_frame(scene, config, *size).full(spp=spp, seed=seed)
        if cache is not None:
            tmp = cache.with_name(cache.name + ".tmp.npz")
            np.savez(tmp, **held)
            tmp.replace(cache)
    return held[key]


def measure(scene_name: str, model_path: Path, size: tuple[int, int], scales: list[float], frames: int, spp: int,
            gi_res: str = "model", exposure: float | None = None, log=print, truth_cache: Path | None = None) -> dict:
    """Scores of each scale's frame against the scale-1 frame (and the path tracer with ``spp``), per split."""
    from diviewer.evaluation.evaluate import score
    from diviewer.gl.context import describe, headless_context
    from diviewer.gl.neural import NeuralPass
    from diviewer.gl.renderer import Renderer
    from diviewer.runtime import NeuralGI
    from diviewer.scene import load_scene, sample_config
    from diviewer.viewer.models import gi_resolution, runtime_pads
    from diviewer.viewer.scale import render_size

    scene = load_scene(scene_name)
    model = NeuralGI(model_path, scene=scene)
    if exposure is None:  # the model's tone map (as `diviewer eval`), else the scene's display exposure (EV)
        exposure = float(model.meta.get("encoding", {}).get("exposure", 2.0 ** scene.exposure))
    W, H = size
    ref = variant = None
    if spp > 0:
        from diviewer.reference import mitsuba as ref

        variant = ref.select_variant()
    rows: dict[str, list] = {"train": [], "test": []}
    t0 = time.time()
    with headless_context() as ctx:
        passes = {}
        for s in scales:
            r = Renderer(ctx, scene, *render_size(size, s))
            gi = gi_resolution(gi_res, (r.width, r.height), model.resolution, model.multiple,
                               pads=runtime_pads(model), shape=size)
            passes[s] = (r, NeuralPass(ctx, r, model, gi_size=gi))
        for split in rows:
            for i in range(frames):
                seed = int(np.random.SeedSequence([STREAM, 0 if split == "train" else 1, i]).generate_state(1)[0]
                           & 0x7FFFFFFF)
                config = sample_config(scene, seed, split)
                images = {}
                for s, (r, npass) in passes.items():
                    r.render(config)
                    npass.run(**npass.inputs_for(scene, config))
                    tex = npass.composite()
                    hdr = np.flipud(np.frombuffer(tex.read(), dtype="f2").reshape(r.height, r.width, 4)[..., :3])
                    images[s] = bilinear(np.ascontiguousarray(hdr, dtype=np.float32), W, H)
                truth = (_truth(ref, scene, config, (W, H), spp, seed, truth_cache, f"{scene_name}_{split}_{i}_{seed}_{W}x{H}_"
                                f"{spp}") if ref is not None else None)
                row = {"seed": seed, "scales": {}}
                for s, img in images.items():
                    row["scales"][str(s)] = {"vs_full": score(img, images[1.0], exposure) if s != 1.0 else None,
                                             "vs_truth": score(img, truth, exposure) if truth is not None else None}
                rows[split].append(row)
                log(f"{split} {i}: " + ", ".join(f"{s:g} {row['scales'][str(s)]['vs_full']['psnr_tm']:.2f} dB"
                                                   for s in scales if s != 1.0) + f" ({time.time() - t0:.0f} s)")
        gl = describe(ctx)
        gi_sizes = {str(s): list(p.gi_size) for s, (_, p) in passes.items()}
        for r, p in passes.values():
            p.release()
            r.release()

    def mean(rs, s, against, q):
        vals = [r["scales"][str(s)][against][q] for r in rs if r["scales"][str(s)][against] is not None]
        return float(np.mean(vals)) if vals else None

    qs = ("psnr", "ssim", "psnr_tm", "ssim_tm")
    summary = {split: {str(s): {a: {q: mean(rs, s, a, q) for q in qs} for a in ("vs_full", "vs_truth")}
                       for s in scales}
               for split, rs in [*rows.items(), ("all", rows["train"] + rows["test"])]}
    return {"scene": scene_name, "model": str(model_path), "window": list(size), "scales": scales,
            "render_sizes": {str(s): list(render_size(size, s)) for s in scales}, "gi_res": gi_res,
            "gi_sizes": gi_sizes, "spp": spp, "variant": variant, "gl_renderer": gl, "tonemap_exposure": exposure,
            "summary": summary, "frames": rows, "seconds": round(time.time() - t0, 1)}


def table(result: dict) -> str:
    """The summary as text: per split and scale, PSNR/SSIM tone-mapped against full resolution (and the truth)."""
    lines = [f"{'split':6} {'scale':>6} {'shaded':>10}  {'dB vs full':>10} {'SSIM':>6}  "
             f"{'dB vs truth':>11} {'SSIM':>6}"]
    for split, by_scale in result["summary"].items():
        for s, d in by_scale.items():
            f, t = d["vs_full"], d["vs_truth"]
            w, h = result["render_sizes"][s]
            cell = lambda v, fmt: format(v, fmt) if v is not None else "-"
            lines.append(f"{split:6} {float(s):6.3f} {f'{w}x{h}':>10}  {cell(f['psnr_tm'], '10.2f'):>10} "
                         f"{cell(f['ssim_tm'], '6.4f'):>6}  {cell(t['psnr_tm'], '11.2f'):>11} "
                         f"{cell(t['ssim_tm'], '6.4f'):>6}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict:
    from diviewer.frames import parse_resolution
    from diviewer.imageio import write_text

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="cornell")
    ap.add_argument("--model", type=Path, default=None, help="default: assets/models/<scene>.onnx")
    ap.add_argument("--size", default="768x768", help="window size WxH (default 768x768, the viewer's)")
    ap.add_argument("--scales", default="1,0.875,0.75,0.625,0.5", help="render scales (1 is always measured)")
    ap.add_argument("--frames", type=int, default=6, help="frames per split (train, test)")
    ap.add_argument("--spp", type=int, default=0, help="also score against Mitsuba at this many spp (0: no)")
    ap.add_argument("--gi-res", default="model", help="the viewer's --gi-res (default model)")
    ap.add_argument("--exposure", type=float, default=None,
                    help="tone-map exposure of the scores, a multiplier as `diviewer eval`'s (default: the model's)")
    ap.add_argument("--out", type=Path, default=None, help="default: runs/<scene>/scale_accuracy.json")
    ap.add_argument("--truth-cache", type=Path, default=None,
                    help="with --spp: keep Mitsuba's frames in this .npz and reuse them (score several models alike)")
    a = ap.parse_args(argv)
    model = a.model or ROOT / "assets" / "models" / f"{a.scene}.onnx"
    out = a.out or ROOT / "runs" / a.scene / "scale_accuracy.json"
    result = measure(a.scene, model, parse_resolution(a.size, "--size"), parse_scales(a.scales), a.frames, a.spp,
                     a.gi_res, a.exposure, truth_cache=a.truth_cache)
    write_text(out, json.dumps(result, indent=1))
    print(table(result))
    print(f"wrote {out}")
    return result


if __name__ == "__main__":
    main()
