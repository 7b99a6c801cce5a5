"""Where commands write: output paths checked up front, strict JSON, and staged writes that leave
an earlier result intact until the whole new one is known good (temporary names, then renames)."""

from __future__ import annotations

import errno
import json
import math
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

from diviewer.errors import DiviewerError

# OSErrors that are the user's or the machine's doing (a full disk, a read-only folder), not a bug:
# the CLI reports them in one line, naming the file.
ENVIRONMENT_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOTDIR,
                      errno.EISDIR, errno.EEXIST, errno.ENOENT, errno.ENAMETOOLONG, errno.EFBIG, errno.EIO,
                      errno.ENOTEMPTY, errno.EXDEV}


def _nearest_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _writable_from(path: Path, option: str, folder: Path | None = None) -> None:
    """The folders that would be created for ``path`` (inside ``folder``, default ``path`` itself: a folder
    to make) can be: the nearest existing one is a writable folder."""
    anchor = _nearest_existing(folder if folder is not None else path)
    if not anchor.is_dir():
        raise DiviewerError(f"{anchor} is a file, so {path} cannot be created under it", field=option)
    if not os.access(anchor, os.W_OK | os.X_OK):
        raise DiviewerError(f"folder {anchor} is not writable", field=option)


def check_output_dir(path: str | Path, option: str = "--out") -> Path:
    """Refuse an output folder that is a file or cannot be created or written, before any work."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise DiviewerError(f"{path} is a file; give a folder", field=option)
    _writable_from(path, option)
    return path


def check_output_file(path: str | Path, option: str = "--out", protect: tuple = (), suffix: str | None = None) -> Path:
    """Refuse an output file that is a folder, lies under a file, is unwritable, or is one of ``protect``.

    Args:
        protect: files the command reads (its inputs) or writes besides this one: never overwritten.
        suffix: the extension the file must have (e.g. ``.onnx``), or None.
    """
    path = Path(path)
    if path.is_dir() or str(path).endswith(os.sep):
        raise DiviewerError(f"{path} is a folder; give a file name", field=option)
    if suffix is not None and path.suffix.lower() != suffix:
        raise DiviewerError(f"expected a {suffix} file name, got {path.name}", field=option)
    for other in protect:
        if other is not None and _same_file(path, Path(other)):
            raise DiviewerError(f"{path} is also {other}, which this command reads or writes itself; "
                                f"give another file name", field=option)
    _writable_from(path, option, folder=path.parent)  # an existing file is overwritten, not made a folder
    if path.exists() and not os.access(path, os.W_OK):
        raise DiviewerError(f"{path} is not writable", field=option)
    return path


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return a.samefile(b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def strict(obj):
    """``obj`` with every non-finite float replaced by None, so that it is strict JSON (no NaN/Infinity)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: strict(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict(v) for v in obj]
    if hasattr(obj, "item") and hasattr(obj, "dtype"):  # numpy scalars
        return strict(obj.item())
    return obj


def dumps(obj, **kwargs) -> str:
    """Strict JSON text: non-finite numbers become null (``json`` would write NaN/Infinity, which is not JSON)."""
    return json.dumps(strict(obj), allow_nan=False, **kwargs)


def write_json(path: str | Path, obj, **kwargs) -> None:
    """Write strict JSON atomically (temporary name, then rename)."""
    from diviewer.imageio import write_text

    write_text(path, dumps(obj, **kwargs))


class Staging:
    """Files written under temporary names beside their final ones, renamed into place together.

    ``stage(final)`` returns the temporary path to write; ``commit`` renames them all (renames
    cannot run out of space); ``discard`` removes them, leaving whatever was there before.
    """

    def __init__(self):
        self._pending: list[tuple[Path, Path]] = []

    def __call__(self, final: str | Path) -> Path:
        final = Path(final)
        final.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{final.name}.", suffix=final.suffix, dir=final.parent)
        os.close(fd)
        self._pending.append((Path(tmp), final))
        return Path(tmp)

    def commit(self) -> None:
        mask = os.umask(0)
        os.umask(mask)
        for tmp, final in self._pending:
            os.chmod(tmp, 0o666 & ~mask)  # mkstemp makes 0600; results get ordinary permissions
            os.replace(tmp, final)
        self._pending.clear()

    def discard(self) -> None:
        for tmp, _ in self._pending:
            tmp.unlink(missing_ok=True)
        self._pending.clear()


@contextmanager
def staged():
    """A Staging committed when the block succeeds and discarded when it raises."""
    st = Staging()
    try:
        yield st
    except BaseException:
        st.discard()
        raise
    st.commit()
