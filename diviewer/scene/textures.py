"""Base-colour texture files decoded by their real format (8/16/32-bit integer, float), within a size cap."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.scene.colour import srgb_to_linear
from diviewer.scene.reads import note_read

MAX_TEXTURE_SIDE = 4096
"""Longest side of a texture, in pixels. Textures are held as float32 RGB(A) on the CPU and the GPU
(4096 x 4096: 256 MiB each); a larger one is refused with the command that downscales it."""

_cache: dict[tuple, tuple[np.ndarray, np.ndarray | None]] = {}


def frozen_array(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)  # shared by every scene that loads the same file
    return a


def file_key(file: Path, what: str, path, field: str) -> tuple:
    """The cache key of an existing file (its path, mtime and size: an edited file is read again); records the read."""
    if not file.is_file():
        raise DiviewerError(f"{what} file not found: {file}", path=path, field=field)
    note_read(file)
    st = file.stat()
    return (str(file.resolve()), st.st_mtime_ns, st.st_size)


def _integer_bits(im) -> int:
    """Bits per sample of a single-channel integer image (Pillow's mode ``I``: PNG 16-bit or TIFF 16/32-bit)."""
    if im.format == "PNG":
        return 16
    tags = getattr(im, "tag_v2", None)
    bits = tags.get(258) if tags is not None else None
    if isinstance(bits, (tuple, list)):
        bits = bits[0]
    return int(bits) if bits else 32


def decode(im, file: Path, *, path=None, field: str = "") -> tuple[np.ndarray, np.ndarray | None]:
    """A loaded Pillow image as (H, W, 3) linear float32 colour and (H, W) alpha or None, by its real format.

    Integer images (8, 16 or 32 bits) hold sRGB-encoded colour, scaled by their own maximum: a 16-bit
    greyscale PNG is grey, not white (Pillow's ``convert`` would clip it to 8 bits). Float images
    (``F``: float TIFF) hold linear values, which must lie in [0, 1] (a base colour is a reflectance).
    """
    mode = im.mode
    if mode.startswith("I;16"):  # 16-bit greyscale, any byte order
        grey = np.asarray(im, dtype=np.float64) / 65535.0
        return srgb_to_linear(np.repeat(grey[..., None], 3, -1)).astype(np.float32), None
    if mode == "I":
        raw = np.asarray(im, dtype=np.float64)
        bits = _integer_bits(im)
        if raw.size and raw.min() < 0:
            raise DiviewerError(f"texture {file} has negative values (a signed integer image): not a colour",
                                path=path, field=field)
        grey = raw / float(2 ** bits - 1)
        return srgb_to_linear(np.repeat(np.clip(grey, 0.0, 1.0)[..., None], 3, -1)).astype(np.float32), None
    if mode == "F":
        lin = np.asarray(im, dtype=np.float32)
        if not np.all(np.isfinite(lin)):
            raise DiviewerError(f"texture {file} has NaN or infinite values", path=path, field=field)
        if lin.size and (lin.min() < 0.0 or lin.max() > 1.0):
            raise DiviewerError(f"float texture {file} has values in [{lin.min():.3g}, {lin.max():.3g}]; a base colour "
                                f"is a reflectance in [0, 1]: rescale it", path=path, field=field)
        return np.repeat(lin[..., None], 3, -1).astype(np.float32), None
    has_alpha = mode in ("RGBA", "LA", "PA", "RGBa", "La") or (mode == "P" and "transparency" in im.info)
    arr = np.asarray(im.convert("RGBA" if has_alpha else "RGB"), dtype=np.float32) / 255.0
    return srgb_to_linear(arr[..., :3]).astype(np.float32), (arr[..., 3] if has_alpha else None)


def load_texture(file: Path, *, path=None, field: str = "") -> tuple[np.ndarray, np.ndarray | None]:
    """An image file as a linear (H, W, 3) float32 texture, top row first, and its alpha (H, W) or None.

    The colour is decoded from sRGB (as stored by integer image files; float files are linear); alpha is
    linear. Cached per file.

    Raises:
        DiviewerError: the file is missing, not a readable image or larger than `MAX_TEXTURE_SIDE`,
            naming the file and ``field``.
    """
    file = Path(file)
    key = file_key(file, "texture", path, field)
    if key not in _cache:
        _cache[key] = _decoded(file, file, path, field)
    return _cache[key]


def load_texture_bytes(data: bytes, label: str, *, path=None, field: str = "") -> tuple[np.ndarray, np.ndarray | None]:
    """An image held in memory (a glTF's embedded data URI or buffer view) as `load_texture` reads a file;
    ``label`` names it in errors. Cached by its content."""
    import hashlib
    import io

    key = ("bytes", hashlib.sha256(data).hexdigest())
    if key not in _cache:
        _cache[key] = _decoded(io.BytesIO(data), label, path, field)
    return _cache[key]


def _decoded(source, file, path, field: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Open ``source`` (a path or a file object; ``file`` names it) with Pillow and decode it, within the size cap."""
    from PIL import Image

    try:
        with Image.open(source) as im:
            w, h = im.size
            if max(w, h) > MAX_TEXTURE_SIDE:
                raise _too_large(file, w, h, path, field)
            im.load()
            rgb, alpha = decode(im, file, path=path, field=field)
    except DiviewerError:
        raise
    except Image.DecompressionBombError as exc:
        raise DiviewerError(f"texture {file} is larger than {MAX_TEXTURE_SIDE} px on a side ({exc}); downscale it",
                            path=path, field=field) from exc
    except Exception as exc:  # Pillow raises several types for truncated or foreign files
        raise DiviewerError(f"cannot read texture {file}: {exc}", path=path, field=field) from exc
    if rgb.size == 0:
        raise DiviewerError(f"texture {file} has no pixels", path=path, field=field)
    return frozen_array(rgb), None if alpha is None else frozen_array(alpha.astype(np.float32))


def _too_large(file: Path, w: int, h: int, path, field: str) -> DiviewerError:
    s = MAX_TEXTURE_SIDE
    return DiviewerError(
        f"texture {file} is {w}x{h}, larger than {s} px on a side; downscale it, e.g. "
        f"python -c \"from PIL import Image; im = Image.open('{file}'); im.thumbnail(({s}, {s})); im.save('{file}')\"",
        path=path, field=field)
