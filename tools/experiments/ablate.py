"""Ablations of the neural GI recipe on one dataset and one training budget, scored on the evaluation set.

Usage: python tools/experiments/ablate.py --data runs/cornell/data64 --evalset runs/cornell/evalset --out runs/cornell/ablate
       [--steps 600] [--train-frames 1000] [--only NAME ...] [--jobs 2] [--table OUT.md]
Every run trains `diviewer train` for the same number of steps on the same first N train frames (so
runs started while a capture still grows see the same data) and exports fp32 ONNX; one `diviewer eval`
then scores them all on the evaluation set. Each stage resumes: run the same command again after an interruption. The
table (markdown, plus ablate.json) lists per split PSNR/SSIM tone-mapped, FLIP, the checkerboard ratio
and the equivalent sample count, with each run's training speed on this machine.
"""

from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import dvrun  # this folder's helper for running diviewer (a script's own folder is on sys.path)

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


DEMODULATED = ["--divide-albedo"]


def one(name: str, a: argparse.Namespace) -> dict:
    """Train and export one ablation (RUN/NAME.onnx, fp32); each stage is skipped when its output exists."""
    what, extra = ABLATIONS[name]
    recipe = BASE + ([] if name == "nodemod" else DEMODULATED) + extra
    run = a.out / name
    run.mkdir(parents=True, exist_ok=True)
    log = run / "ablate.log"
    if not (run / "done").is_file():
        args = ["train", "--data", str(a.data), "--out", str(run), "--max-steps", str(a.steps),
                     "--train-frames", str(a.train_frames), "--val-every-steps", str(a.steps // 3), "--seed", "0"]
        t0 = time.time()
        dvrun.run(args + (["--resume"] if (run / "last.ckpt").is_file() else recipe), log)
        (run / "done").write_text(json.dumps({"train_s": time.time() - t0}))
    model = run / f"{name}.onnx"
    if not model.is_file():
        dvrun.run(["export", str(run / "best.ckpt"), "--out", str(model)], log)
    return {"name": name, "what": what, "args": recipe, "model": str(model),
            "train": json.loads((run / "done").read_text())}


def score(results: list[dict], a: argparse.Namespace) -> dict:
    """One `diviewer eval` over every model, so the reference rows (ladder, noise floor) are scored once."""
    out = a.out / "eval.json"
    models = [r["model"] for r in results]
    if out.is_file():
        cached = json.loads(out.read_text())
        if cached.get("ablate_models") == models:
            return cached
    args = ["eval", "--evalset", str(a.evalset), "--out", str(out)]
    for m in models:
        args += ["--model", m]
    dvrun.run(args, a.out / "eval.log")
    result = json.loads(out.read_text())
    result["ablate_models"] = models
    out.write_text(json.dumps(result, indent=1))
    return result


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
    evaluation = score(results, a)
    (a.out / "ablate.json").write_text(json.dumps({"runs": results, "eval": evaluation}, indent=1))
    lines = table(results, evaluation)
    print("\n".join(lines))
    if a.table:
        a.table.write_text("\n".join(lines) + "\n")


def table(results: list[dict], evaluation: dict) -> list[str]:
    """Markdown rows: one per ablation, then the reference rows; columns per split of the eval JSON."""
    splits = list(evaluation["splits"])
    head = "| row | train s | " + " | ".join(f"{s}: PSNR tm / SSIM tm / FLIP-LDR / eq. spp / checker" for s in splits)
    lines = [head + " |", "|---" * (2 + len(splits)) + "|"]
    for r in results:
        cells = [_cell(evaluation["splits"][s]["methods"][r["name"]]) for s in splits]
        lines.append(f"| {r['what']} | {r['train']['train_s']:.0f} | " + " | ".join(cells) + " |")
    for key in ("direct", "noise_floor"):
        cells = [_cell(evaluation["splits"][s]["methods"][key]) for s in splits]
        lines.append(f"| {evaluation['splits'][splits[0]]['methods'][key]['label']} | - | " + " | ".join(cells) + " |")
    return lines


def _cell(m: dict) -> str:
    """One method's means in one split (evaluate.evaluate_evalset's layout)."""
    eq = m["equivalent_spp"]["psnr_tm"]
    checker = "-" if m["checkerboard"] is None else f"{m['checkerboard']:.2f}"
    return (f"{m['psnr_tm']['mean']:.2f} / {m['ssim_tm']['mean']:.3f} / {m['flip_ldr']['mean']:.3f} / "
            f"{eq['text'] if eq else '-'} / {checker}")


if __name__ == "__main__":
    main()
