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


class SceneWarning(UserWarning):
    """Something a scene load did not take as the file says, but could go on without (an unhonoured glTF
    extension, a default material): the CLI prints it as one ``warning:`` line."""


_warnings: contextvars.ContextVar[list | None] = contextvars.ContextVar("diviewer_scene_warnings", default=None)


@contextlib.contextmanager
def recording_warnings():
    """Collect the warnings a scene load notes (`note_warning`) into the yielded list (the Scene keeps them)."""
    found: list[str] = []
    token = _warnings.set(found)
    try:
        yield found
    finally:
        _warnings.reset(token)


def note_warning(*messages: str) -> None:
    """Record warnings of a scene load (no-op outside `recording_warnings`); each is said once per load."""
    found = _warnings.get()
    if found is not None:
        found.extend(m for m in messages if m not in found)
