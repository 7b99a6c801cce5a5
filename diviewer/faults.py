"""Faults a write can meet that are the machine's doing (a full disk, a read-only folder), as one line
naming the user's file: what `diviewer.imageio.atomic_path` raises and the CLI prints."""

from __future__ import annotations

import errno
import os
from pathlib import Path

# OSErrors that are the user's or the machine's doing (a full disk, a read-only folder), not a bug:
# the CLI reports them in one line, naming the file.
ENVIRONMENT_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOTDIR,
                      errno.EISDIR, errno.EEXIST, errno.ENOENT, errno.ENAMETOOLONG, errno.EFBIG, errno.EIO,
                      errno.ENOTEMPTY, errno.EXDEV}


def nearest_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def write_error(exc: BaseException, written: dict) -> BaseException | None:
    """The one-line fault a failed write is, naming the user's file instead of a temporary one, or None.

    Args:
        exc: what the write raised (an OSError; or a library's RuntimeError on a full disk: OpenEXR says
            "No space left on device", torch.save only "unexpected pos").
        written: {temporary path: the user's path} of the files being written.
    """
    names = {str(k): str(v) for k, v in written.items()}
    user = next(iter(names.values()), None)
    if isinstance(exc, OSError) and exc.errno in ENVIRONMENT_ERRNOS:
        name = names.get(str(exc.filename), exc.filename if exc.filename is not None else user)
        if name == exc.filename and exc.filename2 is None:
            return None  # already names the user's file
        return OSError(exc.errno, exc.strerror, name)
    # OpenEXR and torch.save raise RuntimeError, numpy's tofile an OSError without an errno
    # ("4096 requested and 1984 written"): a full disk all the same.
    if type(exc) in (RuntimeError, OSError) and user is not None:
        text = str(exc)
        if os.strerror(errno.ENOSPC) in text or disk_full(Path(user).parent):
            return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), user)
        for tmp, final in names.items():
            if tmp in text:
                return type(exc)(text.replace(tmp, final))
    return None


FULL_BYTES = 1 << 20
"""A folder with less space than this left is full: a library that does not say ENOSPC ran out of it."""


def disk_full(folder: Path) -> bool:
    """Whether the file system holding ``folder`` has (almost) no space or no inodes left."""
    try:
        st = os.statvfs(nearest_existing(folder))
    except OSError:
        return False
    return st.f_bavail * st.f_frsize < FULL_BYTES or (st.f_files > 0 and st.f_favail == 0)
