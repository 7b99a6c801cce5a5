"""A small valid glTF scene written by tests: a textured, alpha-masked quad and a box, a .bin and a PNG.

Tests edit its files (the scene identity), mutate its JSON (tests/extremes: hypothesis) or load it as is.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

SCENE_TOML = """[scene]
name = "tiny_gltf"

[gltf]
file = "tiny.gltf"

[camera]
position = [0.0, 1.0, 4.0]
target = [0.0, 0.0, 0.0]
fov = 50.0
near = 0.1
far = 20.0

[[lights]]
name = "sun"
type = "directional"
direction = [-0.3, -1.0, -0.4]
irradiance = 3.0
"""


def _box() -> tuple[np.ndarray, np.ndarray]:
    v = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)], np.float32)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    f = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], np.uint16)
    return v, f


def gltf_document(bin_name: str = "tiny.bin", image_name: str = "tex.png") -> tuple[dict, bytes]:
    """(the glTF JSON, the .bin's bytes): a box (indices, no uvs) under a parent node and a textured quad."""
    quad_v = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], np.float32)
    quad_n = np.tile(np.array([[0, 1, 0]], np.float32), (4, 1))
    quad_uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    quad_i = np.array([0, 2, 1, 0, 3, 2], np.uint16)
    box_v, box_f = _box()
    parts = [quad_v, quad_n, quad_uv, quad_i, box_v, box_f.ravel()]
    blob, views = b"", []
    for p in parts:
        data = p.tobytes()
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
        blob += data + b"\0" * (-len(data) % 4)
    accessors = [
        {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
         "min": [-1, 0, -1], "max": [1, 0, 1]},
        {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"},
        {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"},
        {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"},
        {"bufferView": 4, "componentType": 5126, "count": 8, "type": "VEC3",
         "min": [-0.5] * 3, "max": [0.5] * 3},
        {"bufferView": 5, "componentType": 5123, "count": 36, "type": "SCALAR"},
    ]
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"uri": bin_name, "byteLength": len(blob)}],
        "bufferViews": views,
        "accessors": accessors,
        "images": [{"uri": image_name}],
        "samplers": [{"magFilter": 9728}],
        "textures": [{"source": 0, "sampler": 0}],
        "materials": [
            {"name": "leaf", "alphaMode": "MASK", "alphaCutoff": 0.5,
             "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "baseColorFactor": [1, 1, 1, 1]}},
            {"name": "stone", "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.5, 0.4, 1.0]}},
        ],
        "meshes": [
            {"name": "quad", "primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2},
                                             "indices": 3, "material": 0}]},
            {"name": "box", "primitives": [{"attributes": {"POSITION": 4}, "indices": 5, "material": 1}]},
        ],
        "nodes": [
            {"name": "ground", "mesh": 0, "translation": [0, -0.5, 0], "scale": [2, 1, 2]},
            {"name": "pivot", "children": [2], "rotation": [0, 0.3826834, 0, 0.9238795]},
            {"name": "cube", "mesh": 1, "translation": [0, 0.01, 0]},
        ],
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
    }
    return doc, blob


def checker_rgba(size: int = 8, cell: int = 1) -> np.ndarray:
    """An RGBA checker: opaque reddish cells and fully transparent ones, ``cell`` texels wide."""
    yy, xx = np.mgrid[0:size, 0:size]
    on = ((yy // cell + xx // cell) % 2 == 0)
    img = np.zeros((size, size, 4), np.uint8)
    img[..., 0], img[..., 1], img[..., 2] = 200, 120, 60
    img[..., 3] = np.where(on, 255, 0)
    return img


def write_scene(folder: Path, doc: dict | None = None, blob: bytes | None = None, image: np.ndarray | None = None,
                toml: str = SCENE_TOML) -> Path:
    """Write tiny.gltf, tiny.bin, tex.png and scene.toml into ``folder``; returns the scene file."""
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    d, b = gltf_document()
    (folder / "tiny.gltf").write_text(json.dumps(d if doc is None else doc))
    (folder / "tiny.bin").write_bytes(b if blob is None else blob)
    Image.fromarray(checker_rgba() if image is None else image).save(folder / "tex.png")
    (folder / "scene.toml").write_text(toml)
    return folder / "scene.toml"


def glb_bytes(doc: dict, blob: bytes | None) -> bytes:
    """A .glb container: the 12-byte header, the JSON chunk (space-padded) and the BIN chunk (zero-padded), the
    document's first buffer made the BIN chunk (its uri dropped)."""
    import struct

    doc = json.loads(json.dumps(doc))
    if blob is not None:
        doc["buffers"][0].pop("uri", None)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    out = struct.pack("<II", len(text), 0x4E4F534A) + text
    if blob is not None:
        blob = blob + b"\0" * (-len(blob) % 4)
        out += struct.pack("<II", len(blob), 0x004E4942) + blob
    return b"glTF" + struct.pack("<II", 2, 12 + len(out)) + out


def data_uri(data: bytes, mime: str = "application/octet-stream") -> str:
    import base64

    return f"data:{mime};base64," + base64.b64encode(data).decode()


def png_bytes(image: np.ndarray) -> bytes:
    import io

    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(image).save(out, format="PNG")
    return out.getvalue()


def scene_toml(gltf_file: str, extra: str = "") -> str:
    """SCENE_TOML importing ``gltf_file`` instead of tiny.gltf, with ``extra`` appended."""
    return SCENE_TOML.replace('file = "tiny.gltf"', f'file = "{gltf_file}"') + extra
