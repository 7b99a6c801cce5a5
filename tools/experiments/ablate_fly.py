"""Issue 25's ablations for a model that holds wherever the user flies: one budget, one set of frames.

Usage: python tools/experiments/ablate_fly.py --data CROPS --shade-data CROPS_SHADE --out OUT
       [--steps 15000] [--only NAME ...] [--jobs 2] [--evalset EVALSET]

CROPS and CROPS_SHADE come from tools/experiments/crop_dataset.py on one snapshot of the capture (the
second with --shade-boost). Every run is the shipped cornell recipe (K=8, indirect light over albedo,
transposed convolutions, L1, no GAN) with one change, trains for the same number of steps (the cosine
schedule's horizon set to them, decay from a third of the way) on all train frames of its data, and is
exported to fp32 ONNX. Scoring: `diviewer eval` on the crops' test split (held-out camera regions and
unseen meshes) and val split (cameras anywhere, a fifth at the scene camera), and on EVALSET if given.
Each stage resumes: run the same command again after an interruption.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import dvrun  # this folder's helper for running diviewer

BASE = ["--k", "8", "--target", "indirect", "--divide-albedo", "--upsample", "transpose", "--gan-weight", "0",
        "--lr", "2e-4", "--lr-decay", "cosine", "--seed", "0"]
# name -> (what it changes, extra train arguments, which data)
ABLATIONS: dict[str, tuple[str, list[str], str]] = {
    "base": ("shipped recipe: K=8, L1 on encoded radiance", [], "data"),
    "log": ("L1 on log radiance (dark regions count)", ["--recon-space", "log"], "data"),
    "shade": ("more frames with the object in shade", [], "shade_data"),
    "k16": ("K=16", ["--k", "16"], "data"),
    "log_shade": ("log loss and more shaded frames", ["--recon-space", "log"], "shade_data"),
}


def _train_count(data: Path) -> int:
    manifest = json.loads((data / "manifest.json").read_text())
    return sum(1 for f in manifest["frame_list"] if f["split"] == "train" and (data / "frames" / f"{f['index']:06d}.json").is_file())


def one(name: str, a: argparse.Namespace) -> dict:
    what, extra, which = ABLATIONS[name]
    data = getattr(a, which)
    run = a.out / name
    run.mkdir(parents=True, exist_ok=True)
    log = run / "ablate.log"
    n = _train_count(data)
    epochs = max(1, math.ceil(a.steps / math.ceil(n / 4)))  # the schedule's horizon: epochs x steps per epoch
    if not (run / "done").is_file():
        args = ["train", "--data", str(data), "--out", str(run), "--epochs", str(epochs),
                "--max-steps", str(a.steps), "--lr-decay-start", str(a.steps // 3),
                "--val-every-steps", str(max(1, a.steps // 10)), "--device", "cpu"]
        t0 = time.time()
        dvrun.run(args + (["--resume"] if (run / "last.ckpt").is_file() else BASE + extra), log)
        (run / "done").write_text(json.dumps({"train_s": time.time() - t0, "train_frames": n, "epochs": epochs}))
    model = run / f"{name}.onnx"
    if not model.is_file():
        dvrun.run(["export", str(run / "best.ckpt"), "--out", str(model)], log)
    return {"name": name, "what": what, "args": BASE + extra, "data": str(data), "model": str(model),
            "train": json.loads((run / "done").read_text())}


def score(results: list[dict], a: argparse.Namespace) -> dict:
    """`diviewer eval` of every model on the crops' test and val splits (and the evaluation set)."""
    scores = {}
    for r in results:
        for split in ("test", "val"):
            out = a.out / r["name"] / f"eval_{split}.json"
            if not out.is_file():
                dvrun.run(["eval", "--data", str(a.data), "--split", split, "--model", r["model"], "--out", str(out)],
                          a.out / "eval.log")
            scores.setdefault(r["name"], {})[split] = json.loads(out.read_text())
    if a.evalset:
        out = a.out / "evalset.json"
        if not out.is_file():
            args = ["eval", "--evalset", str(a.evalset), "--out", str(out)]
            for r in results:
                args += ["--model", r["model"]]
            dvrun.run(args, a.out / "eval.log")
        scores["evalset"] = json.loads(out.read_text())
    return scores


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--shade-data", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--evalset", type=Path, default=None)
    ap.add_argument("--steps", type=int, default=15000)
    ap.add_argument("--only", nargs="*", default=None, choices=sorted(ABLATIONS))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--train-only", action="store_true")
    a = ap.parse_args()
    names = a.only or list(ABLATIONS)
    with ThreadPoolExecutor(a.jobs) as pool:
        results = list(pool.map(lambda n: one(n, a), names))
    if a.train_only:
        return
    scores = score(results, a)
    (a.out / "ablate_fly.json").write_text(json.dumps({"runs": results, "scores": scores}, indent=1))
    print(json.dumps({r["name"]: {s: scores[r["name"]][s].get("summary", scores[r["name"]][s]) for s in ("test", "val")}
                      for r in results}, indent=1)[:4000])


if __name__ == "__main__":
    main()
