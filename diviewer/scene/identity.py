"""A scene's identity: what it looks like (its parsed TOML and every file it loads), as one sha256.

Models, datasets and evaluation sets record it; the runtime refuses a model whose scene differs.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

IDENTITY_VERSION = 2
"""Version of `scene_identity`'s definition (1 was the scene file's bytes alone)."""

NOT_IDENTITY = ("camera", "ranges")
"""Top-level tables of a scene file that do not change what the scene looks like: where the camera
starts and what the sampler varies (a model records the ranges it was trained on separately)."""

DISPLAY_ONLY = ("exposure", "auto_exposure")
"""Fields of [scene] that say how frames are shown, not what they hold."""

RASTER_ONLY = ("shadow_size",)
"""Fields of [scene] that set how the rasterizer approximates the scene, not what it is: the path tracer's truth
does not see them, so an evaluation set stays the scene's, and a model trained at another setting still runs."""


def scene_identity(data: dict, files: list[Path], base: Path) -> str:
    """sha256 of what a scene looks like: its parsed TOML (less `NOT_IDENTITY` and [scene]'s `DISPLAY_ONLY` and
    `RASTER_ONLY`) and the bytes of every file it loads (glTF, buffers, textures, mesh files), by path from the TOML."""
    content = {k: v for k, v in data.items() if k not in NOT_IDENTITY}
    if isinstance(content.get("scene"), dict):
        content["scene"] = {k: v for k, v in content["scene"].items() if k not in DISPLAY_ONLY + RASTER_ONLY}
    deps = {}
    for f in files:
        try:
            rel = os.path.relpath(f.resolve(), base.resolve())
        except ValueError:  # another drive (Windows)
            rel = str(f.resolve())
        deps[rel.replace(os.sep, "/")] = _sha256_file(f)
    blob = json.dumps({"identity_version": IDENTITY_VERSION, "scene": content, "files": dict(sorted(deps.items()))},
                      sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()


_hash_cache: dict[tuple, str] = {}


def _sha256_file(f: Path) -> str:
    """A file's sha256, cached on (path, mtime, size) as the texture and glTF caches are."""
    st = f.stat()
    key = (str(f.resolve()), st.st_mtime_ns, st.st_size)
    if key not in _hash_cache:
        h = hashlib.sha256()
        with open(f, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
        _hash_cache[key] = h.hexdigest()
    return _hash_cache[key]
