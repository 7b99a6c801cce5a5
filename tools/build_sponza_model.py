"""Rebuild the shipped Sponza model from nothing: capture, noise floor, the K ladder, pick and ship the smallest K.

Usage: python tools/build_sponza_model.py [--frames 3000 --res 256 --spp 1024 --ks 8,16,32,64
       --epochs 30 --seed 0 --work runs/sponza] [--shard k/n --capture-only] [--smoke]

Stages, each resumable (run the same command again after an interruption):
1. capture: `diviewer capture --scene sponza` (GL inputs + Mitsuba ground truth; cuda_ad_rgb/llvm_ad_rgb as
   available). With --shard k/n --capture-only, n machines capture disjoint frames into their own folders;
   merge them with `diviewer data merge` and run again without --shard.
2. noise floor: the reference against itself (two seeds) on test frames, so the model's error can be
   compared with the truth's own noise (the issue asks for >= 6 dB margin).
3. the ladder: the same data, epochs and seed for every K (fixed seeds), each run resumes from last.ckpt.
4. export each K (fp16), evaluate on the test split, ship as assets/models/sponza.onnx the smallest K whose
   tone-mapped PSNR is within --tolerance dB (0.5) of the best K's; the ladder goes to
   assets/models/sponza_ladder.json with timings and the machine.
--smoke runs everything at toy size (3 frames: one per split, 1 epoch, K=8) into runs/sponza_smoke and ships nothing.
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run(*args: str) -> None:
    print("+ diviewer", " ".join(args), flush=True)
    subprocess.run([sys.executable, "-m", "diviewer", *args], check=True)


def noise_floor(work: Path, res: str, spp: int, seeds: range) -> dict:
    """Reference self-agreement (PSNR between two seeds) on test-split configurations; cached in work/."""
    out = work / "noise_floor.json"
    if out.is_file():
        return json.loads(out.read_text())
    rows = []
    for s in seeds:
        d = work / "noise" / f"test_{s}"
        run("render", "--scene", "sponza", "--seed", str(s), "--split", "test", "--res", res, "--reference", "pt",
            "--spp", str(spp), "--noise-floor", "--out", str(d))
        rows.append(json.loads((d / "frame.json").read_text())["reference"]["noise_floor"])
    summary = {"spp": spp, "frames": len(rows), "psnr_mean": sum(r["psnr"] for r in rows) / len(rows), "frames_detail": rows}
    out.write_text(json.dumps(summary, indent=1))
    return summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=3000, help="frames over all splits (the paper: 3,400)")
    ap.add_argument("--res", default="256")
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--ks", default="8,16,32,64", help="generator widths to train (add 128 on an accelerator)")
    ap.add_argument("--epochs", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0, help="training seed, the same for every K")
    ap.add_argument("--target", default="indirect", choices=("full", "indirect"))
    ap.add_argument("--tolerance", type=float, default=0.5, help="dB below the best K's test PSNR (tone-mapped)")
    ap.add_argument("--shard", default=None, help="k/n: capture only every n-th frame (then merge)")
    ap.add_argument("--capture-only", action="store_true")
    ap.add_argument("--smoke", action="store_true", help="3 frames, 1 epoch, K=8: check the pipeline, ship nothing")
    ap.add_argument("--work", type=Path, default=None, help="dataset and runs (default runs/sponza)")
    a = ap.parse_args()
    if a.smoke:
        a.frames, a.res, a.spp, a.ks, a.epochs = 3, "64", 4, "8", 1
    work = a.work or ROOT / "runs" / ("sponza_smoke" if a.smoke else "sponza")
    data = work / ("data" if a.shard is None else f"data_shard{a.shard.replace('/', 'of')}")
    t0 = time.time()
    capture = ["capture", "--scene", "sponza", "--frames", str(a.frames), "--res", a.res, "--spp", str(a.spp),
               "--out", str(data)]
    if a.smoke:
        capture += ["--splits", "1,1,1"]  # one frame per split
    run(*capture, *(["--shard", a.shard] if a.shard else []))
    if a.capture_only or a.shard:
        print(f"captured into {data} in {time.time() - t0:.0f} s; merge the shards, then run without --shard")
        return
    run("data", "check", str(data), "--fast")
    t_capture = time.time() - t0
    floor = noise_floor(work, a.res, a.spp, range(1 if a.smoke else 4))
    ladder = []
    for k in (int(x) for x in a.ks.split(",")):
        run_dir = work / f"train_k{k}_{a.target}"
        t1 = time.time()
        train = ["train", "--data", str(data), "--k", str(k), "--epochs", str(a.epochs), "--target", a.target,
                 "--seed", str(a.seed), "--out", str(run_dir)]
        run(*train, *(["--resume"] if (run_dir / "last.ckpt").is_file() else []))
        model = work / "models" / f"sponza_k{k}.onnx"
        model.parent.mkdir(parents=True, exist_ok=True)
        run("export", str(run_dir / "best.ckpt"), "--out", str(model), "--fp16")
        scores = {}
        for split in ("test", "val"):
            out = work / "models" / f"sponza_k{k}_{split}.json"
            run("eval", "--model", str(model), "--data", str(data), "--split", split, "--out", str(out))
            scores[split] = json.loads(out.read_text())
        test = scores["test"]
        ladder.append({"K": k, "model": str(model), "train_seconds": time.time() - t1,
                       "bytes": model.stat().st_size, "inference_ms": test["inference_ms"],
                       "splits": {s: {m: {q: r["methods"][m][q]["mean"] for q in ("psnr", "ssim", "psnr_tm", "ssim_tm")}
                                      for m in ("neural", "direct")} for s, r in scores.items()}})
    from diviewer.bench.frontier import smallest_sufficient_k

    pick = smallest_sufficient_k({r["K"]: r["splits"]["test"]["neural"]["psnr_tm"] for r in ladder}, a.tolerance)
    best, chosen = pick["best_psnr"], next(r for r in ladder if r["K"] == pick["K"])
    record = {"scene": "sponza", "frames": a.frames, "res": a.res, "spp": a.spp, "epochs": a.epochs, "seed": a.seed,
              "target": a.target, "noise_floor": {k: v for k, v in floor.items() if k != "frames_detail"},
              "ladder": ladder, "chosen_K": chosen["K"],
              "why": f"smallest K whose test PSNR (tone-mapped) is within {a.tolerance} dB of the best ({best:.2f} dB)",
              "capture_seconds": t_capture, "total_seconds": time.time() - t0,
              "machine": {"node": platform.node(), "processor": platform.processor() or platform.machine(),
                          "python": platform.python_version()}}
    print(json.dumps({k: v for k, v in record.items() if k != "ladder"}, indent=1))
    if a.smoke:
        (work / "ladder.json").write_text(json.dumps(record, indent=1))
        print(f"smoke run: nothing shipped; {work / 'ladder.json'}")
        return
    dst = ROOT / "assets" / "models" / "sponza.onnx"
    src = Path(chosen["model"])
    shutil.copyfile(src, dst)
    card = json.loads(src.with_suffix(".json").read_text())
    card["ladder"] = {"chosen_K": chosen["K"], "why": record["why"], "noise_floor": record["noise_floor"],
                      "rows": [{k: r[k] for k in ("K", "bytes", "inference_ms", "splits")} for r in ladder]}
    dst.with_suffix(".json").write_text(json.dumps(card, indent=1))
    run_dir = work / f"train_k{chosen['K']}_{a.target}"
    shutil.copyfile(run_dir / "curves.png", dst.with_name("sponza_curves.png"))
    shutil.copyfile(run_dir / "metrics.csv", dst.with_name("sponza_metrics.csv"))
    dst.with_name("sponza_ladder.json").write_text(json.dumps(record, indent=1))
    print(f"shipped K={chosen['K']} as {dst}")


if __name__ == "__main__":
    main()
