"""One run per output folder: an advisory lock (fcntl.flock) held for a run's life, its owner written inside.

A second `capture`, `evalset` or `train` into the same folder refuses at once, naming the owner. The
kernel drops a flock when its holder dies, so the file a killed run left is taken over by the next run;
a run that ends removes its lock file. Capture shards (``--shard k/n``) into one folder each hold a lock
of their own and refuse only a run whose frames overlap theirs (the whole capture, or a shard k'/n'
that shares frames). Folders written before locks existed have no lock file: the first run makes one.
"""

from __future__ import annotations

import fcntl
import json
import math
import os
import socket
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from diviewer.errors import DiviewerError

PREFIX = ".diviewer"
SUFFIX = ".lock"
TRIES = 5
"""Attempts at a lock before refusing: another run's check of stale locks holds one for an instant."""
RETRY_S = 0.05


def lock_path(folder: Path, part: str | None = None) -> Path:
    """The lock file of ``folder`` (``part``: a shard's own, e.g. ``shard-2-of-4``)."""
    return Path(folder) / f"{PREFIX}{'.' + part if part else ''}{SUFFIX}"


def shard_part(k: int, n: int) -> str | None:
    """The lock part of capture shard k/n (1-based); None for the whole capture."""
    return None if n == 1 else f"shard-{k}-of-{n}"


def _shard_of(part: str | None) -> tuple[int, int] | None:
    if part is None:
        return None
    try:
        _, k, _, n = part.split("-")
        return int(k), int(n)
    except ValueError:
        return None


def shards_overlap(a: str | None, b: str | None) -> bool:
    """Whether two runs' frames overlap: only two shards k/n and k'/n' with disjoint frames do not.

    Frame i is shard k/n's when i = k-1 (mod n); both congruences hold for some i iff
    k-1 = k'-1 (mod gcd(n, n')).
    """
    sa, sb = _shard_of(a), _shard_of(b)
    if sa is None or sb is None:
        return True
    (k, n), (k2, n2) = sa, sb
    return (k - k2) % math.gcd(n, n2) == 0


def _owner_text(path: Path) -> str:
    try:
        info = json.loads(path.read_text() or "{}")
    except (OSError, ValueError):
        info = {}
    if not isinstance(info, dict) or "pid" not in info:
        return "another run (its lock file names no owner yet)"
    what = f"diviewer {info.get('command', '?')}"
    if info.get("part"):
        what += f" ({info['part'].replace('-of-', '/').replace('shard-', 'shard ')})"
    return f"{what}, pid {info['pid']} on host {info.get('host', '?')} since {info.get('started', '?')}"


def holder(folder: str | Path, part: str | None = None) -> str | None:
    """Who holds ``folder``'s lock now (its command, pid, host and start), or None where no live run does."""
    path = lock_path(Path(folder), part)
    return _owner_text(path) if _held(path) else None


def _refuse(folder: Path, other: Path, option: str) -> DiviewerError:
    return DiviewerError(f"another run is writing here: {_owner_text(other)}; wait for it to end or give another "
                         f"{option} (its lock: {other.name})", path=folder, field=option)


def _take(path: Path) -> int | None:
    """Open and exclusively lock ``path``; the descriptor, or None while another process holds it."""
    for attempt in range(TRIES):
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            time.sleep(RETRY_S)
            continue
        try:  # the file may have been removed by its previous owner between our open and our lock
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return fd
        os.close(fd)
    return None


def _held(path: Path) -> bool:
    """Whether a live process holds the lock file ``path`` (a killed run's file is not held)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    except FileNotFoundError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return False
    except BlockingIOError:
        return True
    finally:
        os.close(fd)  # closing drops the shared lock we may have taken


@contextmanager
def run_lock(folder: str | Path, command: str, part: str | None = None, option: str = "--out"):
    """Hold ``folder``'s run lock for the block; refuse at once (DiviewerError) if another run holds it.

    Args:
        command: the subcommand, written into the lock file with the pid, host and start time.
        part: a capture shard's part (``shard_part``): shards with disjoint frames share the folder.
        option: the option that named the folder, for the message.
    """
    folder = Path(folder)
    created = not folder.exists()
    folder.mkdir(parents=True, exist_ok=True)
    path = lock_path(folder, part)
    fd = _take(path)
    if fd is None:
        raise _refuse(folder, path, option)
    try:
        for other in sorted(folder.glob(f"{PREFIX}*{SUFFIX}")):
            if other.name == path.name:
                continue
            other_part = other.name[len(PREFIX):-len(SUFFIX)].lstrip(".") or None
            if shards_overlap(part, other_part) and _held(other):
                raise _refuse(folder, other, option)
        info = {"pid": os.getpid(), "host": socket.gethostname(), "command": command, "part": part,
                "started": time.strftime("%Y-%m-%d %H:%M:%S %Z"), "argv": sys.argv}
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(info) + "\n").encode(), 0)
        os.fsync(fd)
    except BaseException:
        _release(fd, path, folder, created)
        raise
    try:
        yield path
    finally:
        _release(fd, path, folder, created)


def _release(fd: int, path: Path, folder: Path, created: bool) -> None:
    """Remove the lock file while still holding it (a waiting opener then sees another inode), then unlock."""
    try:
        path.unlink(missing_ok=True)
    finally:
        os.close(fd)
    if created:
        try:
            folder.rmdir()  # a run refused before it wrote anything leaves no empty folder behind
        except OSError:
            pass
