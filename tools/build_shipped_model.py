"""Rebuild a shipped model: capture the scene's dataset, train the cGAN, export to assets/models/.

Usage: python tools/build_shipped_model.py --scene cornell [--frames 500 --res 128 --spp 256 --k 32
       --epochs 30 --target indirect --work runs/cornell]
The defaults are the settings of the shipped assets/models/cornell.onnx (exported in fp16).
Every stage resumes: run the same command again after an interruption and it goes on where it
stopped (capture skips finished frames, training continues from RUN/last.ckpt). Logs go to stdout;
run it in the background with `nohup ... > build.log 2>&1 &`.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run(*args: str) -> None:
    print("+ diviewer", " ".join(args), flush=True)
    subprocess.run([sys.executable, "-m", "diviewer", *args], check=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="cornell")
    ap.add_argument("--frames", type=int, default=500)
    ap.add_argument("--res", default="128")
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--k", type=int, default=32)
    ap.add_argument("--epochs", type=int, default=30)
    ap.add_argument("--target", default="indirect", choices=("full", "indirect"))
    ap.add_argument("--fp32", action="store_true", help="export fp32 weights (default fp16: same scores, half the size)")
    ap.add_argument("--name", default=None, help="model file name in assets/models (default SCENE)")
    ap.add_argument("--work", type=Path, default=None, help="dataset and run folder (default runs/SCENE)")
    a = ap.parse_args()
    work = a.work or ROOT / "runs" / a.scene
    data, run_dir = work / "data", work / f"train_k{a.k}_{a.target}"
    run("capture", "--scene", a.scene, "--frames", str(a.frames), "--res", a.res, "--spp", str(a.spp),
        "--out", str(data))
    run("data", "check", str(data), "--fast")
    train = ["train", "--data", str(data), "--k", str(a.k), "--epochs", str(a.epochs), "--target", a.target,
             "--out", str(run_dir)]
    if (run_dir / "last.ckpt").is_file():
        train.append("--resume")
    run(*train)
    name = a.name or a.scene
    out = ROOT / "assets" / "models" / f"{name}.onnx"
    run("export", str(run_dir / "best.ckpt"), "--out", str(out), *([] if a.fp32 else ["--fp16"]))
    shutil.copyfile(run_dir / "curves.png", out.with_name(f"{name}_curves.png"))
    shutil.copyfile(run_dir / "metrics.csv", out.with_name(f"{name}_metrics.csv"))
    run("eval", "--model", str(out), "--data", str(data), "--split", "test")
    card = json.loads(out.with_suffix(".json").read_text())
    print(json.dumps(card.get("validation"), indent=1))


if __name__ == "__main__":
    main()
