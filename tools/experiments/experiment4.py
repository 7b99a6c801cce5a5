"""Deep Illumination's Experiment 4, measured: a model trained on VXGI ground truth against one trained on path tracing.

Usage: python tools/experiments/experiment4.py --pt-run runs/cornell/ablate/l1 --pt-data runs/cornell/data64
       --vxgi-data runs/cornell/data_vxgi --evalset runs/cornell/evalset --out runs/cornell/exp4_vxgi
       [--steps 400] [--train-frames 600] [--min-val 40] [--vxgi-res 64] [--table OUT.md]
The path-tracing side is an existing run of tools/experiments/ablate.py (`--only l1`). The VXGI side: `diviewer capture
--gt vxgi` with the path-traced dataset's frames, resolution, splits and seed (the same configurations, frame for
frame), stopped once it holds --train-frames train and --min-val val frames; `diviewer train` with ablate.py's
l1 recipe, steps and frame count; export fp32. Both models are then scored by `diviewer eval` against the path
tracer on the evaluation set (waiting until it is complete), beside VXGI itself (what the VXGI model was taught,
rendered again for the set's configurations) and direct light. Each stage resumes: run the same command again after
an interruption. Run it as `OMP_NUM_THREADS=1 nice -n 5 python tools/experiments/experiment4.py ...` beside other work: its
jobs run one at a time, each on one thread.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import ablate  # noqa: E402  (the recipe is ablate.py's, not a copy of it)
import dvrun  # noqa: E402


def recipe() -> list[str]:
    """`diviewer train` arguments of ablate.py's l1 row (resize decoder, L1 alone, indirect, albedo divided)."""
    return ablate.BASE + ablate.DEMODULATED + ablate.ABLATIONS["l1"][1]


def present(root: Path, frame_list: list[dict]) -> dict[str, int]:
    """Complete frames per split (the .json sidecar is written last: it marks a frame complete)."""
    out: dict[str, int] = {}
    for f in frame_list:
        name = f"{f['index']:06d}"
        if (root / "frames" / f"{name}.json").is_file() and (root / "frames" / f"{name}.npy").is_file():
            out[f["split"]] = out.get(f["split"], 0) + 1
    return out


def capture(a: argparse.Namespace, log: Path) -> dict[str, int]:
    """`diviewer capture --gt vxgi` with the path-traced dataset's plan, until enough train and val frames exist."""
    s = json.loads((a.pt_data / "manifest.json").read_text())["settings"]
    frame_list = json.loads((a.pt_data / "manifest.json").read_text())["frame_list"]
    args = ["capture", "--scene", json.loads((a.pt_data / "manifest.json").read_text())["scene"],
                 "--frames", str(s["frames"]), "--res", f"{s['width']}x{s['height']}", "--spp", str(s["spp"]),
                 "--splits", ",".join(str(x) for x in s["split_fractions"]), "--seed", str(s["seed"]),
                 "--dtype", s["dtype"], "--gt", "vxgi", "--vxgi-res", str(a.vxgi_res), "--out", str(a.vxgi_data)]

    def enough(counts):
        return counts.get("train", 0) >= a.train_frames and counts.get("val", 0) >= a.min_val

    counts = present(a.vxgi_data, frame_list) if (a.vxgi_data / "manifest.json").is_file() else {}
    if enough(counts):
        return counts
    proc = dvrun.start(args, log)  # stopped once enough frames exist
    try:
        while proc.poll() is None:
            time.sleep(10)
            if (a.vxgi_data / "manifest.json").is_file() and enough(counts := present(a.vxgi_data, frame_list)):
                break
    finally:
        if proc.poll() is None:
            proc.terminate()  # capture resumes where it stopped; a half-written frame has no sidecar
            proc.wait()
    counts = present(a.vxgi_data, frame_list)
    if not enough(counts):
        raise SystemExit(f"capture ended with {counts} frames; see {log}")
    return counts


def capture_rate(root: Path, n: int | None = None) -> dict:
    """Seconds per frame from the sidecars (GL buffers, ground truth) and from their write times (wall)."""
    sidecars = sorted((root / "frames").glob("*.json"))[:n]
    infos = [json.loads(p.read_text()) for p in sidecars]
    gl = [i["seconds"]["gl"] for i in infos]
    gt = [i["seconds"]["gt"] for i in infos]
    times = sorted(p.stat().st_mtime for p in sidecars)
    wall = (times[-1] - times[0]) / max(len(times) - 1, 1)
    return {"frames": len(infos), "gl_s": sum(gl) / len(gl), "gt_s": sum(gt) / len(gt), "wall_s_per_frame": wall,
            "frames_per_s": 1.0 / wall if wall > 0 else None}


def wait_for_evalset(evalset: Path) -> None:
    m = json.loads((evalset / "manifest.json").read_text())
    planned = len(m["frame_list"])
    while (done := sum(present(evalset, m["frame_list"]).values())) < planned:
        print(f"waiting for the evaluation set: {done}/{planned} frames", flush=True)
        time.sleep(60)


def score_vxgi_itself(a: argparse.Namespace, eval_result: dict) -> dict:
    """The VXGI ground truth itself against the path tracer, per split of the evaluation set: what the VXGI-trained
    model was taught, re-rendered (GL, the VXGI dataset's settings) for the set's configurations."""
    from diviewer.evaluation.evalset import load_evalset
    from diviewer.evaluation.evaluate import aggregate, equivalent, score_frame
    from diviewer.gl.context import headless_context
    from diviewer.gl.renderer import Renderer
    from diviewer.gl.vxgi import VXGIPass, VXGISettings
    from diviewer.metrics import flat_mask
    from diviewer.scene import load_scene
    from diviewer.scene.loader import config_from_dict

    ds = load_evalset(a.evalset)
    scene = load_scene(ds.manifest["scene"])  # the shipped scene: the file the set names may be another checkout's
    if scene.file_hash != ds.manifest["scene_hash"]:
        raise SystemExit(f"scene '{ds.manifest['scene']}' changed since the evaluation set was made")
    settings = VXGISettings(**json.loads((a.vxgi_data / "manifest.json").read_text())["vxgi"])
    exposure = float(eval_result["tonemap_exposure"])
    entries = {f["index"]: f for f in ds.frames}
    out = {}
    with headless_context() as ctx:
        renderer = Renderer(ctx, scene, ds.width, ds.height)
        vx = VXGIPass(ctx, renderer, settings)
        try:
            for split, r in eval_result["splits"].items():
                rows = []
                for i in ds.indices(split):
                    f = ds.load(i)
                    config = config_from_dict(scene, entries[i]["config"])
                    renderer.render(config)
                    vx.run(config)
                    rows.append(score_frame(vx.read("vxgi"), f["pt"], exposure,
                                            flat_mask(f["depth"], f["normal"], f["albedo"], f["direct"])))
                m = aggregate(rows)
                n = eval_result["ladder_spp"]
                m["equivalent_spp"] = equivalent(m, n, [r["methods"][f"pt_spp{k}"] for k in n])
                m.update(kind="vxgi", label=f"VXGI {settings.resolution}^3, {settings.bounces} bounces", frames=len(rows),
                         settings=dataclasses.asdict(settings))
                out[split] = m
        finally:
            vx.release()
            renderer.release()
    return out


def check_pt_run(a: argparse.Namespace) -> None:
    """The path-tracing run was trained as this script trains the VXGI one (its first `train` line in ablate.log)."""
    line = next(ln for ln in (a.pt_run / "ablate.log").read_text().splitlines() if ln.startswith("+") and " train " in ln)
    given = line.split()[line.split().index("train") + 1:]
    opt = {k: v for k, v in zip(given, given[1:]) if k.startswith("--")}
    want = {"--max-steps": str(a.steps), "--train-frames": str(a.train_frames), "--val-every-steps": str(a.steps // 3),
            "--seed": "0", "--data": None}
    bad = [f"{k} {opt.get(k)} (here {v})" for k, v in want.items() if v is not None and opt.get(k) != v]
    r = recipe()
    if bad or " ".join(r) not in " ".join(given):
        raise SystemExit(f"{a.pt_run} was not trained with this recipe: {bad or given}")
    if Path(opt["--data"]).name != a.pt_data.name:  # the log's path is relative to where ablate.py ran
        raise SystemExit(f"{a.pt_run} was trained on {opt['--data']}, not {a.pt_data}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pt-run", type=Path, required=True, help="tools/experiments/ablate.py's l1 run (model.onnx, done)")
    ap.add_argument("--pt-data", type=Path, required=True, help="the path-traced dataset it was trained on")
    ap.add_argument("--vxgi-data", type=Path, required=True)
    ap.add_argument("--evalset", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--train-frames", type=int, default=600)
    ap.add_argument("--min-val", type=int, default=40)
    ap.add_argument("--vxgi-res", type=int, default=64)
    ap.add_argument("--table", type=Path, default=None)
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    log = a.out / "experiment4.log"
    check_pt_run(a)
    counts = capture(a, log)
    print(f"VXGI dataset: {counts}", flush=True)
    if not (a.out / "done").is_file():
        args = ["train", "--data", str(a.vxgi_data), "--out", str(a.out), "--max-steps", str(a.steps),
                     "--train-frames", str(a.train_frames), "--val-every-steps", str(a.steps // 3), "--seed", "0"]
        t0 = time.time()
        dvrun.run(args + (["--resume"] if (a.out / "last.ckpt").is_file() else recipe()), log)
        (a.out / "done").write_text(json.dumps({"train_s": time.time() - t0}))
    model = a.out / "vxgi_l1.onnx"
    if not model.is_file():
        dvrun.run(["export", str(a.out / "best.ckpt"), "--out", str(model)], log)
    res = a.out / "eval.json"
    if not res.is_file():
        wait_for_evalset(a.evalset)
        dvrun.run(["eval", "--model", str(a.pt_run / "model.onnx"), "--model", str(model), "--evalset", str(a.evalset),
                 "--out", str(res)], log)
    gt_scores = a.out / "vxgi_gt_eval.json"
    if not gt_scores.is_file():
        gt_scores.write_text(json.dumps(score_vxgi_itself(a, json.loads(res.read_text())), indent=1))
    evaluated = json.loads(res.read_text())
    for split, m in json.loads(gt_scores.read_text()).items():
        evaluated["splits"][split]["methods"]["vxgi_gt"] = m
    result = {"pt_run": str(a.pt_run), "vxgi_run": str(a.out), "recipe": recipe(), "steps": a.steps,
              "train_frames": a.train_frames, "vxgi_dataset": {"path": str(a.vxgi_data), "frames": counts,
                                                               "capture": capture_rate(a.vxgi_data)},
              "pt_dataset_capture": capture_rate(a.pt_data, n=sum(counts.values())),
              "train_s": {"pt": json.loads((a.pt_run / "done").read_text())["train_s"],
                          "vxgi": json.loads((a.out / "done").read_text())["train_s"]},
              "eval": evaluated}
    (a.out / "experiment4.json").write_text(json.dumps(result, indent=1))
    lines = table(result, pt_key=(a.pt_run / "model.onnx").stem, vxgi_key=model.stem)
    print("\n".join(lines))
    if a.table:
        a.table.write_text("\n".join(lines) + "\n")


def table(result: dict, pt_key: str, vxgi_key: str) -> list[str]:
    """Markdown: per split, the two models and direct light against the path-traced evaluation set."""
    rows = [("trained on path tracing (ablate l1)", pt_key), ("trained on VXGI", vxgi_key),
            ("VXGI itself (the VXGI model's ground truth)", "vxgi_gt"), ("direct light only", "direct")]
    splits = result["eval"]["splits"]
    lines = ["| ground truth of training | " + " | ".join(f"{s}: PSNR tm / SSIM tm / FLIP-LDR / eq. spp" for s in splits)
             + " |", "|---" * (1 + len(splits)) + "|"]
    for label, key in rows:
        cells = []
        for s in splits.values():
            m = s["methods"][key]
            eq = (m.get("equivalent_spp") or {}).get("psnr_tm")
            cells.append(f"{m['psnr_tm']['mean']:.2f} / {m['ssim_tm']['mean']:.3f} / {m['flip_ldr']['mean']:.3f} / "
                         f"{eq['text'] if eq else '-'}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    v, p = result["vxgi_dataset"]["capture"], result["pt_dataset_capture"]
    lines += ["", f"capture, {v['frames']} VXGI frames: {v['gl_s']:.3f} s GL buffers + {v['gt_s']:.3f} s VXGI per frame, "
              f"{v['wall_s_per_frame']:.2f} s/frame wall ({v['frames_per_s']:.2f} frames/s); the path-traced dataset's first "
              f"{p['frames']} frames: {p['gt_s']:.2f} s path tracing per frame"]
    return lines


if __name__ == "__main__":
    main()
