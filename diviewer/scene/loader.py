"""TOML scene files: parse, validate every field (unknown keys are errors), build a Scene."""

from __future__ import annotations

import dataclasses
import tomllib
import warnings
from pathlib import Path

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.paths import scenes_dir
from diviewer.scene import gltf, shapes
from diviewer.scene.identity import scene_identity
from diviewer.scene.reads import SceneWarning, note_warning, recording_reads, recording_warnings
from diviewer.scene.model import Camera, DirectionalLight, FrameConfig, Material, Object, PointLight, Scene
from diviewer.scene.scene_ranges import parse_ranges as _ranges
from diviewer.scene.toml_table import FLOAT32_MAX, entries, f32, TomlTable  # noqa: F401 (FLOAT32_MAX: re-exported)


MAX_FAR_NEAR = 1e5
"""Largest camera far/near ratio. The G-buffer's 24-bit depth buffer stores 1 - near/distance in
effect, so at far/near = 2**24 (1.7e7) everything beyond that distance is clipped (measured: near
1e-6, far 10 renders a wall at 9 black); at 1e5 surfaces 0.6 % of their distance apart still sort
correctly at the far plane. Refused rather than rendered wrong (a reversed-Z buffer would lift it)."""


def resolve_scene_path(scene: str | Path) -> Path:
    """A shipped scene's name (``cornell``) or a path to a .toml file."""
    p = Path(scene)
    if p.suffix == ".toml" or p.exists() or len(p.parts) > 1:
        if not p.is_file():
            raise DiviewerError(f"scene file not found: {p}")
        return p
    shipped = scenes_dir() / f"{scene}.toml"
    if not shipped.is_file():
        names = sorted(x.stem for x in scenes_dir().glob("*.toml"))
        raise DiviewerError(f"no shipped scene named '{scene}'; shipped scenes: {', '.join(names)}; or pass a path to a .toml file")
    return shipped


def load_scene(scene: str | Path) -> Scene:
    """Load and validate a scene by shipped name or path; its identity hash covers every file it loads."""
    path = resolve_scene_path(scene)
    blob = path.read_bytes()
    try:
        data = tomllib.loads(blob.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DiviewerError(f"not valid TOML: {exc}", path=path) from exc
    with recording_reads() as files:
        parsed = parse_scene(data, path=path)
    return dataclasses.replace(parsed, file_hash=scene_identity(data, files, path.parent))


def load_recorded_scene(manifest: dict, where: Path, refusal: str) -> Scene:
    """The scene a capture or an evaluation set (its ``manifest``) was made from: the manifest's ``scene_file``
    where it still exists (a file outside assets/, or one a set was restamped to), else the shipped scene of its
    name. Refused unless that file is the one the manifest records (``scene_hash``): ``refusal`` says what it
    stops, ``where`` is the file the error names."""
    path = manifest.get("scene_file")
    scene = load_scene(path if path and Path(path).is_file() else manifest["scene"])
    if scene.file_hash != manifest["scene_hash"]:
        raise DiviewerError(f"the scene file {scene.path} is not the one it was made from: {refusal}", path=where,
                            field="scene_hash")
    return scene


def parse_scene(data: dict, *, path: Path | None = None, file_hash: str = "") -> Scene:
    """A Scene from a scene file's parsed TOML (``path``: the file, for messages and relative paths); what it
    could not take as written is kept in ``Scene.warnings`` and said as SceneWarnings."""
    with recording_warnings() as said:
        scene = _parse_scene(data, path, file_hash)
    for message in said:
        warnings.warn(message, SceneWarning, stacklevel=3)
    return dataclasses.replace(scene, warnings=tuple(said))


def _parse_scene(data: dict, path: Path | None, file_hash: str) -> Scene:
    root = TomlTable(data, path, "")
    base = path.parent if path is not None else Path.cwd()

    head = root.table("scene")
    name = head.str("name", path.stem if path else "scene")
    exposure = head.num("exposure", 0.0, lo=-40, hi=40)
    auto_exposure = head.bool("auto_exposure", False)
    ambient = head.vec("ambient", 3, (0.0, 0.0, 0.0), lo=0.0)
    shadow_size = head.num("shadow_size", 2048, lo=16, hi=16384)  # 16384: every OpenGL 4.5 driver's texture limit
    if shadow_size != int(shadow_size):
        raise head.err("shadow_size", f"expected a whole number of texels, got {shadow_size:g}")
    head.finish()

    camera = camera_from_table(root.table("camera"))

    materials: dict[str, Material] = {}
    meshes = {}
    objects = []
    if root.has("gltf"):
        # A whole glTF scene: its meshes, materials and placed objects, before the file's own.
        g = root.table("gltf")
        meshes, materials, objects = gltf.load_gltf(base / g.str("file"), path=path, field="gltf.file")
        g.finish()

    if gltf.DEFAULT_MATERIAL in materials and gltf.DEFAULT_MATERIAL not in root.table("materials").data:
        users = sum(o.material == gltf.DEFAULT_MATERIAL for o in objects)
        note_warning(f"{path}: gltf.file: {users} placed mesh(es) of the glTF have no material: they get "
                     f"'{gltf.DEFAULT_MATERIAL}', glTF's default, albedo {gltf.DEFAULT_ALBEDO[0]:g} (white, reflecting "
                     f"all light); give them one with [materials.{gltf.DEFAULT_MATERIAL}] albedo = [0.8, 0.8, 0.8]")
    from_gltf = set(materials) if root.has("gltf") else None
    for key, t in entries(root.table("materials"), lambda k: None):
        # A glTF material of the same name is overridden: the keys given replace its values, the rest stay.
        materials[key] = _material(key, t, base, path, materials.get(key))

    for key, t in entries(root.table("meshes"), _not_in_gltf(meshes, "mesh")):
        if t.has("file") == t.has("shape"):
            raise t.err("shape", "a mesh needs exactly one of 'shape' (procedural) or 'file'")
        if t.has("shape"):
            shape = t.str("shape")
            params = {k: t.raw(k) for k in list(t.data) if k != "shape"}
            meshes[key] = shapes.procedural(key, shape, params, path=path, field=t.where)
        else:
            mesh, color, texture = shapes.load_file(key, base / t.str("file"), path=path, field=t.where)
            meshes[key] = mesh
            if (color is not None or texture is not None) and f"mesh:{key}" not in materials:
                # The file's own material, used by objects that name no material.
                materials[f"mesh:{key}"] = Material(f"mesh:{key}", albedo=color or (1.0, 1.0, 1.0), texture=texture,
                                                    texture_source=str(base / t.data["file"]))

    objects += _objects(root, path, meshes, materials, {o.name for o in objects})
    if not objects:
        raise DiviewerError("a scene needs at least one object ([[objects]] or [gltf])", path=path, field="objects")
    if from_gltf is not None:
        _unused_overrides(root, path, from_gltf, {o.material for o in objects})

    lights = []
    raw_lights = root.raw("lights", [])
    if not isinstance(raw_lights, list):
        raise root.err("lights", "expected an array of tables ([[lights]])")
    for i, l in enumerate(raw_lights):
        lights.append(_light(TomlTable(l, path, f"lights[{i}]"), i))
    if len({l.name for l in lights}) != len(lights):
        raise DiviewerError("light names must be unique", path=path, field="lights")

    default = FrameConfig(camera=camera, lights=tuple(lights), objects=tuple(objects))
    ranges = _ranges(root.table("ranges"), default, meshes)
    root.finish()
    return Scene(name=name, path=path, file_hash=file_hash, meshes=meshes, materials=materials, default=default,
                 ranges=ranges, exposure=exposure, auto_exposure=auto_exposure, ambient=ambient,
                 shadow_size=int(shadow_size))


def _unused_overrides(root: TomlTable, path: Path | None, from_gltf: set[str], used: set[str]) -> None:
    """A [materials.NAME] of a glTF scene that names no glTF material and that no object uses is most likely a
    misspelt override: said as a warning, with the glTF's material names."""
    for key in root.table("materials").data:
        if key not in from_gltf and key not in used:
            names = ", ".join(sorted(n for n in from_gltf if n in used)) or "none"
            note_warning(f"{path}: materials.{key}: no glTF material is named '{key}' and no object uses it, so it "
                         f"changes nothing; the glTF's materials in use: {names}")


def _material(key: str, t: TomlTable, base: Path, path: Path | None, over: Material | None = None) -> Material:
    """One [materials.KEY] table: albedo, emission, an optional texture and its alpha cut-out, double_sided.
    ``over``: the glTF material of that name, whose values stand where the table gives none (its emission texture
    stays: ``emission`` replaces the factor that multiplies it)."""
    if over is None:
        over = Material(key, double_sided=True)  # a scene file's own material: both faces by default
        texture, alpha, tex_src, cutoff = None, None, "", 0.5
    else:
        texture, alpha, tex_src, cutoff = over.texture, over.alpha, over.texture_source, over.alpha_cutoff
    if t.has("texture"):
        tex_path = base / t.str("texture")
        texture, alpha = gltf.load_texture(tex_path, path=path, field=t._field("texture"))
        tex_src, cutoff = str(tex_path), 0.5
        alpha_kept = False
    else:
        t.raw("texture")  # an allowed key all the same
        alpha_kept = over.is_masked  # a glTF material's own cut-out stays unless its texture is replaced
    if t.has("alpha_cutoff"):
        # Alpha-tested: the texture's alpha channel is the cut-out mask (as glTF's alphaMode MASK).
        cutoff = t.num("alpha_cutoff", lo=0.0, hi=1.0)
        if alpha is None:
            raise t.err("alpha_cutoff", "needs a 'texture' with an alpha channel (the cut-out mask)")
    else:
        t.raw("alpha_cutoff")
        alpha = alpha if alpha_kept else None
    return Material(key, albedo=t.vec("albedo", 3, over.albedo, lo=0.0, hi=1.0),
                    emission=t.vec("emission", 3, over.emission, lo=0.0),
                    texture=texture, texture_source=tex_src, alpha=alpha, alpha_cutoff=cutoff,
                    emission_texture=over.emission_texture, emission_texture_source=over.emission_texture_source,
                    double_sided=t.bool("double_sided", over.double_sided))


def _objects(root: TomlTable, path: Path | None, meshes: dict, materials: dict, names: set[str]) -> list[Object]:
    """The [[objects]] array: each a mesh and a material by name, placed; names unique (``names``: those taken)."""
    objects = []
    raw_objects = root.raw("objects", [])
    if not isinstance(raw_objects, list):
        raise root.err("objects", "expected an array of tables ([[objects]])")
    for i, o in enumerate(raw_objects):
        t = TomlTable(o, path, f"objects[{i}]")
        oname = t.str("name", f"object{i}")
        if oname in names:
            raise t.err("name", f"duplicate object name '{oname}'")
        names.add(oname)
        mesh = t.str("mesh")
        if mesh not in meshes:
            raise t.err("mesh", f"unknown mesh '{mesh}'; meshes: {', '.join(meshes)}")
        default_mat = f"mesh:{mesh}" if f"mesh:{mesh}" in materials else None
        mat = t.str("material", default_mat)
        if mat not in materials:
            raise t.err("material", f"unknown material '{mat}'; materials: {', '.join(materials)}")
        scale = t.vec("scale", 3, (1.0, 1.0, 1.0))
        if min(abs(s) for s in scale) < 1e-9:
            raise t.err("scale", f"scale must be non-zero on every axis, got {scale}")
        objects.append(Object(oname, mesh, mat, position=t.vec("position", 3, (0.0, 0.0, 0.0)),
                              rotation=t.vec("rotation", 3, (0.0, 0.0, 0.0)), scale=scale))
        t.finish()
    return objects


def _not_in_gltf(defined: dict, what: str):
    """``entries``' check for a name the glTF file already defined."""
    return lambda key: f"{what} '{key}' is already defined by the glTF file" if key in defined else None


def camera_from_table(t: TomlTable) -> Camera:
    c = Camera(position=t.vec("position", 3, (0.0, 0.0, 5.0)), target=t.vec("target", 3, (0.0, 0.0, 0.0)),
               up=t.vec("up", 3, (0.0, 1.0, 0.0)), fov=t.num("fov", 45.0, lo=0.0, hi=180.0, lo_open=True, hi_open=True),
               near=t.num("near", 0.05, lo=0.0, lo_open=True), far=t.num("far", 100.0, lo=0.0, lo_open=True))
    if c.near >= c.far:
        raise t.err("near", f"near ({c.near}) must be less than far ({c.far})")
    if c.far / c.near > MAX_FAR_NEAR:
        raise t.err("near", f"far / near = {c.far / c.near:.3g} is more than the depth buffer resolves "
                            f"({MAX_FAR_NEAR:.0e}); raise near to at least {c.far / MAX_FAR_NEAR:.3g} or lower far")
    d = np.subtract(c.target, c.position)
    if np.linalg.norm(d) < 1e-9:
        raise t.err("target", "camera target equals its position")
    if np.linalg.norm(np.cross(d, c.up)) < 1e-9 * np.linalg.norm(d) * max(np.linalg.norm(c.up), 1e-30):
        raise t.err("up", "camera 'up' is zero or parallel to the viewing direction")
    t.finish()
    return c


def _light(t: TomlTable, i: int):
    kind = t.str("type", choices=("directional", "point"))
    name = t.str("name", f"light{i}")
    color = t.vec("color", 3, (1.0, 1.0, 1.0), lo=0.0)
    if kind == "directional":
        direction = t.vec("direction", 3)
        if np.linalg.norm(direction) < 1e-9:
            raise t.err("direction", "direction must be non-zero")
        light = DirectionalLight(name, direction=tuple(float(x) for x in np.divide(direction, np.linalg.norm(direction))),
                                 color=color, irradiance=t.num("irradiance", 1.0, lo=0.0))
        strength = ("irradiance", light.irradiance)
    else:
        light = PointLight(name, position=t.vec("position", 3), color=color, intensity=t.num("intensity", 1.0, lo=0.0))
        strength = ("intensity", light.intensity)
    # The shader multiplies colour by strength: the product must stay in float32 too.
    if not f32(max(color) * strength[1]):
        raise t.err(strength[0], f"color x {strength[0]} = {max(color) * strength[1]:.3g} is outside float32's range "
                                 f"(+-3.4e38), in which it is rendered")
    t.finish()
    return light


def add_mesh_file(scene: Scene, path: str | Path, key: str | None = None) -> tuple[Scene, str, str | None]:
    """The scene with a mesh file (OBJ, PLY, glTF, ...) added to its mesh library.

    Returns:
        The new scene, the mesh's key (``file:<stem>`` unless given) and the key of the file's own
        material (base colour or texture) or None when the file has none.
    """
    import dataclasses

    path = Path(path).expanduser()
    key = key or f"file:{path.stem}"
    mesh, color, texture = shapes.load_file(key, path)
    materials = dict(scene.materials)
    material = None
    if color is not None or texture is not None:
        material = f"mesh:{key}"
        materials[material] = Material(material, albedo=tuple(color or (1.0, 1.0, 1.0)), texture=texture,
                                       texture_source=str(path))
    return dataclasses.replace(scene, meshes={**scene.meshes, key: mesh}, materials=materials), key, material


def config_from_dict(scene: Scene, data: dict, *, path=None) -> FrameConfig:
    """Rebuild a FrameConfig written by FrameConfig.to_dict, checked against the scene."""
    t = TomlTable(data, path, "")
    camera = camera_from_table(t.table("camera"))
    for key in ("lights", "objects"):
        if not isinstance(t.data.get(key, []), list):
            raise t.err(key, f"expected a list of tables, got {t.data[key]!r}")
    lights = []
    for i, l in enumerate(t.raw("lights", [])):
        lights.append(_light(TomlTable(l, path, f"lights[{i}]"), i))
    objects = []
    for i, o in enumerate(t.raw("objects", [])):
        ot = TomlTable(o, path, f"objects[{i}]")
        mesh, mat = ot.str("mesh"), ot.str("material")
        if mesh not in scene.meshes:
            raise ot.err("mesh", f"scene '{scene.name}' has no mesh '{mesh}'")
        if mat not in scene.materials:
            raise ot.err("material", f"scene '{scene.name}' has no material '{mat}'")
        objects.append(Object(ot.str("name"), mesh, mat, position=ot.vec("position"), rotation=ot.vec("rotation"),
                              scale=ot.vec("scale")))
        ot.finish()
    t.finish()
    return FrameConfig(camera=camera, lights=tuple(lights), objects=tuple(objects))
