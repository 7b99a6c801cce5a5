"""Image files: float EXR (OpenEXR) and 8-bit PNG, written atomically (temporary name, then rename)."""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.faults import write_error


@contextmanager
def atomic_path(path: str | Path, suffix: str | None = None):
    """Yield a temporary path beside ``path``; on success it is renamed onto ``path``.

    A fault while writing (a full disk) removes the temporary file and is raised naming ``path``.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix or path.suffix, dir=path.parent)
    except OSError as exc:
        raise (write_error(exc, {exc.filename: path}) or exc) from None
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; the result gets ordinary permissions
        os.replace(tmp, path)
    except BaseException as exc:
        fault = write_error(exc, {tmp: path})  # before the unlink: a full disk is still full
        Path(tmp).unlink(missing_ok=True)
        if fault is not None:
            raise fault from exc
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text(path: str | Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_exr(path: str | Path, image: np.ndarray, half: bool = False) -> None:
    """Write an (H, W) single-channel ("Z") or (H, W, 3) RGB float image.

    Args:
        half: store float16 instead of float32.
    """
    import OpenEXR

    image = np.asarray(image)
    dtype = np.float16 if half else np.float32
    if image.ndim == 2:
        channels = {"Z": np.ascontiguousarray(image, dtype=dtype)}
    elif image.ndim == 3 and image.shape[2] == 3:
        # OpenEXR writes wrong pixels from non-contiguous views: always pass contiguous arrays.
        channels = {"RGB": np.ascontiguousarray(image, dtype=dtype)}
    else:
        raise ValueError(f"write_exr takes (H, W) or (H, W, 3) arrays, got {image.shape}")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path) as tmp:
        with OpenEXR.File(header, channels) as f:
            f.write(str(tmp))


def read_exr(path: str | Path) -> np.ndarray:
    """Read an EXR written by write_exr: (H, W) for one channel, (H, W, 3) for RGB; float32."""
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise DiviewerError(f"image not found: {path}")
    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            ch = {name: np.array(c.pixels) for name, c in f.channels().items()}
    except Exception as exc:
        raise DiviewerError(f"cannot read EXR {path}: {exc}") from exc
    if set(ch) >= {"R", "G", "B"}:
        return np.stack([ch["R"], ch["G"], ch["B"]], axis=-1).astype(np.float32)
    if len(ch) == 1:
        return next(iter(ch.values())).astype(np.float32)
    raise DiviewerError(f"{path}: unexpected channels {sorted(ch)}")


def write_png(path: str | Path, image: np.ndarray) -> None:
    """Write an (H, W) or (H, W, 3) uint8 image."""
    from PIL import Image

    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"write_png takes uint8 images, got {image.dtype}")
    with atomic_path(path) as tmp:
        Image.fromarray(np.ascontiguousarray(image)).save(tmp, format="PNG")


def read_png(path: str | Path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as img:
        return np.asarray(img.convert("RGB"))


def depth_preview(depth: np.ndarray) -> np.ndarray:
    """Depth as uint8 grey (near bright, far dark, background black), scaled to the frame's range."""
    valid = depth > 0
    out = np.zeros(depth.shape, np.uint8)
    if valid.any():
        lo, hi = float(depth[valid].min()), float(depth[valid].max())
        t = (depth - lo) / max(hi - lo, 1e-12)
        out[valid] = (255 * (1.0 - 0.85 * np.clip(t[valid], 0, 1))).astype(np.uint8)
    return out


def normal_preview(normal: np.ndarray) -> np.ndarray:
    """View-space normals as uint8 RGB (n * 0.5 + 0.5), background black."""
    valid = np.any(normal != 0, axis=-1, keepdims=True)
    return np.where(valid, np.clip(np.nan_to_num(normal) * 0.5 + 0.5, 0, 1) * 255, 0).astype(np.uint8)

