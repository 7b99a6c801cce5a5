"""`python -m diviewer.train.cli`, torchrun's entry: `diviewer train` on its own, its options and its one-line
errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _entry(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "diviewer.train.cli", *argv], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)


def test_the_entry_is_the_train_command():
    r = _entry("--help")
    assert r.returncode == 0 and r.stdout.startswith("usage: diviewer.train.cli train"), r.stderr
    assert "--data DATA" in r.stdout and "--recipe R" in r.stdout and "[the cornell recipe:" in r.stdout


def test_a_user_error_is_one_line_and_exit_2(tmp_path):
    (tmp_path / "run").write_text("a file where the run folder goes")
    r = _entry("--data", str(tmp_path / "data"), "--out", str(tmp_path / "run"))
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert r.returncode == 2 and len(lines) == 1 and lines[0].startswith("diviewer train: error:"), r.stderr
