"""Which files a scene load reads, so that the scene's identity can cover them (identity.scene_identity)."""

from __future__ import annotations

import contextlib
import contextvars
from pathlib import Path

_reads: contextvars.ContextVar[list | None] = contextvars.ContextVar("diviewer_scene_reads", default=None)


@contextlib.contextmanager
def recording_reads():
    """Collect every file a scene load reads (glTF, buffers, textures, mesh files) into the yielded list,
    cache hits included: the scene's identity hash covers them (diviewer.scene.identity.scene_identity)."""
    files: list[Path] = []
    token = _reads.set(files)
    try:
        yield files
    finally:
        _reads.reset(token)


def note_read(*files: Path) -> None:
    """Record files a scene load depends on (no-op outside `recording_reads`)."""
    files_read = _reads.get()
    if files_read is not None:
        files_read.extend(Path(f) for f in files)
