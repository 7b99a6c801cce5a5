"""A glTF document read defensively: every index range-checked, every number typed, every error naming the field.

diviewer/scene/gltf.py reads glTF files through `Doc`: a hand-edited or hostile file ends in one
DiviewerError naming the file and the JSON field (``materials[3].alphaCutoff``), never in a KeyError, a
hang or a silently wrong scene.
"""

from __future__ import annotations

import math
from pathlib import Path
from urllib.parse import unquote, urlsplit

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.scene.toml_table import FLOAT32_MAX

MIN_SCALE = 1e-9
"""Smallest singular value of a node's world transform (as the scene file's smallest object scale):
below it a mesh collapses to a plane, a line or a point, and its normals are undefined."""


def is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def is_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and abs(v) <= FLOAT32_MAX


def _bounds(lo, hi) -> str:
    return f"in [{lo}, {hi}]" if lo is not None and hi is not None else f">= {lo}" if lo is not None else f"<= {hi}"


class Doc:
    """One parsed glTF JSON document; getters check types and indices and name ``file: field`` on error."""

    def __init__(self, doc, file: Path):
        self.file = file
        if not isinstance(doc, dict):
            raise self.err("", f"a glTF document is a JSON object, got {type(doc).__name__}")
        self.doc = doc
        self._arrays: dict[str, list] = {}

    def err(self, field: str, msg: str) -> DiviewerError:
        return DiviewerError(msg, path=self.file, field=field or None)

    def array(self, kind: str) -> list:
        """A top-level array (``meshes``, ``nodes``, ...) whose items are all JSON objects; [] when absent."""
        if kind in self._arrays:
            return self._arrays[kind]
        v = self.doc.get(kind, [])
        if not isinstance(v, list):
            raise self.err(kind, f"expected an array, got {type(v).__name__}")
        for i, item in enumerate(v):
            if not isinstance(item, dict):
                raise self.err(f"{kind}[{i}]", f"expected a JSON object, got {type(item).__name__}")
        self._arrays[kind] = v
        return v

    def index(self, kind: str, i, field: str) -> int:
        """``i`` checked as an index into the top-level array ``kind``; the error names the referring ``field``."""
        n = len(self.array(kind))
        if not is_int(i) or not 0 <= i < n:
            raise self.err(field, f"{i!r} is not an index into '{kind}' (the file has {n})")
        return i

    def get(self, kind: str, i, field: str) -> dict:
        return self.array(kind)[self.index(kind, i, field)]

    def table(self, obj: dict, key: str, field: str) -> dict:
        v = obj.get(key, {})
        if not isinstance(v, dict):
            raise self.err(field, f"expected a JSON object, got {v!r}")
        return v

    def int(self, obj: dict, key: str, field: str, default=None, lo: int = 0) -> int:
        v = obj.get(key, default)
        if v is None:
            raise self.err(field, "missing required field")
        if not is_int(v) or v < lo:
            raise self.err(field, f"expected a whole number >= {lo}, got {v!r}")
        return v

    def flag(self, obj: dict, key: str, field: str, default: bool) -> bool:
        v = obj.get(key, default)
        if not isinstance(v, bool):
            raise self.err(field, f"expected true or false, got {v!r}")
        return v

    def num(self, obj: dict, key: str, field: str, default: float, lo=None, hi=None) -> float:
        v = obj.get(key, default)
        if not is_num(v):
            raise self.err(field, f"expected a finite number, got {v!r}")
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise self.err(field, f"must be {_bounds(lo, hi)}, got {v}")
        return float(v)

    def nums(self, obj: dict, key: str, n: int, field: str, default, lo=None, hi=None) -> tuple[float, ...]:
        v = obj.get(key, default)
        if not isinstance(v, (list, tuple)) or len(v) != n or not all(is_num(x) for x in v):
            raise self.err(field, f"expected {n} finite numbers (within float32), got {v!r}")
        if (lo is not None and min(v) < lo) or (hi is not None and max(v) > hi):
            raise self.err(field, f"each value must be {_bounds(lo, hi)}, got {list(v)}")
        return tuple(float(x) for x in v)

    def indices(self, obj: dict, key: str, kind: str, field: str) -> list[int]:
        v = obj.get(key, [])
        if not isinstance(v, list):
            raise self.err(field, f"expected an array of indices into '{kind}', got {v!r}")
        return [self.index(kind, x, f"{field}[{k}]") for k, x in enumerate(v)]

    def uri(self, obj: dict, base: Path, field: str, what: str) -> Path:
        """A relative file URI, percent-decoded (``my%20texture.png``), as a path next to the glTF file (the caller
        reads ``data:`` URIs and a .glb's buffer views itself)."""
        uri = obj.get("uri")
        if not isinstance(uri, str) or not uri:
            raise self.err(field, f"the {what} has no 'uri' (a file name, a data: URI or, in a .glb, a bufferView)")
        parts = urlsplit(uri)
        if parts.scheme and len(parts.scheme) > 1:  # one letter: a Windows drive
            raise self.err(field, f"only relative file URIs are supported, got {uri!r}")
        return base / unquote(uri)

    def matrix(self, node: dict, field: str) -> np.ndarray:
        """A node's local transform (its ``matrix``, or translation x rotation x scale), checked finite."""
        if "matrix" in node:
            m = self.nums(node, "matrix", 16, f"{field}.matrix", None)
            out = np.asarray(m, dtype=np.float64).reshape(4, 4).T  # glTF stores column-major
            if not np.allclose(out[3], (0.0, 0.0, 0.0, 1.0)):
                raise self.err(f"{field}.matrix", "the last row must be (0, 0, 0, 1): glTF nodes are affine")
            return out
        q = self.nums(node, "rotation", 4, f"{field}.rotation", (0.0, 0.0, 0.0, 1.0))
        norm = math.sqrt(sum(c * c for c in q))
        if abs(norm - 1.0) > 1e-3:
            raise self.err(f"{field}.rotation", f"a rotation is a unit quaternion; this one has length {norm:.6g}")
        x, y, z, w = q  # as written (normalising would move shipped scenes' poses by float rounding)
        r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        m = np.identity(4)
        m[:3, :3] = r @ np.diag(self.nums(node, "scale", 3, f"{field}.scale", (1.0, 1.0, 1.0)))
        m[:3, 3] = self.nums(node, "translation", 3, f"{field}.translation", (0.0, 0.0, 0.0))
        return m

    def check_world(self, world: np.ndarray, bounds: np.ndarray | None, field: str) -> None:
        """Refuse a composed world transform that is not finite in float32, or (for a node placing a mesh with
        object-space ``bounds``) that collapses the mesh or places it beyond float32."""
        if not np.all(np.isfinite(world)) or np.abs(world).max() > FLOAT32_MAX:
            raise self.err(field, "the node's world transform (its own times its parents') is not finite in float32")
        if bounds is None:
            return  # a node placing no mesh may scale to zero (hidden children are refused where they place a mesh)
        s = np.linalg.svd(world[:3, :3], compute_uv=False)
        if s.min() < MIN_SCALE:
            raise self.err(field, f"the node's world transform collapses its mesh (smallest scale {s.min():.3g} "
                                  f"< {MIN_SCALE:g}): a zero scale or a degenerate matrix")
        corners = np.array([[bounds[i, 0], bounds[j, 1], bounds[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        placed = corners.astype(np.float64) @ world[:3, :3].T + world[:3, 3]
        if not np.all(np.isfinite(placed)) or np.abs(placed).max() > FLOAT32_MAX:
            raise self.err(field, "the node places its mesh beyond float32's range (+-3.4e38)")
