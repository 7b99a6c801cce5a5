"""Which files a scene load reads, so that the scene's identity can cover them (identity.scene_identity)."""

from __future__ import annotations

import contextlib
import contextvars
from pathlib import Path

_reads: contextvars.ContextVar[list | None] = contextvars.ContextVar("diviewer_scene_reads", default=None)


@contextlib.contextmanager
def _collecting(var: contextvars.ContextVar):
    """A fresh list set as ``var``'s value for the block, yielded; the value before is put back after."""
    found: list = []
    token = var.set(found)
    try:
        yield found
    finally:
        var.reset(token)


def recording_reads():
    """Collect every file a scene load reads (glTF, buffers, textures, mesh files) into the yielded list,
    cache hits included: the scene's identity hash covers them (diviewer.scene.identity.scene_identity)."""
    return _collecting(_reads)


def note_read(*files: Path) -> None:
    """Record files a scene load depends on (no-op outside `recording_reads`)."""
    files_read = _reads.get()
    if files_read is not None:
        files_read.extend(Path(f) for f in files)


class SceneWarning(UserWarning):
    """Something a scene load did not take as the file says, but could go on without (an unhonoured glTF
    extension, a default material): the CLI prints it as one ``warning:`` line."""


_warnings: contextvars.ContextVar[list | None] = contextvars.ContextVar("diviewer_scene_warnings", default=None)


def recording_warnings():
    """Collect the warnings a scene load notes (`note_warning`) into the yielded list (the Scene keeps them)."""
    return _collecting(_warnings)


def note_warning(*messages: str) -> None:
    """Record warnings of a scene load (no-op outside `recording_warnings`); each is said once per load."""
    found = _warnings.get()
    if found is not None:
        found.extend(m for m in messages if m not in found)
