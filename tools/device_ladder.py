"""A recipe's capture and K ladder inside one accelerator lease, against a deadline (tools/device_lease.sh sets up).

Usage on the device:  python3 tools/device_ladder.py --recipe assets/recipes/sponza.toml --minutes 23

1. capture: the recipe's [capture] (scene from [recipe] scene) in --shards processes into WORK/data, then
   `diviewer data check --fast`;
2. probe: every K of the ladder trained side by side for a few hundred steps (the rate they will share);
3. sizing: the recipe's epochs (and lr_decay_start, in the same proportion) cut to what the rate fits before the
   deadline, never raised; the sized recipe is written to WORK/recipe.toml, the file the runs train with, so
   their cards record the recipe as run (it comes back with the results: ship it as the scene's recipe);
4. the ladder trained side by side (`diviewer train --recipe WORK/recipe.toml --k K`), each exported to
   WORK/models/walk_kK.onnx (float32 unless the recipe's [export] fp16);
5. `diviewer eval` of the models on the capture's test split (WORK/test_split.json: the data stays there) and on
   the compact evaluation set (WORK/eval_compact.json); tools/device_pack.sh brings back the rest.

Measured on an H100 (2026-11-24, docs/sponza.md): Sponza at 228x128, 128 spp, area direct light, 8 shards: 1.2-1.4 s
a frame each, the GPU 5 % busy (host-bound): give --shards the core count. The machine goes back 30 s after a call
ends, and the data with it: keep the calls back to back, or size the run (--minutes) to one 10-minute call.

Everything logs to stdout; WORK/ladder.json records the plan, the rates, the times and what finished. A run the
deadline cuts is killed and exported from its best checkpoint, and ladder.json says so.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from diviewer.train.recipe import load_recipe  # noqa: E402

DV = [sys.executable, "-m", "diviewer"]
PROBE_STEPS = 400
EXPORT_SECONDS = 150.0
"""Kept back from the deadline for the exports, their verification and the two evaluations."""


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


def capture_args(cap: dict, scene: str, out: Path) -> list[str]:
    """`diviewer capture` options that reproduce a recipe's [capture] table."""
    args = ["capture", "--scene", scene, "--out", str(out), "--frames", str(cap["frames"]),
            "--res", f"{cap['width']}x{cap['height']}", "--spp", str(cap["spp"]), "--max-depth", str(cap["max_depth"]),
            "--seed", str(cap["seed"]), "--splits", ",".join(f"{f:g}" for f in cap["split_fractions"]),
            "--gt", cap["gt"], "--dtype", cap["dtype"]]
    if cap.get("direct_samples", 1) != 1:
        args += ["--direct-samples", str(cap["direct_samples"])]
    return args


def run_all(cmds: list[list[str]], logs: list[Path], deadline: float | None = None) -> list[int | None]:
    """Run commands side by side; kill what is still running at ``deadline``; their return codes (None: killed)."""
    procs = []
    for cmd, lp in zip(cmds, logs):
        procs.append(subprocess.Popen(cmd, stdout=lp.open("w"), stderr=subprocess.STDOUT, start_new_session=True))
    while any(p.poll() is None for p in procs):
        if deadline is not None and time.time() > deadline:
            for p in procs:
                if p.poll() is None:
                    log(f"deadline: killing {' '.join(p.args[3:8])}")
                    p.kill()
            break
        time.sleep(5)
    return [p.wait() if p.returncode is not None or p.poll() is not None else None for p in procs]


def metrics_rate(run: Path) -> float:
    """Steps per second between the first and last validation rows of a run's metrics.csv."""
    rows = list(csv.DictReader((run / "metrics.csv").open()))
    if len(rows) < 2:
        raise RuntimeError(f"{run}: fewer than two metrics rows to time")
    a, b = rows[0], rows[-1]
    return (int(b["step"]) - int(a["step"])) / max(float(b["seconds"]) - float(a["seconds"]), 1e-6)


def sized_recipe(src: Path, dst: Path, epochs: int, decay_start: int, note: str) -> None:
    """The recipe file with its epochs and lr_decay_start replaced (and a comment saying why)."""
    text = src.read_text()
    text = re.sub(r"(?m)^epochs\s*=.*$", f"epochs = {epochs}", text)
    text = re.sub(r"(?m)^lr_decay_start\s*=.*$", f"lr_decay_start = {decay_start}", text)
    dst.write_text(f"# {note}\n" + text)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recipe", type=Path, required=True)
    ap.add_argument("--minutes", type=float, required=True, help="from now until every model is exported")
    ap.add_argument("--work", type=Path, default=Path("/tmp/dv"))
    ap.add_argument("--shards", type=int, default=os.cpu_count() or 8,
                    help="capture processes (default: one per core; the capture is host-bound)")
    args = ap.parse_args()
    t0 = time.time()
    deadline = t0 + args.minutes * 60
    rec = load_recipe(args.recipe)
    w = args.work
    (w / "logs").mkdir(parents=True, exist_ok=True)
    data = w / "data"
    record: dict = {"recipe": str(args.recipe), "minutes": args.minutes, "started": time.ctime(t0), "ks": list(rec.ks())}

    def save() -> None:
        (w / "ladder.json").write_text(json.dumps(record, indent=1))

    cap = capture_args(rec.capture, rec.scene, data)
    n = args.shards
    codes = run_all([DV + cap + ["--shard", f"{k}/{n}"] for k in range(1, n + 1)],
                    [w / "logs" / f"capture_{k}.log" for k in range(1, n + 1)])
    record["capture_seconds"] = round(time.time() - t0, 1)
    log(f"capture done in {record['capture_seconds']} s, return codes {codes}")
    save()
    if any(codes) or subprocess.run(DV + ["data", "check", "--fast", str(data)]).returncode:
        log("capture or check failed")
        return 1

    ks = rec.ks()
    t1 = time.time()
    probe = [DV + ["train", "--data", str(data), "--out", str(w / f"probe_k{k}"), "--recipe", str(args.recipe),
                   "--k", str(k), "--max-steps", str(PROBE_STEPS), "--val-every-steps", str(PROBE_STEPS // 2)] for k in ks]
    run_all(probe, [w / "logs" / f"probe_k{k}.log" for k in ks])
    rates = {k: metrics_rate(w / f"probe_k{k}") for k in ks}
    load = max(time.time() - t1 - PROBE_STEPS / min(rates.values()), 0.0)
    record.update(probe_rates=rates, probe_seconds=round(time.time() - t1, 1), load_seconds=round(load, 1))
    train = rec.train
    spe = record["steps_per_epoch"] = steps_per_epoch(data, train)
    seconds = deadline - time.time() - load - EXPORT_SECONDS
    fit = int(min(rates.values()) * seconds * 0.95 // spe)
    epochs = max(1, min(int(train["epochs"]), fit))
    share = train.get("lr_decay_start", 0) / (int(train["epochs"]) * spe)
    decay = int(round(share * epochs * spe / 500) * 500)
    note = (f"sized by tools/device_ladder.py in a lease: {epochs} of the recipe's {train['epochs']} epochs fit "
            f"({min(rates.values()):.1f} steps/s for the slowest K side by side, {spe} steps an epoch)")
    sized = w / "recipe.toml"
    sized_recipe(args.recipe, sized, epochs, decay, note)
    record.update(epochs=epochs, lr_decay_start=decay, sized_recipe=str(sized))
    log(note)
    save()

    t2 = time.time()
    runs = [w / f"train_k{k}" for k in ks]
    codes = run_all([DV + ["train", "--data", str(data), "--out", str(r), "--recipe", str(sized), "--k", str(k)]
                     for k, r in zip(ks, runs)], [w / "logs" / f"train_k{k}.log" for k in ks],
                    deadline=deadline - EXPORT_SECONDS)
    record["train_seconds"] = round(time.time() - t2, 1)
    record["finished"] = {k: c == 0 for k, c in zip(ks, codes)}
    save()
    (w / "models").mkdir(exist_ok=True)
    fp16 = ["--fp16"] if rec.export.get("fp16") else []
    for k, r in zip(ks, runs):
        out = w / "models" / f"walk_k{k}.onnx"
        c = subprocess.run(DV + ["export", str(r / "best.ckpt"), "--out", str(out)] + fp16).returncode
        log(f"export K={k}: {'ok' if c == 0 else 'failed'}")
    models = [a for k in ks for a in ("--model", str(w / "models" / f"walk_k{k}.onnx"))
              if (w / "models" / f"walk_k{k}.onnx").is_file()]
    if not models:
        log("no model exported")
        return 1
    # the ladder rule's figure (the capture's test split: the data stays on this machine) and the compact
    # evaluation set shipped in assets/evalsets (`diviewer ship ladder` takes both)
    subprocess.run(DV + ["eval", "--data", str(data), "--split", "test", *models, "--out", str(w / "test_split.json")])
    subprocess.run(DV + ["eval", *models, "--out", str(w / "eval_compact.json")])
    record["total_seconds"] = round(time.time() - t0, 1)
    save()
    log("done")
    return 0


def steps_per_epoch(data: Path, train: dict) -> int:
    """Optimizer steps in one epoch of the capture's train split at the recipe's batch size."""
    m = json.loads((data / "manifest.json").read_text())
    n_train = sum(1 for f in m["frame_list"] if f.get("split") == "train") if "frame_list" in m else None
    if not n_train:
        raise RuntimeError(f"{data}/manifest.json: no train frames listed")
    frames = min(n_train, train.get("train_frames") or n_train)
    return frames // int(train["batch_size"])


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    raise SystemExit(main())
