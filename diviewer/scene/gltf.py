"""glTF 2.0 scenes as downloaded (.gltf with files or data URIs, .glb) as mesh, material and object libraries.

A scene file imports one with ``[gltf] file = "scene.gltf"`` or ``"scene.glb"``: each primitive becomes a Mesh, each
glTF material a diffuse Material (diviewer/scene/gltf_material.py: base colour factor and texture, ``alphaMode: MASK``
with its ``alphaCutoff``, ``doubleSided``, emission, the extensions read), and each node that places a mesh an Object
with the node's world pose, so instanced meshes stay instanced. Metallic, roughness, normal maps and ``BLEND``
transparency are not modelled (the renderers are diffuse): a BLEND material is drawn opaque. A primitive without a
material gets ``gltf_default`` (glTF's default: white, albedo 1.0), with a warning. The document is validated,
never trusted (diviewer/scene/gltf_check.py): indices, types, transforms and the node graph (a cycle is refused).
Files are parsed once per process and cached by the path, mtime and size of the glTF and of every file it reads.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.scene import camera as cam
from diviewer.scene import gltf_draco
from diviewer.scene.gltf_check import Doc, is_int
from diviewer.scene.gltf_container import data_uri, read_document
from diviewer.scene.gltf_material import DRACO, apply_uv_transform, check_extensions, material as _material
from diviewer.scene.model import Material, Mesh, Object
from diviewer.scene.reads import note_read, note_warning, recording_reads, recording_warnings
from diviewer.scene.textures import frozen_array, file_key as _file_key, load_texture  # noqa: F401 (load_texture: re-exported)

DEFAULT_MATERIAL = "gltf_default"
"""The material of primitives that name none: glTF's default (white, albedo 1.0); ``[materials.gltf_default]`` in
the scene file overrides it."""
DEFAULT_ALBEDO = (1.0, 1.0, 1.0)

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
FLOAT = (5126,)
UNSIGNED = (5121, 5123, 5125)
_gltf_cache: dict[tuple, tuple[tuple[dict, dict, list], tuple[Path, ...], tuple, tuple[str, ...]]] = {}


class _Reader:
    """Accessors of one glTF file, read straight from its buffers with numpy, every offset checked."""

    def __init__(self, doc: Doc, base: Path, glb_bin: bytes | None = None):
        self.d, self.file = doc, doc.file
        self.buffers = []
        for i, b in enumerate(doc.array("buffers")):
            field = f"buffers[{i}]"
            uri = b.get("uri")
            if uri is None and i == 0 and glb_bin is not None:
                data, what = glb_bin, f"{doc.file}'s BIN chunk"  # a .glb's own buffer has no uri
            elif uri is None:
                raise doc.err(f"{field}.uri", "the buffer has no 'uri' (only the first buffer of a .glb, its BIN chunk, "
                                              "may have none, and only where the .glb has a BIN chunk)")
            elif isinstance(uri, str) and uri.startswith("data:"):
                data, what = data_uri(uri, doc, f"{field}.uri", "buffer"), "the embedded buffer"
            else:
                bin_path = doc.uri(b, base, f"{field}.uri", "buffer")
                if not bin_path.is_file():
                    raise doc.err(f"{field}.uri", f"buffer file not found: {bin_path}")
                note_read(bin_path)
                data, what = bin_path.read_bytes(), str(bin_path)
            length = doc.int(b, "byteLength", f"{field}.byteLength")
            if len(data) < length:
                raise doc.err(field, f"{what} has {len(data)} bytes, the file declares {length}")
            self.buffers.append(data)

    def accessor(self, index, field: str, types: tuple, components: tuple, normalized: tuple = ()) -> np.ndarray:
        """Accessor ``index`` (referred to by ``field``) as a (count, width) array, which must be one of
        ``types`` with a component type in ``components`` (or, normalised, in ``normalized``: scaled to [0, 1])."""
        d = self.d
        acc = d.get("accessors", index, field)
        where = f"accessors[{index}]"
        ctype, kind = acc.get("componentType"), acc.get("type")
        if not is_int(ctype) or ctype not in _COMPONENTS or not isinstance(kind, str) or kind not in _WIDTH:
            raise d.err(where, f"unknown componentType {ctype!r} or type {kind!r}")
        norm = acc.get("normalized", False) is True and ctype in normalized
        if kind not in types or not (ctype in components or norm):
            raise d.err(field, f"accessor {index} is a {kind} of {np.dtype(_COMPONENTS[ctype]).name}"
                               f"{' (normalized)' if acc.get('normalized') else ''}; expected a "
                               f"{' or '.join(types)} of {', '.join(np.dtype(_COMPONENTS[c]).name for c in components)}")
        if "sparse" in acc:
            raise d.err(f"{where}.sparse", "sparse accessors are not supported")
        count = d.int(acc, "count", f"{where}.count", lo=0)
        if "bufferView" not in acc:
            raise d.err(f"{where}.bufferView", "an accessor without a bufferView (all zeros) is not supported")
        view = d.get("bufferViews", acc["bufferView"], f"{where}.bufferView")
        vf = f"bufferViews[{acc['bufferView']}]"
        b = d.index("buffers", view.get("buffer"), f"{vf}.buffer")
        buf = self.buffers[b]
        dtype, width = np.dtype(_COMPONENTS[ctype]), _WIDTH[kind]
        v_off, v_len = d.int(view, "byteOffset", f"{vf}.byteOffset", 0), d.int(view, "byteLength", f"{vf}.byteLength")
        if v_off + v_len > len(buf):
            raise d.err(vf, f"the buffer view reaches past its buffer ({v_off} + {v_len} > {len(buf)} bytes)")
        elem = dtype.itemsize * width
        stride = d.int(view, "byteStride", f"{vf}.byteStride", 0) or elem
        if stride < elem:
            raise d.err(f"{vf}.byteStride", f"{stride} is less than the accessor's element size ({elem} bytes)")
        start = v_off + d.int(acc, "byteOffset", f"{where}.byteOffset", 0)
        end = start + stride * (count - 1) + elem if count else start
        if end > v_off + v_len:
            raise d.err(where, "the accessor reaches past its buffer view")
        if count == 0:
            return np.zeros((0, width), dtype=np.float32 if norm else dtype)
        raw = np.ndarray((count, width), dtype=dtype, buffer=buf, offset=start, strides=(stride, dtype.itemsize))
        if norm:
            return raw.astype(np.float32) / float(np.iinfo(dtype).max)
        return np.array(raw)  # a copy: the bytes object is not kept alive by the mesh


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


def _unique(name, taken: set, default: str) -> str:
    out = name = name if isinstance(name, str) and name else default
    k = 1
    while out in taken:
        k += 1
        out = f"{name}#{k}"
    taken.add(out)
    return out


def _stamp(deps) -> tuple:
    """(path, mtime, size) of each file a cached parse read: an edited buffer or texture is read again."""
    out = []
    for f in deps:
        try:
            st = Path(f).stat()
            out.append((str(f), st.st_mtime_ns, st.st_size))
        except OSError:
            out.append((str(f), None, None))
    return tuple(out)


def load_gltf(file: Path, *, path=None, field: str = "gltf.file") -> tuple[dict[str, Mesh], dict[str, Material], list[Object]]:
    """Meshes (one per primitive), materials and placed objects of a .gltf or .glb file; cached per file.

    What the load could not take as the file says (an extension not honoured, primitives without a material) is
    noted as warnings (diviewer.scene.reads.note_warning), again on a cache hit.

    Raises:
        DiviewerError: a missing or malformed file, buffer or texture, or an invalid document, naming the
            file and the field.
    """
    file = Path(file)
    key = _file_key(file, "glTF", path, field)
    cached = _gltf_cache.get(key)
    if cached is None or _stamp(cached[1]) != cached[2]:
        doc, glb_bin = read_document(file, path=path, field=field)
        with recording_reads() as deps, recording_warnings() as said:
            parsed = _parse(Doc(doc, file), file.parent, glb_bin)
        cached = _gltf_cache[key] = (parsed, tuple(deps), _stamp(deps), tuple(said))
    (meshes, materials, objects), deps, _, said = cached
    note_read(*deps)  # buffers and textures, also when the parse came from the cache
    note_warning(*said)
    return dict(meshes), dict(materials), list(objects)


def _attributes(d: Doc, reader: _Reader, prim: dict, where: str):
    """(attribute names, a getter of one as a (count, width) array, the indices or None) of a primitive, read
    from its accessors or, compressed, from its KHR_draco_mesh_compression data."""
    attrs = d.table(prim, "attributes", f"{where}.attributes")
    draco = d.table(prim, "extensions", f"{where}.extensions").get(DRACO)
    if draco is not None and DRACO not in d.doc.get("extensionsRequired", []) and not gltf_draco.available():
        draco = None  # not required: the accessors hold an uncompressed copy, read below
    decoded, idx = {}, None
    if draco is not None:
        decoded, faces = gltf_draco.decode(d, reader.buffers, draco, where)
        idx = faces.ravel()
    elif "indices" in prim:
        idx = reader.accessor(prim["indices"], f"{where}.indices", ("SCALAR",), UNSIGNED).ravel()

    def get(name, types, components, normalized=()):
        if name in decoded:
            return decoded[name].astype(np.float64 if name != "POSITION" else np.float32)
        return reader.accessor(attrs[name], f"{where}.attributes.{name}", types, components, normalized)
    return set(attrs) | set(decoded), get, idx


def _primitive(d: Doc, reader: _Reader, prim, where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Vertices, normals, faces and uvs of one triangle primitive, every accessor checked."""
    if not isinstance(prim, dict):
        raise d.err(where, f"expected a JSON object, got {type(prim).__name__}")
    if prim.get("mode", 4) != 4:
        raise d.err(f"{where}.mode", "only triangle primitives (mode 4) are supported")
    names, get, idx = _attributes(d, reader, prim, where)
    if "POSITION" not in names:
        raise d.err(f"{where}.attributes", "primitive has no POSITION")
    v = get("POSITION", ("VEC3",), FLOAT)
    if v.ndim != 2 or v.shape[1] != 3:
        raise d.err(f"{where}.attributes.POSITION", f"expected 3 numbers a vertex, got {v.shape[1:]}")
    if not np.all(np.isfinite(v)):
        raise d.err(f"{where}.attributes.POSITION", "non-finite (NaN or infinite) positions")
    if idx is not None:
        if len(idx) % 3:
            raise d.err(f"{where}.indices", f"{len(idx)} indices is not a whole number of triangles")
        if len(idx) and (int(idx.max()) >= len(v) or int(idx.min()) < 0):
            raise d.err(f"{where}.indices", f"index {int(idx.max())} is out of range ({len(v)} vertices)")
        faces = idx.reshape(-1, 3).astype(np.uint32)
    else:
        if len(v) % 3:
            raise d.err(f"{where}.attributes.POSITION", f"{len(v)} vertices without indices is not a whole number of triangles")
        faces = np.arange(len(v), dtype=np.uint32).reshape(-1, 3)
    if len(faces) == 0:
        raise d.err(where, "the primitive has no triangles")
    p = v.astype(np.float64)
    fn = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    extent = max(float(np.ptp(p[faces.ravel()], axis=0).max()), 1e-30)
    if np.all(np.linalg.norm(fn, axis=1) / 2 <= 1e-12 * extent * extent):
        raise d.err(where, f"all {len(faces)} triangles have zero area; clean the mesh")

    def per_vertex(name: str, width: int, types, components, normalized=()):
        a = get(name, types, components, normalized).astype(np.float64)
        if a.ndim != 2 or a.shape[1] != width or len(a) != len(v) or not np.all(np.isfinite(a)):
            raise d.err(f"{where}.attributes.{name}", f"expected {len(v)} finite {width}-vectors (one per POSITION), "
                                                      f"got {a.shape}{'' if np.all(np.isfinite(a)) else ' with NaN/Inf'}")
        return a

    if "NORMAL" in names:
        n = per_vertex("NORMAL", 3, ("VEC3",), FLOAT)
    else:  # area-weighted vertex normals (glTF says flat; smooth is what the eye expects here)
        n = np.zeros((len(v), 3))
        for k in range(3):
            np.add.at(n, faces[:, k], fn)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(norm > 1e-12, n / np.maximum(norm, 1e-30), (0.0, 1.0, 0.0))
    uv = None
    if "TEXCOORD_0" in names:
        t = per_vertex("TEXCOORD_0", 2, ("VEC2",), FLOAT, normalized=(5121, 5123))
        uv = np.stack([t[:, 0], 1.0 - t[:, 1]], axis=1).astype(np.float32)  # glTF's v = 0 is the image's top row
    return v.astype(np.float32), n.astype(np.float32), faces, uv


def _parse(d: Doc, base: Path, glb_bin: bytes | None = None):
    check_extensions(d)
    reader = _Reader(d, base, glb_bin)
    names: set = set()
    mat_names = [_unique(m.get("name"), names, f"material{i}") for i, m in enumerate(d.array("materials"))]
    parsed = [_material(d, reader.buffers, i, n, base) for i, n in enumerate(mat_names)]
    materials = {n: m for n, (m, _) in zip(mat_names, parsed)}
    default_mat = None
    meshes: dict[str, Mesh] = {}
    prim_keys: list[list[tuple[str, str]]] = []  # per glTF mesh: (mesh key, material name) per primitive
    mesh_names: set = set()
    for mi_, m in enumerate(d.array("meshes")):
        keys = []
        prims = m.get("primitives")
        if not isinstance(prims, list) or not prims:
            raise d.err(f"meshes[{mi_}].primitives", "expected a non-empty array of primitives")
        for pi, prim in enumerate(prims):
            where = f"meshes[{mi_}].primitives[{pi}]"
            v, n, faces, uv = _primitive(d, reader, prim, where)
            if "material" in prim:
                k = d.index("materials", prim["material"], f"{where}.material")
                mat, transform = mat_names[k], parsed[k][1]
                if uv is not None and transform is not None:
                    uv = apply_uv_transform(uv, transform)  # each primitive is a mesh of its own: its uvs can move
            else:
                default_mat = default_mat or _unique(DEFAULT_MATERIAL, names, DEFAULT_MATERIAL)
                materials.setdefault(default_mat, Material(default_mat, albedo=DEFAULT_ALBEDO))
                mat = default_mat
            mname = m.get("name") if isinstance(m.get("name"), str) else f"mesh{mi_}"
            key = _unique(mname + (f".{pi}" if len(prims) > 1 else ""), mesh_names, f"mesh{mi_}")
            meshes[key] = Mesh(key, frozen_array(v), frozen_array(n), frozen_array(faces), None if uv is None else frozen_array(uv),
                               source=f"{d.file}#{where}")
            keys.append((key, mat))
        prim_keys.append(keys)
    return meshes, materials, _place(d, meshes, prim_keys)


def _roots(d: Doc) -> list[int]:
    nodes = d.array("nodes")
    scenes = d.array("scenes")
    if not scenes:
        return list(range(len(nodes)))
    k = d.index("scenes", d.doc.get("scene", 0), "scene")
    return d.indices(scenes[k], "nodes", "nodes", f"scenes[{k}].nodes")


def _place(d: Doc, meshes: dict, prim_keys: list) -> list[Object]:
    """Objects for the nodes that place meshes, walking the node graph once (a node reached twice, by a
    cycle or a second parent, is refused: glTF's node graph is a forest)."""
    nodes = d.array("nodes")
    objects: list[Object] = []
    obj_names: set = set()
    visited: set[int] = set()
    stack = [(i, np.identity(4), f"scenes.nodes[{k}]") for k, i in reversed(list(enumerate(_roots(d))))]
    while stack:
        i, parent, ref = stack.pop()
        if i in visited:
            raise d.err(ref, f"node {i} is reached twice: the node graph has a cycle or a node with two parents")
        visited.add(i)
        node, where = nodes[i], f"nodes[{i}]"
        world = parent @ d.matrix(node, where)
        children = d.indices(node, "children", "nodes", f"{where}.children")
        stack.extend((c, world, f"{where}.children[{k}]") for k, c in reversed(list(enumerate(children))))
        if "mesh" not in node:
            d.check_world(world, None, where)
            continue
        keys = prim_keys[d.index("meshes", node["mesh"], f"{where}.mesh")]
        bounds = np.stack([np.min([meshes[k].bounds[0] for k, _ in keys], axis=0),
                           np.max([meshes[k].bounds[1] for k, _ in keys], axis=0)])
        d.check_world(world, bounds, where)
        pose = _pose(world)
        nname = node.get("name") if isinstance(node.get("name"), str) else f"node{i}"
        for key, mat in keys:
            name = _unique(nname + (f".{key}" if len(keys) > 1 else ""), obj_names, f"node{i}")
            if pose is None:  # a shearing transform cannot be an Object pose: bake it into a copy
                src = meshes[key]
                baked = f"{key}@{name}"
                nm = cam.normal_matrix(world)
                nn = src.normals @ nm.T
                nn /= np.maximum(np.linalg.norm(nn, axis=1, keepdims=True), 1e-30)
                faces = src.faces if np.linalg.det(world[:3, :3]) > 0 else src.faces[:, ::-1]
                meshes[baked] = Mesh(baked, frozen_array((src.vertices @ world[:3, :3].T + world[:3, 3]).astype(np.float32)),
                                     frozen_array(nn.astype(np.float32)), frozen_array(faces), src.uvs, source=src.source)
                objects.append(Object(name, baked, mat))
            else:
                objects.append(Object(name, key, mat, position=pose[0], rotation=pose[1], scale=pose[2]))
    if not objects:
        raise d.err("nodes", "the glTF scene places no meshes")
    return objects
