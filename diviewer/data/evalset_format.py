"""An evaluation set on disk: the manifest's kind, its splits, and the reader that refuses a training capture.

Shared by `diviewer evalset` (diviewer/evaluation/evalset.py, which writes one) and `diviewer eval`
(diviewer/evaluation/evaluate.py, which scores on one), so neither imports the other for it.
"""

from __future__ import annotations

from pathlib import Path

from diviewer.data.dataset import Dataset
from diviewer.errors import DiviewerError

KIND = "evalset"
"""The manifest's ``kind`` of an evaluation set (a training capture has none)."""
EVAL_SPLITS = ("unseen_configs", "unseen_objects", "moved_camera", "window_shapes")
"""Every split an evaluation set may have, in plan order (diviewer/evaluation/evalset.py says what each holds)."""


def is_evalset(ds: Dataset) -> bool:
    return ds.manifest.get("kind") == KIND


def load_evalset(path: str | Path) -> Dataset:
    """An evaluation set, refused (with the command that makes one) if the folder is an ordinary capture."""
    ds = Dataset(path)
    if not is_evalset(ds):
        raise DiviewerError("not an evaluation set (a training capture?); make one with "
                            "`diviewer evalset --scene S --out DIR`, or pass a capture with --data", path=path)
    return ds
