"""Training speed on this machine: the trainer's own steps (`diviewer.train.step.train_step` on the trainer's
batches: aspect crops, light scales, world inputs) timed for several ways of running the generator.

Usage: python tools/experiments/train_speed.py --data DATA [--recipe R] [--k 16] [--frames 160] [--steps 34]
           [--variants eager,compile,channels_last,eager,compile] [--out OUT.json]

Variants, each on freshly built networks with the same seed and the same batches:
- ``eager``: as `diviewer train` runs (PyTorch eager).
- ``compile``: the generator under ``torch.compile(dynamic=False)`` (Inductor; one graph per crop shape).
- ``channels_last``: the generator's weights and inputs in NHWC (oneDNN's preferred layout on x86).

The first ``--warmup`` steps of each variant (compilation, allocator, the first of each crop shape) are
reported apart; the median and mean of the rest are the variant's pace. A variant may be named again: the
rounds, taken in turn, show how much of a difference is this machine's noise. Nothing is written but ``--out``
(the networks train in memory; the run folder is a temporary one).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
import types
from pathlib import Path

VARIANTS = ("eager", "compile", "channels_last")


def measure(cfg, steps: int, variants: list[str], warmup: int = 6, log=print) -> list[dict]:
    """Milliseconds per `train_step` for each variant, in the order given (a variant may come back: rounds), on
    the first ``steps + warmup`` batches of epoch 0 of ``cfg``."""
    import torch

    from diviewer.train import distributed, trainer
    from diviewer.train.step import train_step

    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        raise ValueError(f"unknown variant {unknown[0]!r}; one of {', '.join(VARIANTS)}")
    out: list[dict] = []
    for variant in variants:
        torch._dynamo.reset()  # a variant that comes back compiles again, as a fresh process would
        torch.manual_seed(cfg.seed)
        dev = distributed.setup(cfg)
        run, nets, _ = trainer._prepare(cfg, dev, lambda *_: None, False)
        if variant == "compile":
            nets.netG = torch.compile(nets.netG, dynamic=False)
        elif variant == "channels_last":
            nets.netG = nets.netG.to(memory_format=torch.channels_last)
        batches = distributed.epoch_batches(len(run.train_arr), 0, cfg.seed, cfg.batch_size, 0, 1)
        n = min(steps + warmup, len(batches))
        times, shapes = [], []
        for i, x16 in zip(range(n), distributed.loader(run.train_arr, batches, cfg, dev)):
            t = time.perf_counter()
            b = trainer._batch(run, x16, batches[i], 0, i)
            if variant == "channels_last":
                b["real_A"] = b["real_A"].contiguous(memory_format=torch.channels_last)
            train_step(nets, b)
            times.append(time.perf_counter() - t)
            shapes.append(list(b["real_A"].shape))
        timed = times[warmup:] or times
        row = {"variant": variant, "median_ms": 1e3 * statistics.median(timed),
               "mean_ms": 1e3 * statistics.mean(timed), "steps_timed": len(timed),
               "warmup_s": [round(t, 3) for t in times[:warmup]], "shapes": sorted({tuple(s) for s in shapes})}
        out.append(row)
        log(f"{variant}: median {row['median_ms']:.1f} ms a step over {len(timed)} steps "
            f"(mean {row['mean_ms']:.1f}); warm-up {row['warmup_s']} s")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--recipe", default="sponza")
    ap.add_argument("--k", type=int, default=16)
    ap.add_argument("--frames", type=int, default=160, help="train frames held in memory (the first by index)")
    ap.add_argument("--steps", type=int, default=34)
    ap.add_argument("--warmup", type=int, default=6)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    import torch

    from diviewer import provenance
    from diviewer.train.cli import resolve_config

    with tempfile.TemporaryDirectory() as tmp:
        args = types.SimpleNamespace(data=a.data, out=Path(tmp) / "run", recipe=a.recipe, K=a.k,
                                     train_frames=a.frames)
        cfg = resolve_config(args)
        result = measure(cfg, a.steps, [v for v in a.variants.split(",") if v], a.warmup)
    record = {"data": str(a.data), "recipe": a.recipe, "K": a.k, "batch_size": cfg.batch_size,
              "train_frames": a.frames, "torch": torch.__version__, "threads": torch.get_num_threads(),
              "cpu": provenance.cpu_model(), "rounds": result}
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, record)  # atomic
    return 0


if __name__ == "__main__":
    sys.exit(main())
