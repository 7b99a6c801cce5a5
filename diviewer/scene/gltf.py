"""glTF 2.0 scenes (.gltf + .bin + images) as mesh, material and object libraries.

A scene file imports one with ``[gltf] file = "..."``: each primitive becomes a Mesh, each glTF material a
diffuse Material (base colour factor and texture, ``alphaMode: MASK`` with its ``alphaCutoff``, ``doubleSided``),
and each node that places a mesh an Object with the node's world pose, so instanced meshes stay instanced.
Metallic, roughness, normal maps and ``BLEND`` transparency are not modelled (the renderers are diffuse):
a BLEND material is drawn opaque. The document is validated, never trusted (diviewer/scene/gltf_check.py):
indices, types, transforms and the node graph (a cycle is refused). Files are parsed once per process and
cached by the path, mtime and size of the .gltf and of every file it reads.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.scene import camera as cam
from diviewer.scene.gltf_check import Doc, is_int
from diviewer.scene.model import Material, Mesh, Object
from diviewer.scene.reads import note_read, recording_reads
from diviewer.scene.textures import _frozen, file_key as _file_key, load_texture

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
FLOAT = (5126,)
UNSIGNED = (5121, 5123, 5125)
_gltf_cache: dict[tuple, tuple[tuple[dict, dict, list], tuple[Path, ...], tuple]] = {}


class _Reader:
    """Accessors of one glTF file, read straight from its buffers with numpy, every offset checked."""

    def __init__(self, doc: Doc, base: Path):
        self.d, self.file = doc, doc.file
        self.buffers = []
        for i, b in enumerate(doc.array("buffers")):
            bin_path = doc.uri(b, base, f"buffers[{i}].uri", "buffer")
            if not bin_path.is_file():
                raise doc.err(f"buffers[{i}].uri", f"buffer file not found: {bin_path}")
            note_read(bin_path)
            data = bin_path.read_bytes()
            length = doc.int(b, "byteLength", f"buffers[{i}].byteLength")
            if len(data) < length:
                raise doc.err(f"buffers[{i}]", f"{bin_path} has {len(data)} bytes, the file declares {length}")
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


ALPHA_MODES = ("OPAQUE", "MASK", "BLEND")


def _material(d: Doc, i: int, name: str, base: Path) -> Material:
    m = d.array("materials")[i]
    where = f"materials[{i}]"
    pbr = d.table(m, "pbrMetallicRoughness", f"{where}.pbrMetallicRoughness")
    factor = d.nums(pbr, "baseColorFactor", 4, f"{where}.pbrMetallicRoughness.baseColorFactor",
                    (1.0, 1.0, 1.0, 1.0), lo=0.0, hi=1.0)
    texture = alpha = None
    source = ""
    if "baseColorTexture" in pbr:
        field = f"{where}.pbrMetallicRoughness.baseColorTexture"
        ref = d.table(pbr, "baseColorTexture", field)
        if d.int(ref, "texCoord", f"{field}.texCoord", 0) != 0:
            raise d.err(f"{field}.texCoord", "only TEXCOORD_0 is read; bake the texture onto the first uv set")
        tex = d.get("textures", ref.get("index"), f"{field}.index")
        t_field = f"textures[{ref['index']}]"
        if "sampler" in tex:
            d.index("samplers", tex["sampler"], f"{t_field}.sampler")
        if "source" not in tex:
            raise d.err(f"{t_field}.source", "the texture has no image (an extension's image is not supported)")
        image = d.get("images", tex["source"], f"{t_field}.source")
        file = d.uri(image, base, f"images[{tex['source']}].uri", "image")
        source = str(file)
        texture, alpha = load_texture(file, path=d.file, field=f"{where} ({name}).baseColorTexture")
    mode = m.get("alphaMode", "OPAQUE")
    if mode not in ALPHA_MODES:
        raise d.err(f"{where}.alphaMode", f"{mode!r} is not one of {', '.join(ALPHA_MODES)}")
    cutoff = d.num(m, "alphaCutoff", f"{where}.alphaCutoff", 0.5, lo=0.0, hi=1.0)
    if mode == "MASK":
        if alpha is None:
            alpha = np.full(texture.shape[:2] if texture is not None else (1, 1), 1.0, np.float32)
            if texture is None:
                texture = np.ones((1, 1, 3), np.float32)
        if factor[3] != 1.0:
            alpha = _frozen(alpha * factor[3])
    else:
        alpha = None  # OPAQUE ignores alpha; BLEND is drawn opaque (no transparency in these renderers)
    emission = d.nums(m, "emissiveFactor", 3, f"{where}.emissiveFactor", (0.0, 0.0, 0.0), lo=0.0)
    return Material(name, albedo=factor[:3], emission=emission, texture=texture, texture_source=source, alpha=alpha,
                    alpha_cutoff=cutoff if mode == "MASK" else 0.5,
                    double_sided=d.flag(m, "doubleSided", f"{where}.doubleSided", False))


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
    """Meshes (one per primitive), materials and placed objects of a .gltf file; cached per file.

    Raises:
        DiviewerError: a missing or malformed file, buffer or texture, or an invalid document, naming the
            file and the field.
    """
    file = Path(file)
    key = _file_key(file, "glTF", path, field)
    cached = _gltf_cache.get(key)
    if cached is None or _stamp(cached[1]) != cached[2]:
        try:
            doc = json.loads(file.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
            raise DiviewerError(f"not a glTF JSON file: {type(exc).__name__}: {str(exc)[:200]}",
                                path=path, field=field) from exc
        with recording_reads() as deps:
            parsed = _parse(Doc(doc, file), file.parent)
        cached = _gltf_cache[key] = (parsed, tuple(deps), _stamp(deps))
    (meshes, materials, objects), deps, _ = cached
    note_read(*deps)  # buffers and textures, also when the parse came from the cache
    return dict(meshes), dict(materials), list(objects)


def _primitive(d: Doc, reader: _Reader, prim, where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Vertices, normals, faces and uvs of one triangle primitive, every accessor checked."""
    if not isinstance(prim, dict):
        raise d.err(where, f"expected a JSON object, got {type(prim).__name__}")
    if prim.get("mode", 4) != 4:
        raise d.err(f"{where}.mode", "only triangle primitives (mode 4) are supported")
    attrs = d.table(prim, "attributes", f"{where}.attributes")
    if "POSITION" not in attrs:
        raise d.err(f"{where}.attributes", "primitive has no POSITION")
    v = reader.accessor(attrs["POSITION"], f"{where}.attributes.POSITION", ("VEC3",), FLOAT)
    if not np.all(np.isfinite(v)):
        raise d.err(f"{where}.attributes.POSITION", "non-finite (NaN or infinite) positions")
    if "indices" in prim:
        idx = reader.accessor(prim["indices"], f"{where}.indices", ("SCALAR",), UNSIGNED).ravel()
        if len(idx) % 3:
            raise d.err(f"{where}.indices", f"{len(idx)} indices is not a whole number of triangles")
        if len(idx) and int(idx.max()) >= len(v):
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

    def per_vertex(name: str, types, components, normalized=()):
        a = reader.accessor(attrs[name], f"{where}.attributes.{name}", types, components, normalized).astype(np.float64)
        if len(a) != len(v) or not np.all(np.isfinite(a)):
            raise d.err(f"{where}.attributes.{name}", f"expected {len(v)} finite values (one per POSITION), "
                                                      f"got {len(a)}{'' if np.all(np.isfinite(a)) else ' with NaN/Inf'}")
        return a

    if "NORMAL" in attrs:
        n = per_vertex("NORMAL", ("VEC3",), FLOAT)
    else:  # area-weighted vertex normals (glTF says flat; smooth is what the eye expects here)
        n = np.zeros((len(v), 3))
        for k in range(3):
            np.add.at(n, faces[:, k], fn)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(norm > 1e-12, n / np.maximum(norm, 1e-30), (0.0, 1.0, 0.0))
    uv = None
    if "TEXCOORD_0" in attrs:
        t = per_vertex("TEXCOORD_0", ("VEC2",), FLOAT, normalized=(5121, 5123))
        uv = np.stack([t[:, 0], 1.0 - t[:, 1]], axis=1).astype(np.float32)  # glTF's v = 0 is the image's top row
    return v.astype(np.float32), n.astype(np.float32), faces, uv


def _parse(d: Doc, base: Path):
    reader = _Reader(d, base)
    names: set = set()
    mat_names = [_unique(m.get("name"), names, f"material{i}") for i, m in enumerate(d.array("materials"))]
    materials = {n: _material(d, i, n, base) for i, n in enumerate(mat_names)}
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
            mname = m.get("name") if isinstance(m.get("name"), str) else f"mesh{mi_}"
            key = _unique(mname + (f".{pi}" if len(prims) > 1 else ""), mesh_names, f"mesh{mi_}")
            meshes[key] = Mesh(key, _frozen(v), _frozen(n), _frozen(faces), None if uv is None else _frozen(uv),
                               source=f"{d.file}#{where}")
            if "material" in prim:
                mat = mat_names[d.index("materials", prim["material"], f"{where}.material")]
            else:
                default_mat = default_mat or _unique("gltf_default", names, "gltf_default")
                materials.setdefault(default_mat, Material(default_mat, albedo=(1.0, 1.0, 1.0)))
                mat = default_mat
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
                meshes[baked] = Mesh(baked, _frozen((src.vertices @ world[:3, :3].T + world[:3, 3]).astype(np.float32)),
                                     _frozen(nn.astype(np.float32)), _frozen(faces), src.uvs, source=src.source)
                objects.append(Object(name, baked, mat))
            else:
                objects.append(Object(name, key, mat, position=pose[0], rotation=pose[1], scale=pose[2]))
    if not objects:
        raise d.err("nodes", "the glTF scene places no meshes")
    return objects
