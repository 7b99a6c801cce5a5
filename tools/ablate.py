"""Ablations of the neural GI recipe on one dataset and one training budget, scored on the evaluation set.

Usage: python tools/ablate.py --data runs/cornell/data64 --evalset runs/cornell/evalset --out runs/cornell/ablate
       [--steps 600] [--train-frames 1000] [--only NAME ...] [--jobs 2] [--table OUT.md]
Every run trains `diviewer train` for the same number of steps on the same first N train frames (so
runs started while a capture still grows see the same data), exports fp32 ONNX and runs `diviewer eval`
on the evaluation set. Each stage resumes: run the same command again after an interruption. The
table (markdown, plus ablate.json) lists per split PSNR/SSIM tone-mapped, FLIP, the checkerboard ratio
and the equivalent sample count, with each run's training speed on this machine.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

# name -> (what it changes, extra `diviewer train` arguments). The first row is the paper's recipe
# (transposed convolutions, batch norm, L1 x 100 + GAN); every row but the last predicts indirect
# irradiance (albedo demodulation, multiplied back inside the graph).
BASE = ["--k", "16", "--target", "indirect"]
ABLATIONS: dict[str, tuple[str, list[str]]] = {
    "paper": ("transposed conv, batch norm, L1 + GAN (paper)", ["--upsample", "transpose"]),
    "resize": ("resize-conv decoder, L1 + GAN", ["--upsample", "resize"]),
    "shuffle": ("pixel-shuffle decoder, L1 + GAN", ["--upsample", "shuffle"]),
    "l1": ("resize, L1 alone (no GAN)", ["--upsample", "resize", "--gan-weight", "0"]),
    "transpose_l1": ("transposed conv, L1 alone", ["--upsample", "transpose", "--gan-weight", "0"]),
    "k8": ("resize, L1 alone, K=8", ["--upsample", "resize", "--gan-weight", "0", "--k", "8"]),
    "k32": ("resize, L1 alone, K=32", ["--upsample", "resize", "--gan-weight", "0", "--k", "32"]),
    "k64": ("resize, L1 alone, K=64", ["--upsample", "resize", "--gan-weight", "0", "--k", "64"]),
    "l2lin": ("resize, L2 on linear radiance alone", ["--upsample", "resize", "--gan-weight", "0",
                                                     "--recon-loss", "l2", "--recon-space", "linear"]),
    "l1lin": ("resize, L1 on linear radiance alone", ["--upsample", "resize", "--gan-weight", "0",
                                                     "--recon-space", "linear"]),
    "strongD": ("resize, L1 + LSGAN, netD lr x2", ["--upsample", "resize", "--gan-mode", "lsgan", "--d-lr", "4e-4"]),
    "instance": ("resize, instance norm, L1 + GAN", ["--upsample", "resize", "--norm", "instance"]),
    "nonorm": ("resize, no norm, L1 + GAN", ["--upsample", "resize", "--norm", "none"]),
    "nodemod": ("resize, L1 alone, indirect radiance (no albedo demodulation)", ["--upsample", "resize",
                                                                             "--gan-weight", "0"]),
}


def sh(args: list[str], log: Path) -> None:
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", DIVIEWER_TORCH_THREADS="1")
    with log.open("a") as f:
        f.write("+ " + " ".join(args) + "\n")
        f.flush()
        subprocess.run(args, check=True, stdout=f, stderr=subprocess.STDOUT, env=env)


DEMODULATED = ["--divide-albedo"]


def one(name: str, a: argparse.Namespace) -> dict:
    """Train, export and score one ablation; each stage is skipped when its output exists."""
    what, extra = ABLATIONS[name]
    run = a.out / name
    run.mkdir(parents=True, exist_ok=True)
    log = run / "ablate.log"
    dv = [sys.executable, "-m", "diviewer"]
    if not (run / "done").is_file():
        args = dv + ["train", "--data", str(a.data), "--out", str(run), "--max-steps", str(a.steps),
                     "--train-frames", str(a.train_frames),
                     "--val-every-steps", str(a.steps // 3), "--seed", "0"]
        t0 = time.time()
        recipe = BASE + ([] if name == "nodemod" else DEMODULATED) + extra
        sh(args + (["--resume"] if (run / "last.ckpt").is_file() else recipe), log)
        (run / "done").write_text(json.dumps({"train_s": time.time() - t0}))
    model = run / "model.onnx"
    if not model.is_file():
        sh(dv + ["export", str(run / "best.ckpt"), "--out", str(model)], log)
    res = run / "eval.json"
    if a.train_only:
        return {}
    if not res.is_file():
        sh(dv + ["eval", "--model", str(model), "--evalset", str(a.evalset), "--out", str(res)], log)
    return {"name": name, "what": what, "args": BASE + ([] if name == "nodemod" else DEMODULATED) + extra, "train": json.loads((run / "done").read_text()),
            "eval": json.loads(res.read_text())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--evalset", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--train-frames", type=int, default=1000)
    ap.add_argument("--only", nargs="*", default=None, choices=sorted(ABLATIONS))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--train-only", action="store_true", help="train and export only (score later)")
    ap.add_argument("--table", type=Path, default=None, help="write the markdown table here too")
    a = ap.parse_args()
    names = a.only or list(ABLATIONS)
    with ThreadPoolExecutor(a.jobs) as pool:
        results = list(pool.map(lambda n: one(n, a), names))
    if a.train_only:
        return
    (a.out / "ablate.json").write_text(json.dumps(results, indent=1))
    lines = table(results)
    print("\n".join(lines))
    if a.table:
        a.table.write_text("\n".join(lines) + "\n")


def table(results: list[dict]) -> list[str]:
    """Markdown rows: one per ablation, columns per split from `diviewer eval --evalset`'s JSON."""
    splits = list(results[0]["eval"]["splits"]) if results else []
    head = "| ablation | train s | " + " | ".join(f"{s}: PSNR tm / SSIM tm / FLIP-LDR / eq. spp / checker" for s in splits)
    lines = [head + " |", "|---" * (2 + len(splits)) + "|"]
    for r in results:
        cells = [_cell(r["eval"]["splits"][s]) for s in splits]
        lines.append(f"| {r['what']} | {r['train']['train_s']:.0f} | " + " | ".join(cells) + " |")
    return lines


def _cell(split: dict) -> str:
    """The (only) model's means in one split of an eval result (evaluate.evaluate_evalset's layout)."""
    m = next(v for v in split["methods"].values() if v.get("kind") == "neural")
    eq = m["equivalent_spp"]["psnr_tm"]
    return (f"{m['psnr_tm']['mean']:.2f} / {m['ssim_tm']['mean']:.3f} / {m['flip_ldr']['mean']:.3f} / "
            f"{eq['text'] if eq else '-'} / {m['checkerboard']:.2f}")


if __name__ == "__main__":
    main()
