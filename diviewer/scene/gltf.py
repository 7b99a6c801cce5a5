"""glTF 2.0 scenes (.gltf + .bin + images) as mesh, material and object libraries; base-colour textures.

A scene file imports one with ``[gltf] file = "..."``: each primitive becomes a Mesh, each glTF material a
diffuse Material (base colour factor and texture, ``alphaMode: MASK`` with its ``alphaCutoff``), and each
node that places a mesh an Object with the node's world pose, so instanced meshes stay instanced.
Metallic, roughness, normal maps and ``BLEND`` transparency are not modelled (the renderers are diffuse):
a BLEND material is drawn opaque. Files are parsed once per process and cached by path and mtime.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.scene import camera as cam
from diviewer.scene.model import Material, Mesh, Object
from diviewer.scene.colour import srgb_to_linear
from diviewer.scene.reads import note_read, recording_reads

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_texture_cache: dict[tuple, tuple[np.ndarray, np.ndarray | None]] = {}
_gltf_cache: dict[tuple, tuple[tuple[dict, dict, list], tuple[Path, ...]]] = {}


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)  # shared by every scene that loads the same file
    return a


def _file_key(file: Path, what: str, path, field: str) -> tuple:
    """The cache key of an existing file (its path, mtime and size: an edited file is read again)."""
    if not file.is_file():
        raise DiviewerError(f"{what} file not found: {file}", path=path, field=field)
    note_read(file)
    st = file.stat()
    return (str(file.resolve()), st.st_mtime_ns, st.st_size)


def load_texture(file: Path, *, path=None, field: str = "") -> tuple[np.ndarray, np.ndarray | None]:
    """An image file as a linear (H, W, 3) float32 texture, top row first, and its alpha (H, W) or None.

    The colour is decoded from sRGB (as stored by image files); alpha is linear. Cached per file.

    Raises:
        DiviewerError: the file is missing or not a readable image, naming the file and ``field``.
    """
    from PIL import Image

    file = Path(file)
    key = _file_key(file, "texture", path, field)
    if key not in _texture_cache:
        try:
            with Image.open(file) as im:
                im.load()
                has_alpha = im.mode in ("RGBA", "LA", "PA") or (im.mode == "P" and "transparency" in im.info)
                arr = np.asarray(im.convert("RGBA" if has_alpha else "RGB"), dtype=np.float32) / 255.0
        except Exception as exc:  # Pillow raises several types for truncated or foreign files
            raise DiviewerError(f"cannot read texture {file}: {exc}", path=path, field=field) from exc
        rgb = _frozen(srgb_to_linear(arr[..., :3]).astype(np.float32))
        alpha = _frozen(arr[..., 3]) if has_alpha else None
        _texture_cache[key] = (rgb, alpha)
    return _texture_cache[key]


class _Reader:
    """Accessors of one glTF file, read straight from its buffers with numpy."""

    def __init__(self, doc: dict, base: Path, file: Path):
        self.doc, self.file = doc, file
        self.buffers = []
        for i, b in enumerate(doc.get("buffers", [])):
            uri = b.get("uri")
            if uri is None or uri.startswith("data:"):
                raise DiviewerError("only external .bin buffers are supported (not embedded or .glb)",
                                    path=file, field=f"buffers[{i}].uri")
            bin_path = base / uri
            if not bin_path.is_file():
                raise DiviewerError(f"buffer file not found: {bin_path}", path=file, field=f"buffers[{i}].uri")
            note_read(bin_path)
            data = bin_path.read_bytes()
            if len(data) < b.get("byteLength", 0):
                raise DiviewerError(f"{bin_path} has {len(data)} bytes, the file declares {b['byteLength']}",
                                    path=file, field=f"buffers[{i}]")
            self.buffers.append(data)

    def accessor(self, index: int) -> np.ndarray:
        acc = self.doc["accessors"][index]
        where = f"accessors[{index}]"
        try:
            dtype = np.dtype(_COMPONENTS[acc["componentType"]])
            width, count = _WIDTH[acc["type"]], int(acc["count"])
            view = self.doc["bufferViews"][acc["bufferView"]]
        except (KeyError, IndexError) as exc:
            raise DiviewerError(f"unsupported or incomplete accessor ({exc})", path=self.file, field=where) from exc
        buf = self.buffers[view["buffer"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        stride = view.get("byteStride") or dtype.itemsize * width
        end = start + stride * (count - 1) + dtype.itemsize * width if count else start
        if end > view.get("byteOffset", 0) + view["byteLength"] or end > len(buf):
            raise DiviewerError("accessor reaches past its buffer view", path=self.file, field=where)
        raw = np.ndarray((count, width), dtype=dtype, buffer=buf, offset=start, strides=(stride, dtype.itemsize))
        return np.array(raw)  # a copy: the bytes object is not kept alive by the mesh


def _node_matrix(node: dict) -> np.ndarray:
    if "matrix" in node:
        return np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T  # glTF stores column-major
    x, y, z, w = node.get("rotation", (0.0, 0.0, 0.0, 1.0))
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    m = np.identity(4)
    m[:3, :3] = r @ np.diag(node.get("scale", (1.0, 1.0, 1.0)))
    m[:3, 3] = node.get("translation", (0.0, 0.0, 0.0))
    return m


def _pose(m: np.ndarray):
    """(position, euler xyz degrees, scale) with Object.matrix() == m, or None if m shears."""
    from diviewer.scene.sampler import matrix_to_euler_xyz

    a = m[:3, :3]
    s = np.linalg.norm(a, axis=0)
    if s.min() < 1e-12:
        return None
    if np.linalg.det(a) < 0:
        s[0] = -s[0]
    r = a / s
    if not np.allclose(r.T @ r, np.identity(3), atol=1e-5):
        return None
    pose = (tuple(map(float, m[:3, 3])), matrix_to_euler_xyz(r), tuple(map(float, s)))
    return pose if np.allclose(cam.trs(*pose), m, atol=1e-5 * max(1.0, float(np.abs(m).max()))) else None


def _material(doc: dict, i: int, name: str, base: Path, file: Path) -> Material:
    m = doc["materials"][i]
    pbr = m.get("pbrMetallicRoughness", {})
    factor = [float(c) for c in pbr.get("baseColorFactor", (1.0, 1.0, 1.0, 1.0))]
    texture = alpha = None
    source = ""
    if "baseColorTexture" in pbr:
        field = f"materials[{i}] ({name}).baseColorTexture"
        try:
            image = doc["images"][doc["textures"][pbr["baseColorTexture"]["index"]]["source"]]
            uri = image["uri"]
        except (KeyError, IndexError) as exc:
            raise DiviewerError(f"broken texture reference ({exc})", path=file, field=field) from exc
        source = str(base / uri)
        texture, alpha = load_texture(base / uri, path=file, field=field)
    mode = m.get("alphaMode", "OPAQUE")
    if mode == "MASK":
        if alpha is None:
            alpha = np.full(texture.shape[:2] if texture is not None else (1, 1), 1.0, np.float32)
            if texture is None:
                texture = np.ones((1, 1, 3), np.float32)
        if factor[3] != 1.0:
            alpha = _frozen(alpha * factor[3])
    else:
        alpha = None  # OPAQUE ignores alpha; BLEND is drawn opaque (no transparency in these renderers)
    emission = tuple(float(c) for c in m.get("emissiveFactor", (0.0, 0.0, 0.0)))
    return Material(name, albedo=tuple(min(max(c, 0.0), 1.0) for c in factor[:3]), emission=emission,
                    texture=texture, texture_source=source, alpha=alpha,
                    alpha_cutoff=float(m.get("alphaCutoff", 0.5)) if mode == "MASK" else 0.5)


def _unique(name: str, taken: set) -> str:
    out, k = name, 1
    while out in taken:
        k += 1
        out = f"{name}#{k}"
    taken.add(out)
    return out


def load_gltf(file: Path, *, path=None, field: str = "gltf.file") -> tuple[dict[str, Mesh], dict[str, Material], list[Object]]:
    """Meshes (one per primitive), materials and placed objects of a .gltf file; cached per file.

    Raises:
        DiviewerError: a missing or malformed file, buffer or texture, naming it.
    """
    file = Path(file)
    key = _file_key(file, "glTF", path, field)
    if key not in _gltf_cache:
        try:
            doc = json.loads(file.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise DiviewerError(f"not a glTF JSON file: {exc}", path=path, field=field) from exc
        with recording_reads() as deps:
            parsed = _parse(doc, file.parent, file)
        _gltf_cache[key] = (parsed, tuple(deps))
    (meshes, materials, objects), deps = _gltf_cache[key]
    note_read(*deps)  # buffers and textures, also when the parse came from the cache
    return dict(meshes), dict(materials), list(objects)


def _parse(doc: dict, base: Path, file: Path):
    reader = _Reader(doc, base, file)
    names: set = set()
    mat_names = [_unique(m.get("name", f"material{i}"), names) for i, m in enumerate(doc.get("materials", []))]
    materials = {n: _material(doc, i, n, base, file) for i, n in enumerate(mat_names)}
    default_mat = None
    meshes: dict[str, Mesh] = {}
    prim_keys: list[list[tuple[str, str]]] = []  # per glTF mesh: (mesh key, material name) per primitive
    mesh_names: set = set()
    for mi_, m in enumerate(doc.get("meshes", [])):
        keys = []
        for pi, prim in enumerate(m.get("primitives", [])):
            where = f"meshes[{mi_}].primitives[{pi}]"
            if prim.get("mode", 4) != 4:
                raise DiviewerError("only triangle primitives (mode 4) are supported", path=file, field=where)
            attrs = prim.get("attributes", {})
            if "POSITION" not in attrs:
                raise DiviewerError("primitive has no POSITION", path=file, field=where)
            v = reader.accessor(attrs["POSITION"]).astype(np.float32)
            faces = (reader.accessor(prim["indices"]).reshape(-1, 3) if "indices" in prim
                     else np.arange(len(v)).reshape(-1, 3)).astype(np.uint32)
            if len(faces) == 0 or faces.max() >= len(v) or not np.all(np.isfinite(v)):
                raise DiviewerError("indices out of range, no triangles or non-finite positions", path=file, field=where)
            if "NORMAL" in attrs:
                n = reader.accessor(attrs["NORMAL"]).astype(np.float64)
            else:  # area-weighted vertex normals (glTF says flat; smooth is what the eye expects here)
                n = np.zeros((len(v), 3))
                fn = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
                for k in range(3):
                    np.add.at(n, faces[:, k], fn)
            norm = np.linalg.norm(n, axis=1, keepdims=True)
            n = np.where(norm > 1e-12, n / np.maximum(norm, 1e-30), (0.0, 1.0, 0.0))
            uv = None
            if "TEXCOORD_0" in attrs:
                t = reader.accessor(attrs["TEXCOORD_0"]).astype(np.float32)
                uv = np.stack([t[:, 0], 1.0 - t[:, 1]], axis=1)  # glTF's v = 0 is the image's top row
            key = _unique(m.get("name", f"mesh{mi_}") + (f".{pi}" if len(m["primitives"]) > 1 else ""), mesh_names)
            meshes[key] = Mesh(key, _frozen(v), _frozen(n.astype(np.float32)), _frozen(faces),
                               None if uv is None else _frozen(uv), source=f"{file}#{where}")
            if "material" in prim:
                mat = mat_names[prim["material"]]
            else:
                default_mat = default_mat or _unique("gltf_default", names)
                materials.setdefault(default_mat, Material(default_mat, albedo=(1.0, 1.0, 1.0)))
                mat = default_mat
            keys.append((key, mat))
        prim_keys.append(keys)

    objects: list[Object] = []
    obj_names: set = set()
    roots = doc["scenes"][doc.get("scene", 0)]["nodes"] if doc.get("scenes") else range(len(doc.get("nodes", [])))
    stack = [(i, np.identity(4)) for i in reversed(list(roots))]
    while stack:
        i, parent = stack.pop()
        node = doc["nodes"][i]
        world = parent @ _node_matrix(node)
        stack.extend((c, world) for c in reversed(node.get("children", [])))
        if "mesh" not in node:
            continue
        pose = _pose(world)
        for key, mat in prim_keys[node["mesh"]]:
            name = _unique(node.get("name", f"node{i}") + (f".{key}" if len(prim_keys[node["mesh"]]) > 1 else ""),
                           obj_names)
            if pose is None:  # a shearing transform cannot be an Object pose: bake it into a copy
                src = meshes[key]
                baked = f"{key}@{name}"
                nm = cam.normal_matrix(world)
                nn = src.normals @ nm.T
                nn /= np.maximum(np.linalg.norm(nn, axis=1, keepdims=True), 1e-30)
                faces = src.faces if np.linalg.det(world[:3, :3]) > 0 else src.faces[:, ::-1]
                meshes[baked] = Mesh(baked, _frozen((src.vertices @ world[:3, :3].T + world[:3, 3]).astype(np.float32)),
                                     _frozen(nn.astype(np.float32)), _frozen(faces), src.uvs, source=src.source)
                objects.append(Object(name, baked, mat))
            else:
                objects.append(Object(name, key, mat, position=pose[0], rotation=pose[1], scale=pose[2]))
    if not objects:
        raise DiviewerError("the glTF scene places no meshes", path=file, field="nodes")
    return meshes, materials, objects
