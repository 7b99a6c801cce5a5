"""KHR_draco_mesh_compression: a glTF primitive's Draco-compressed geometry, decoded by DracoPy (the ``draco`` extra)."""

from __future__ import annotations

import numpy as np

from diviewer.scene.gltf_check import Doc
from diviewer.scene.gltf_container import view_bytes

EXTRA = "draco"


def available() -> bool:
    """Whether DracoPy can be imported."""
    try:
        import DracoPy  # noqa: F401
    except ImportError:
        return False
    return True


def require_dracopy(d: Doc, field: str):
    """The DracoPy module, or an error naming the extension, the field and the extra that installs it."""
    try:
        import DracoPy
    except ImportError:
        raise d.err(field, f"the file's meshes are compressed with KHR_draco_mesh_compression, which needs the Python "
                           f"package DracoPy; install the '{EXTRA}' extra: pip install 'diviewer[{EXTRA}]'") from None
    return DracoPy


def decode(d: Doc, buffers: list[bytes], ext, where: str) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The attributes (name -> (count, width) array) and (M, 3) faces of a primitive's Draco extension object."""
    field = f"{where}.extensions.KHR_draco_mesh_compression"
    if not isinstance(ext, dict):
        raise d.err(field, f"expected a JSON object, got {ext!r}")
    DracoPy = require_dracopy(d, field)
    blob = view_bytes(d, buffers, ext.get("bufferView"), f"{field}.bufferView")
    try:
        mesh = DracoPy.decode(blob)
    except Exception as exc:  # DracoPy raises its own types (and ValueError) for a corrupt stream
        raise d.err(f"{field}.bufferView", f"the Draco data does not decode: {type(exc).__name__}: {exc}") from exc
    attrs = d.table(ext, "attributes", f"{field}.attributes")
    out = {}
    for name, uid in attrs.items():
        a = mesh.get_attribute_by_unique_id(uid) if isinstance(uid, int) and not isinstance(uid, bool) else None
        if a is None:
            raise d.err(f"{field}.attributes.{name}", f"{uid!r} is not an attribute id of the Draco data")
        out[name] = np.asarray(a["data"]).reshape(len(a["data"]), -1)
    faces = np.asarray(mesh.faces if mesh.faces is not None else np.zeros((0, 3)), dtype=np.int64).reshape(-1, 3)
    return out, faces
