"""Run `diviewer` from a script: the one place that builds its command line, environment and log.
Usage (from a script in this folder):  import dvrun;  dvrun.run(["train", "--data", D, "--out", R], log=R / "x.log")
Each command runs as `python -m diviewer` with this checkout first on PYTHONPATH (so a script runs the tree it
sits in, not another installed copy) and one thread per library (OMP, MKL, torch: experiments run beside other
work on small machines; pass threads=None to keep the caller's settings). Its output is appended to the log,
after the command line, so a log reads as a record of what ran.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def command(args: list) -> list[str]:
    """``python -m diviewer ARGS`` with every argument as a string."""
    return [sys.executable, "-m", "diviewer", *map(str, args)]


def environment(threads: int | None = 1) -> dict[str, str]:
    """The caller's environment with this checkout first on PYTHONPATH and, unless None, the thread counts."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    if threads is not None:
        env.update(OMP_NUM_THREADS=str(threads), MKL_NUM_THREADS=str(threads), DIVIEWER_TORCH_THREADS=str(threads))
    return env


def run(args: list, log: Path, threads: int | None = 1) -> None:
    """Run ``diviewer ARGS`` to the end, its output appended to ``log``; a non-zero exit raises CalledProcessError."""
    with _opened(log, args) as f:
        subprocess.run(command(args), check=True, stdout=f, stderr=subprocess.STDOUT, env=environment(threads))


def start(args: list, log: Path, threads: int | None = 1) -> subprocess.Popen:
    """Start ``diviewer ARGS`` in the background, its output appended to ``log``; the caller waits or stops it."""
    with _opened(log, args, note="  (in the background)") as f:
        return subprocess.Popen(command(args), stdout=f, stderr=subprocess.STDOUT, env=environment(threads))


def _opened(log: Path, args: list, note: str = ""):
    log.parent.mkdir(parents=True, exist_ok=True)
    f = log.open("a")
    f.write("+ " + " ".join(command(args)) + note + "\n")
    f.flush()
    return f
