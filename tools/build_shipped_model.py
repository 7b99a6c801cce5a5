"""Rebuild the shipped models exactly: capture, train and export each with the settings its model card records.

Usage: python tools/build_shipped_model.py [NAME ...] [--work runs/SCENE]
       (NAME: a model in assets/models, e.g. cornell; default: every shipped model)

The settings come from assets/models/NAME.json: scene, resolution, K, target, divide_albedo and
precision always; the capture settings (frames, spp, path depth, seed, splits) and the full training
configuration from its "recipe" block, which `diviewer export` writes into every card. After the
capture the dataset's hash must equal the card's dataset_hash, so the network is trained on the very
data the shipped one saw. A linear baseline
(`diviewer baseline`, e.g. cornell_linear) is fitted again on the capture of the shipped network with
the same dataset hash, over the split and frame count its card's "fit" records.

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
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "assets" / "models"

# Training settings of a recipe, as `diviewer train` spells them; K, target and divide_albedo come
# from the card itself, and how a machine runs a job (device, workers, autocast) is not a recipe.
_TRAIN_FLAGS = {"epochs": "--epochs", "batch_size": "--batch-size", "lr": "--lr", "lambda_L1": "--lambda-l1",
                "ndf": "--ndf", "seed": "--seed", "lr_decay": "--lr-decay", "lr_decay_start": "--lr-decay-start", "val_every": "--val-every",
                "save_every": "--save-every",
                "gan_weight": "--gan-weight", "gan_mode": "--gan-mode", "recon_loss": "--recon-loss",
                "recon_space": "--recon-space", "n_layers_D": "--n-layers-d", "norm_D": "--norm-d", "d_lr": "--d-lr",
                "upsample": "--upsample", "norm": "--norm", "train_frames": "--train-frames", "patience": "--patience",
                "val_every_steps": "--val-every-steps"}
_NOT_RECIPE = {"data", "out", "K", "target", "divide_albedo", "max_steps", "device", "num_workers", "precision",
               "init_from"}


def run(*args: str) -> None:
    print("+ diviewer", " ".join(args), flush=True)
    subprocess.run([sys.executable, "-m", "diviewer", *args], check=True)


def recipe(name: str) -> dict[str, Any]:
    """The model card's settings: what to capture, how to train, how to export; a warm-started model's
    parent recipe under "init" (recursively), built first."""
    card = json.loads((MODELS / f"{name}.json").read_text())
    if card.get("kind") == "linear_baseline":
        return _baseline_recipe(name, card)
    rec = card.get("recipe")
    if not rec:  # cards exported before cards carried a recipe
        sys.exit(f"{MODELS / f'{name}.json'}: no recipe (exported before cards recorded one); cannot rebuild")
    w, h = card["resolution"]
    top = {"K": card["K"], "target": card["target"], "divide_albedo": bool(card.get("divide_albedo"))}
    return _from_recipe(rec, name, card["scene"], f"{w}x{h}", card["precision"] == "fp16", card["dataset_hash"],
                        MODELS / f"{name}.json", top)


def _baseline_recipe(name: str, card: dict) -> dict[str, Any]:
    """A linear baseline (`diviewer baseline`): fitted, not trained, on the capture of the shipped
    network whose card has the same scene and dataset hash (a baseline's card records its fit, not
    how its data was captured)."""
    for other in sorted(MODELS.glob("*.json")):
        net = json.loads(other.read_text())
        if (net.get("recipe") and net.get("scene") == card["scene"]
                and net.get("dataset_hash") == card["dataset_hash"]):
            w, h = card["resolution"]
            return {"name": name, "kind": "linear_baseline", "scene": card["scene"], "res": f"{w}x{h}",
                    "K": card["K"], "target": card["target"], "divide_albedo": False, "fp16": False,
                    "dataset_hash": card["dataset_hash"], "capture": net["recipe"]["capture"], "train": {},
                    "init": None, "fit": {"split": card["fit"]["split"], "frames": card["fit"]["frames"]}}
    sys.exit(f"{MODELS / f'{name}.json'}: dataset_hash {card['dataset_hash'][:16]} is no shipped network's "
             f"(whose recipe says how to capture that data); cannot rebuild the baseline")


def _from_recipe(rec: dict, name: str, scene: str, res: str, fp16: bool, dataset_hash: str, where: Path,
                 top: dict | None = None) -> dict[str, Any]:
    train = {k: v for k, v in rec["train"].items() if k in _TRAIN_FLAGS and v is not None}
    defaults = _train_defaults()
    odd = {k: v for k, v in rec["train"].items()
           if k not in _TRAIN_FLAGS and k not in _NOT_RECIPE and v != defaults.get(k, v)}
    if odd:  # a setting `diviewer train` cannot be given: rebuilding would not be exact
        sys.exit(f"{where}: recipe settings {odd} have no train option; cannot rebuild exactly")
    nets = top or {k: rec["train"][k] for k in ("K", "target", "divide_albedo")}
    r = {"name": name, "scene": scene, "res": res, "K": nets["K"], "target": nets["target"],
         "divide_albedo": bool(nets["divide_albedo"]), "fp16": fp16, "dataset_hash": dataset_hash,
         "capture": rec["capture"], "train": train, "init": None}
    if rec.get("init"):
        init = rec["init"]
        r["init"] = _from_recipe(init["recipe"], f"{name}_init", scene, res, fp16, init["dataset_hash"], where)
        r["init"]["checkpoint_sha256"] = init["checkpoint_sha256"]
    return r


def _train_defaults() -> dict[str, Any]:
    import dataclasses

    from diviewer.train.config import TrainConfig

    return {f.name: f.default for f in dataclasses.fields(TrainConfig)}


def build(r: dict[str, Any], work: Path, max_steps: int | None = None) -> None:
    """Capture, train (its parent first, if it was warm-started), export and evaluate one model; a
    linear baseline is fitted on its capture instead."""
    out = MODELS / f"{r['name']}.onnx"
    if r.get("kind") == "linear_baseline":
        data = capture(r, work)
        run("baseline", "--data", str(data), "--out", str(out), "--split", r["fit"]["split"],
            "--max-frames", str(r["fit"]["frames"]))
        run("eval", "--model", str(out), "--data", str(data), "--split", "test")
        return
    run_dir, data = train_run(r, work, max_steps)
    run("export", str(run_dir / "best.ckpt"), "--out", str(out), *(["--fp16"] if r["fp16"] else []))
    shutil.copyfile(run_dir / "curves.png", out.with_name(f"{r['name']}_curves.png"))
    shutil.copyfile(run_dir / "metrics.csv", out.with_name(f"{r['name']}_metrics.csv"))
    run("eval", "--model", str(out), "--data", str(data), "--split", "test")


def capture(r: dict[str, Any], work: Path) -> Path:
    """The recipe's dataset, captured (or resumed) into work/data (data2, ... where another capture is
    there) and checked against the card's dataset hash."""
    from diviewer.data.dataset import Dataset

    c = r["capture"]
    data = work / "data"  # one folder per capture: a parent on another capture gets its own
    for n in range(100):
        manifest = data / "manifest.json"
        if not manifest.is_file() or Dataset(data).hash == r["dataset_hash"]:
            break
        data = work / f"data{n + 2}"
    run("capture", "--scene", r["scene"], "--frames", str(c["frames"]), "--res", r["res"], "--spp", str(c["spp"]),
        "--max-depth", str(c["max_depth"]), "--seed", str(c["seed"]),
        "--splits", ",".join(str(f) for f in c["split_fractions"]), "--gt", c.get("gt", "pt"),
        "--dtype", c.get("dtype", "float16"), "--out", str(data))
    run("data", "check", str(data), "--fast")
    if Dataset(data).hash != r["dataset_hash"]:
        sys.exit(f"{data}: dataset hash {Dataset(data).hash[:16]} is not the card's {r['dataset_hash'][:16]} "
                 f"({r['name']}): this capture differs from the shipped model's; not building")
    return data


def train_run(r: dict[str, Any], work: Path, max_steps: int | None = None) -> tuple[Path, Path]:
    """The trained run folder of a recipe (resumed if it exists) and its dataset folder."""
    from diviewer.data.dataset import sha256_file

    data = capture(r, work)
    run_dir = work / f"train_{r['name']}"
    train = ["train", "--data", str(data), "--out", str(run_dir), "--k", str(r["K"]), "--target", r["target"]]
    if r["divide_albedo"]:
        train.append("--divide-albedo")
    for k, v in r["train"].items():
        train += [_TRAIN_FLAGS[k], str(v)]
    if r["init"] is not None:  # warm-started: the parent's best checkpoint, rebuilt from its own recipe
        parent_dir, _ = train_run(r["init"], work)
        parent = parent_dir / "best.ckpt"
        if sha256_file(parent) != r["init"]["checkpoint_sha256"]:
            print(f"note: {parent} is not bit for bit the checkpoint the shipped model started from "
                  "(training is not bitwise reproducible across machines); going on from it", flush=True)
        train += ["--init-from", str(parent)]
    if max_steps is not None:  # where the shipped run was stopped (its card's "steps" is the best step)
        train += ["--max-steps", str(max_steps)]
    if (run_dir / "last.ckpt").is_file():
        train.append("--resume")
    run(*train)
    return run_dir, data


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="models in assets/models (default: all shipped models)")
    ap.add_argument("--work", type=Path, default=None, help="dataset and run folders (default runs/SCENE)")
    ap.add_argument("--max-steps", type=int, default=None,
                    help="stop training there (the README says where each shipped model's run stopped)")
    a = ap.parse_args()
    names = a.names or sorted(p.stem for p in MODELS.glob("*.onnx"))  # cards beside models; not *_ladder.json
    missing = [n for n in names if not (MODELS / f"{n}.json").is_file()]
    if missing:
        sys.exit(f"no model card {', '.join(str(MODELS / f'{n}.json') for n in missing)}")
    for name in names:
        r = recipe(name)
        print(f"== {name}: {r['scene']} {r['res']} K={r['K']} {r['target']} "
              f"{'fp16' if r['fp16'] else 'fp32'}, capture {r['capture']}, train {r['train']}", flush=True)
        build(r, a.work or ROOT / "runs" / r["scene"], a.max_steps)


if __name__ == "__main__":
    main()
