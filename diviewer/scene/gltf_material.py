"""glTF materials as diffuse Materials, their textures (files, data URIs, buffer views) and the extensions read.

Honoured: the base colour (factor and texture), ``alphaMode``/``alphaCutoff``, ``doubleSided``, ``emissiveFactor``
and ``emissiveTexture`` (the factor multiplies the texture), ``KHR_materials_emissive_strength`` (multiplies the
factor), ``KHR_texture_transform`` on the base colour or emissive texture (the offset, rotation and scale are applied
to the primitive's uvs; a material whose two textures are placed by different transforms loses its emission, with a
warning: one uv set is read) and ``KHR_draco_mesh_compression`` (with the ``draco`` extra). Any other extension the
file lists in ``extensionsUsed`` is named in a warning; one in ``extensionsRequired`` is refused.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from diviewer.scene.gltf_check import Doc
from diviewer.scene.gltf_container import data_uri, view_bytes
from diviewer.scene.model import Material
from diviewer.scene.reads import note_warning
from diviewer.scene.textures import frozen_array, load_texture, load_texture_bytes

DRACO = "KHR_draco_mesh_compression"
HONOURED = ("KHR_texture_transform", "KHR_materials_emissive_strength", DRACO)
"""Extensions read as their specifications say (Draco needs the ``draco`` extra: DracoPy)."""
ALPHA_MODES = ("OPAQUE", "MASK", "BLEND")


def check_extensions(d: Doc) -> None:
    """Refuse a required extension that is not honoured; name the used ones that are not in a warning."""
    required = d.doc.get("extensionsRequired", [])
    used = d.doc.get("extensionsUsed", [])
    for key, v in (("extensionsRequired", required), ("extensionsUsed", used)):
        if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
            raise d.err(key, f"expected an array of extension names, got {v!r}")
    missing = [x for x in required if x not in HONOURED]
    if missing:
        raise d.err("extensionsRequired", f"the file requires extensions diviewer does not read: {', '.join(missing)} "
                                          f"(it reads {', '.join(HONOURED)}); export the scene without them")
    if DRACO in required:
        from diviewer.scene.gltf_draco import require_dracopy

        require_dracopy(d, "extensionsRequired")
    ignored = [x for x in used if x not in HONOURED and x not in required]
    if ignored:
        note_warning(f"{d.file}: extensionsUsed: not honoured, their effect is left out: {', '.join(ignored)}")


def image(d: Doc, buffers: list[bytes], index, base: Path, field: str, user: str = ""):
    """Image ``index`` (referred to by ``field``; ``user``: who uses it, for messages) as (rgb, alpha, source):
    a file next to the glTF, a data URI or a buffer view."""
    img = d.get("images", index, field)
    where = f"images[{index}]"
    label = f"{d.file} {where}"
    named = f"{user} ({where})" if user else where
    if "bufferView" in img:
        return (*load_texture_bytes(view_bytes(d, buffers, img["bufferView"], f"{where}.bufferView"), label,
                                    path=d.file, field=named), label)
    uri = img.get("uri")
    if isinstance(uri, str) and uri.startswith("data:"):
        return (*load_texture_bytes(data_uri(uri, d, f"{where}.uri", "image"), label, path=d.file, field=named),
                label)
    file = d.uri(img, base, f"{where}.uri", "image")
    return (*load_texture(file, path=d.file, field=named), str(file))


def _texture_ref(d: Doc, buffers, ref: dict, base: Path, field: str):
    """A material's texture reference (``{"index": ...}``) as (rgb, alpha, source)."""
    if d.int(ref, "texCoord", f"{field}.texCoord", 0) != 0:
        raise d.err(f"{field}.texCoord", "only TEXCOORD_0 is read; bake the texture onto the first uv set")
    tex = d.get("textures", ref.get("index"), f"{field}.index")
    t_field = f"textures[{ref['index']}]"
    if "sampler" in tex:
        d.index("samplers", tex["sampler"], f"{t_field}.sampler")
    if "source" not in tex:
        raise d.err(f"{t_field}.source", "the texture has no image (an extension's image is not supported)")
    return image(d, buffers, tex["source"], base, f"{t_field}.source", field)


def uv_transform(d: Doc, ref: dict, field: str) -> np.ndarray | None:
    """KHR_texture_transform of a texture reference as a 3x3 matrix on glTF uvs (translation x rotation x
    scale, as the extension defines it), or None."""
    ext = d.table(d.table(ref, "extensions", f"{field}.extensions"), "KHR_texture_transform",
                  f"{field}.extensions.KHR_texture_transform")
    if not ext:
        return None
    where = f"{field}.extensions.KHR_texture_transform"
    if d.int(ext, "texCoord", f"{where}.texCoord", 0) != 0:
        raise d.err(f"{where}.texCoord", "only TEXCOORD_0 is read; bake the texture onto the first uv set")
    ox, oy = d.nums(ext, "offset", 2, f"{where}.offset", (0.0, 0.0))
    sx, sy = d.nums(ext, "scale", 2, f"{where}.scale", (1.0, 1.0))
    r = d.num(ext, "rotation", f"{where}.rotation", 0.0)
    c, s = math.cos(r), math.sin(r)
    translation = np.array([[1, 0, ox], [0, 1, oy], [0, 0, 1]], np.float64)
    rotation = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], np.float64)  # the GLSL of the spec, row-major
    scale = np.diag([sx, sy, 1.0])
    return translation @ rotation @ scale


def material(d: Doc, buffers: list[bytes], i: int, name: str, base: Path) -> tuple[Material, np.ndarray | None]:
    """glTF material ``i`` as a Material named ``name``, and its textures' uv transform (or None)."""
    m = d.array("materials")[i]
    where = f"materials[{i}]"
    pbr = d.table(m, "pbrMetallicRoughness", f"{where}.pbrMetallicRoughness")
    factor = d.nums(pbr, "baseColorFactor", 4, f"{where}.pbrMetallicRoughness.baseColorFactor",
                    (1.0, 1.0, 1.0, 1.0), lo=0.0, hi=1.0)
    texture = alpha = transform = None
    source = ""
    if "baseColorTexture" in pbr:
        field = f"{where}.pbrMetallicRoughness.baseColorTexture"
        ref = d.table(pbr, "baseColorTexture", field)
        texture, alpha, source = _texture_ref(d, buffers, ref, base, field)
        transform = uv_transform(d, ref, field)
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
            alpha = frozen_array(alpha * factor[3])
    else:
        alpha = None  # OPAQUE ignores alpha; BLEND is drawn opaque (no transparency in these renderers)
    emission = np.asarray(d.nums(m, "emissiveFactor", 3, f"{where}.emissiveFactor", (0.0, 0.0, 0.0), lo=0.0))
    exts = d.table(m, "extensions", f"{where}.extensions")
    if "KHR_materials_emissive_strength" in exts:
        field = f"{where}.extensions.KHR_materials_emissive_strength"
        emission = emission * d.num(d.table(exts, "KHR_materials_emissive_strength", field), "emissiveStrength",
                                    f"{field}.emissiveStrength", 1.0, lo=0.0)
    emission_texture, emission_source = None, ""
    if "emissiveTexture" in m and emission.max() > 0.0:
        field = f"{where}.emissiveTexture"
        ref = d.table(m, "emissiveTexture", field)
        rgb, _, src = _texture_ref(d, buffers, ref, base, field)
        own = uv_transform(d, ref, field)
        if "baseColorTexture" not in pbr:
            emission_texture, emission_source, transform = rgb, src, own  # the uvs take the emission's transform
        elif _same_transform(own, transform):
            emission_texture, emission_source = rgb, src
        else:
            note_warning(f"{d.file}: {field}: material '{name}' places its emissive "
                         f"texture ({src}) with another transform than its base colour texture, and diviewer reads one "
                         f"uv set per material: its emission is left out. Export both textures with the same "
                         f"transform (or bake the emission onto the base colour's uvs)")
            emission = np.zeros(3)
    if not np.all(np.isfinite(emission)) or emission.max() > 3.0e38:
        raise d.err(f"{where}.emissiveFactor", "emissiveFactor times emissiveStrength is beyond float32")
    return Material(name, albedo=factor[:3], emission=tuple(map(float, emission)), texture=texture,
                    texture_source=source, alpha=alpha, alpha_cutoff=cutoff if mode == "MASK" else 0.5,
                    emission_texture=emission_texture, emission_texture_source=emission_source,
                    double_sided=d.flag(m, "doubleSided", f"{where}.doubleSided", False)), transform


def _same_transform(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    """Whether two KHR_texture_transform matrices (None: none, the identity) move uvs alike."""
    eye = np.eye(3)
    return bool(np.allclose(eye if a is None else a, eye if b is None else b, rtol=0.0, atol=1e-9))


def toml_key(name: str) -> str:
    """A material name as a TOML table key: bare where TOML allows, else quoted."""
    bare = name and all(c.isascii() and (c.isalnum() or c in "-_") for c in name)
    return name if bare else '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"'


def apply_uv_transform(uv: np.ndarray, transform: np.ndarray) -> np.ndarray:
    """Diviewer uvs (v = 0 at the image's bottom) moved by a KHR_texture_transform matrix on glTF uvs."""
    g = np.stack([uv[:, 0], 1.0 - uv[:, 1], np.ones(len(uv))], axis=1).astype(np.float64) @ transform.T
    return np.stack([g[:, 0], 1.0 - g[:, 1]], axis=1).astype(np.float32)
