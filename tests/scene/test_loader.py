"""Scene files: the shipped scenes load cleanly; bad files give one clear error naming file and field."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.scene import camera as cam
from diviewer.scene import load_scene, sample_config
from diviewer.scene.loader import config_from_dict
from diviewer.scene.sampler import matrix_to_euler_xyz

SHIPPED = ["cornell", "sponza", "atrium"]


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scene_loads_with_clean_geometry(name):
    scene = load_scene(name)
    assert scene.name == name and len(scene.file_hash) == 64
    for mesh in scene.meshes.values():
        assert np.all(np.isfinite(mesh.vertices)), mesh.name
        np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-5, err_msg=mesh.name)
        assert mesh.faces.max() < len(mesh.vertices)
        v = mesh.vertices[mesh.faces.astype(np.int64)]
        area = np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
        assert area.min() > 0, mesh.name
    for obj in scene.default.objects:
        assert obj.mesh in scene.meshes and obj.material in scene.materials
        assert np.all(np.isfinite(obj.matrix()))


def test_cornell_has_its_parts():
    scene = load_scene("cornell")
    mats = {o.name: scene.materials[o.material].albedo for o in scene.default.objects}
    assert mats["left"][0] > 3 * mats["left"][1], "left wall is red"
    assert mats["right"][1] > 2 * mats["right"][0], "right wall is green"
    r = scene.ranges.objects["center"]
    assert not set(r.train_meshes) & set(r.test_meshes)
    assert len(r.axes) >= 2


def test_box_is_faceted_and_sphere_is_smooth():
    scene = load_scene("cornell")
    box = scene.meshes["cube"]
    assert len(box.vertices) == 24  # creases split: one normal per face corner
    sphere = scene.meshes["sphere"]
    # on a sphere centred at the origin the smooth normal is the position direction
    d = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    assert np.min(np.sum(d * sphere.normals, axis=1)) > 0.999


@pytest.mark.slow
@pytest.mark.parametrize("name", SHIPPED)
def test_sampler_is_reproducible_and_respects_splits(name):
    scene = load_scene(name)
    a = [sample_config(scene, s, "train").to_dict() for s in range(20)]
    b = [sample_config(scene, s, "train").to_dict() for s in range(20)]
    assert a == b
    assert a[0] != a[1]
    r = scene.ranges.objects.get("center")
    if r is not None:
        train_meshes = {sample_config(scene, s, "train").objects[-1].mesh for s in range(50)}
        test_meshes = {sample_config(scene, s, "test").objects[-1].mesh for s in range(50)}
        assert train_meshes <= set(r.train_meshes) and test_meshes <= set(r.test_meshes)
        assert len(train_meshes) > 2 and len(test_meshes) > 1


def test_config_round_trips_through_json_dict():
    scene = load_scene("cornell")
    cfg = sample_config(scene, 5, "test")
    assert config_from_dict(scene, cfg.to_dict()).to_dict() == cfg.to_dict()


def test_euler_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(100):
        r = cam.axis_angle(rng.normal(size=3), rng.uniform(-180, 180))
        np.testing.assert_allclose(cam.euler_xyz(matrix_to_euler_xyz(r)), r, atol=1e-9)


def test_camera_view_matrix_conventions():
    v = cam.look_at((0, 0, 5), (0, 0, 0), (0, 1, 0))
    np.testing.assert_allclose(v @ [0, 0, 0, 1], [0, 0, -5, 1])   # target straight ahead (-z)
    np.testing.assert_allclose(v @ [1, 0, 5, 1], [1, 0, 0, 1])    # world +x is to the right
    np.testing.assert_allclose(cam.view_to_world(v) @ v, np.identity(4), atol=1e-12)
    p = cam.perspective(90, 2.0, 1.0, 10.0)
    clip = p @ [2.0, 1.0, -1.0, 1.0]
    np.testing.assert_allclose(clip[:3] / clip[3], [1.0, 1.0, -1.0])  # near plane corner
    np.testing.assert_allclose(v @ [0, 1, 5, 1], [0, 1, 0, 1])    # world +y is up
    far = p @ [0.0, 0.0, -10.0, 1.0]
    assert far[2] / far[3] == pytest.approx(1.0)  # far plane at clip z = +w


def test_orthographic_maps_its_box_to_the_clip_cube():
    o = cam.orthographic(2.0, 3.0, 0.5, 9.0)
    np.testing.assert_allclose(o @ [2.0, 3.0, -0.5, 1.0], [1, 1, -1, 1], atol=1e-12)
    np.testing.assert_allclose(o @ [-2.0, -3.0, -9.0, 1.0], [-1, -1, 1, 1], atol=1e-12)


def test_rotations_are_right_handed_column_matrices():
    """pyrr builds them; pin them to the right-hand rule and Rodrigues' formula (column vectors)."""
    x, y, z = np.identity(3)
    np.testing.assert_allclose(cam.axis_angle(z, 90) @ x, y, atol=1e-12)
    np.testing.assert_allclose(cam.axis_angle(x, 90) @ y, z, atol=1e-12)
    np.testing.assert_allclose(cam.axis_angle(y, 90) @ z, x, atol=1e-12)
    rng = np.random.default_rng(3)
    for _ in range(20):
        a, deg, v = rng.normal(size=3), rng.uniform(-360, 360), rng.normal(size=3)
        k, th = a / np.linalg.norm(a), np.radians(deg)
        rodrigues = v * np.cos(th) + np.cross(k, v) * np.sin(th) + k * (k @ v) * (1 - np.cos(th))
        np.testing.assert_allclose(cam.axis_angle(a, deg) @ v, rodrigues, atol=1e-12)
    # Euler xyz: about x first, then y, then z.
    np.testing.assert_allclose(cam.euler_xyz((90, 90, 0)) @ y, x, atol=1e-12)
    e = rng.uniform(-180, 180, 3)
    np.testing.assert_allclose(cam.euler_xyz(e), cam.axis_angle(z, e[2]) @ cam.axis_angle(y, e[1]) @ cam.axis_angle(x, e[0]),
                               atol=1e-12)
    p, s, v = rng.normal(size=3), rng.uniform(-2, 2, 3), rng.normal(size=3)
    np.testing.assert_allclose(cam.trs(p, e, s) @ np.append(v, 1.0), np.append(p + cam.euler_xyz(e) @ (s * v), 1.0),
                               atol=1e-12)


# --- bad input ------------------------------------------------------------------------------------

BASE = """
[camera]
position = [0, 0, 5]
fov = 45
near = 0.1
far = 50

[materials.m]
albedo = [0.5, 0.5, 0.5]

[meshes.b]
shape = "box"

[[objects]]
name = "o"
mesh = "b"
material = "m"

[[lights]]
name = "sun"
type = "directional"
direction = [0, -1, 0]
irradiance = 1.0
"""


def write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _obj_file(tmp_path: Path, vertices: str) -> Path:
    p = tmp_path / "m.obj"
    p.write_text(vertices)
    return p


BAD = {
    "toml_syntax": (BASE + "\n[oops\n", None, "not valid TOML"),
    "unknown_key": (BASE.replace("fov = 45", "fov = 45\nfocal = 3"), "camera.focal", "unknown key"),
    "unknown_table": (BASE + "\n[lighting]\nx = 1\n", "lighting", "unknown key"),
    "missing_mesh_file": (BASE + '\n[meshes.f]\nfile = "nope.obj"\n', "meshes.f.file", "not found"),
    "negative_intensity": (BASE.replace("irradiance = 1.0", "irradiance = -2.0"), "lights[0].irradiance", ">= 0"),
    "fov_zero": (BASE.replace("fov = 45", "fov = 0"), "camera.fov", "> 0"),
    "fov_180": (BASE.replace("fov = 45", "fov = 180"), "camera.fov", "< 180"),
    "near_ge_far": (BASE.replace("near = 0.1", "near = 60"), "camera.near", "less than far"),
    "unknown_shape": (BASE.replace('shape = "box"', 'shape = "teapot"'), "meshes.b.shape", "unknown shape"),
    "bad_albedo": (BASE.replace("albedo = [0.5, 0.5, 0.5]", "albedo = [0.5, 1.5, 0.5]"), "materials.m.albedo", "<= 1"),
    "unknown_material": (BASE.replace('material = "m"', 'material = "x"'), "objects[0].material", "unknown material"),
    "light_type": (BASE.replace('type = "directional"', 'type = "spot"'), "lights[0].type", "not one of"),
    "zero_scale": (BASE.replace('material = "m"', 'material = "m"\nscale = [1, 0, 1]'), "objects[0].scale", "non-zero"),
    "string_for_number": (BASE.replace("fov = 45", 'fov = "wide"'), "camera.fov", "finite number"),
    "shadow_size_fraction": ("[scene]\nshadow_size = 1000.5\n" + BASE, "scene.shadow_size", "whole number"),
    "shadow_size_too_big": ("[scene]\nshadow_size = 32768\n" + BASE, "scene.shadow_size", "<= 16384"),
    "shadow_size_tiny": ("[scene]\nshadow_size = 4\n" + BASE, "scene.shadow_size", ">= 16"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_scene_file_names_file_and_field(tmp_path, case):
    text, field, words = BAD[case]
    path = write(tmp_path, text)
    with pytest.raises(DiviewerError) as info:
        load_scene(path)
    msg = str(info.value)
    assert str(path) in msg
    if field:
        assert field in msg
    assert words in msg


def test_mesh_with_nan_vertices_is_refused(tmp_path):
    _obj_file(tmp_path, "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n")
    path = write(tmp_path, BASE + '\n[meshes.f]\nfile = "m.obj"\n')
    with pytest.raises(DiviewerError, match=r"meshes\.f.*NaN"):
        load_scene(path)


def test_mesh_with_zero_area_faces_is_refused(tmp_path):
    _obj_file(tmp_path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\n")
    path = write(tmp_path, BASE + '\n[meshes.f]\nfile = "m.obj"\n')
    with pytest.raises(DiviewerError, match=r"meshes\.f.*zero-area"):
        load_scene(path)


def test_mesh_files_load(tmp_path):
    import trimesh

    trimesh.creation.icosphere(2).export(tmp_path / "ball.ply")
    trimesh.creation.box().export(tmp_path / "cube.obj")
    path = write(tmp_path, BASE + '\n[meshes.ball]\nfile = "ball.ply"\n[meshes.cube]\nfile = "cube.obj"\n')
    scene = load_scene(path)
    assert len(scene.meshes["ball"].faces) == 320
    assert np.all(np.isfinite(scene.meshes["cube"].normals))


def test_glb_with_base_colour_texture(tmp_path):
    import trimesh
    from PIL import Image

    tex = np.zeros((4, 4, 3), np.uint8)
    tex[:2] = [255, 0, 0]  # top half red
    tex[2:] = [0, 0, 255]  # bottom half blue
    img = Image.fromarray(tex)
    box = trimesh.creation.box()
    uv = np.clip(box.vertices[:, :2] + 0.5, 0, 1)
    box.visual = trimesh.visual.TextureVisuals(uv=uv, material=trimesh.visual.material.PBRMaterial(baseColorTexture=img))
    box.export(tmp_path / "tex.glb")
    path = write(tmp_path, BASE + '\n[meshes.t]\nfile = "tex.glb"\n\n[[objects]]\nname = "t"\nmesh = "t"\n')
    scene = load_scene(path)
    mat = scene.materials["mesh:t"]
    assert mat.texture is not None and mat.texture.shape == (4, 4, 3)
    assert scene.meshes["t"].uvs is not None
    obj = next(o for o in scene.default.objects if o.name == "t")
    assert obj.material == "mesh:t"


def test_srgb_curve_round_trips_and_hits_known_values():
    from diviewer.scene.colour import linear_to_srgb, srgb8, srgb_to_linear

    x = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-12)
    # IEC 61966-2-1: 8-bit 128 is linear 0.2158605; the linear segment ends at 0.0031308 -> 0.04045.
    assert srgb_to_linear(128 / 255) == pytest.approx(0.2158605, abs=1e-7)
    assert linear_to_srgb(0.0031308) == pytest.approx(0.04045, abs=1e-6)
    assert srgb8(np.array([np.nan, -1.0, 0.2158605, 2.0])).tolist() == [0, 0, 128, 255]


# --- the scene's identity covers every file it loads (issue 29 item 3) ---------------------------------
def _edit_png(path: Path) -> None:
    from PIL import Image

    img = np.array(Image.open(path))
    img[0, 0, 1] ^= 0x40  # one channel of one texel
    Image.fromarray(img).save(path)


def test_editing_a_texture_or_a_buffer_changes_the_scene_identity(tmp_path):
    from gltf_doc import write_scene

    path = write_scene(tmp_path)
    scene = load_scene(path)
    before, texels = scene.file_hash, scene.materials["leaf"].texture
    tex, bin_ = tmp_path / "tex.png", tmp_path / "tiny.bin"
    original_tex, original_bin = tex.read_bytes(), bin_.read_bytes()
    _edit_png(tex)
    after_texture = load_scene(path)
    assert after_texture.file_hash != before
    assert not np.array_equal(after_texture.materials["leaf"].texture, texels), "the edited texture is what loads"
    tex.write_bytes(original_tex)
    assert load_scene(path).file_hash == before, "the identity is the content, not the file's mtime"
    raw = bytearray(original_bin)
    raw[0:4] = np.float32(-1.25).tobytes()  # the quad's first x coordinate
    bin_.write_bytes(bytes(raw))
    edited = load_scene(path)
    assert edited.file_hash not in (before, after_texture.file_hash)
    assert edited.meshes["quad"].vertices[0, 0] == -1.25, "the glTF cache reads an edited buffer again"
    bin_.write_bytes(original_bin)
    assert load_scene(path).file_hash == before


def test_an_obj_files_material_and_texture_are_in_the_scene_identity(tmp_path):
    from PIL import Image

    (tmp_path / "m.obj").write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\n"
                                    "usemtl red\nf 1/1 2/2 3/3\n")
    (tmp_path / "m.mtl").write_text("newmtl red\nKd 1 1 1\nmap_Kd tex.png\n")
    Image.fromarray(np.full((4, 4, 3), (200, 50, 50), np.uint8)).save(tmp_path / "tex.png")
    path = write(tmp_path, BASE + '\n[meshes.f]\nfile = "m.obj"\n')
    before = load_scene(path)
    assert before.materials["mesh:f"].texture is not None
    _edit_png(tmp_path / "tex.png")
    after_texture = load_scene(path).file_hash
    assert after_texture != before.file_hash
    (tmp_path / "m.mtl").write_text("newmtl red\nKd 1 1 1\nmap_Kd tex.png\n# edited\n")
    assert load_scene(path).file_hash not in (before.file_hash, after_texture)


def test_a_model_trained_before_a_texture_edit_is_refused_after_it(tmp_path):
    pytest.importorskip("onnx")
    from gltf_doc import write_scene
    from onnx_models import base_meta, direct_times

    from diviewer.contract.runtime import NeuralGI

    path = write_scene(tmp_path / "scene")
    before = load_scene(path)
    model = direct_times(tmp_path / "m.onnx", meta=base_meta(scene_hash=before.file_hash, scene=before.name))
    NeuralGI(model, scene=before)  # accepted for the scene it was made for
    _edit_png(tmp_path / "scene" / "tex.png")
    with pytest.raises(DiviewerError, match="scene_hash") as exc:
        NeuralGI(model, scene=load_scene(path))
    assert "another version of its file" in str(exc.value)


needs_mitsuba = pytest.mark.skipif(__import__("importlib").util.find_spec("mitsuba") is None,
                                   reason="needs mitsuba (pip install 'diviewer[train]')")


@pytest.mark.slow
@needs_mitsuba
def test_a_capture_before_and_after_a_texture_edit_is_not_one_dataset(gl_context, tmp_path):
    from gltf_doc import write_scene

    from diviewer.data.capture import CaptureSettings, build_manifest, capture, merge, open_or_create
    from diviewer.data.dataset import Dataset

    path = write_scene(tmp_path / "scene")
    settings = CaptureSettings(frames=2, seed=0, width=16, height=16, spp=2, max_depth=3)
    capture(path, tmp_path / "a", settings, shard=(1, 2), log=lambda *_: None)
    assert len(Dataset(tmp_path / "a").indices()) == 1
    _edit_png(tmp_path / "scene" / "tex.png")
    with pytest.raises(DiviewerError, match="scene_hash"):  # resuming into the same folder after the edit
        capture(path, tmp_path / "a", settings, shard=(2, 2), log=lambda *_: None)
    # the other shard captured after the edit (its manifest is enough: the check comes before any frame)
    open_or_create(tmp_path / "b", build_manifest(load_scene(path), settings))
    with pytest.raises(DiviewerError, match="scene_hash"):
        merge([tmp_path / "a", tmp_path / "b"], tmp_path / "merged", log=lambda *_: None)
    assert not (tmp_path / "merged").exists()


def test_model_matrices_and_bounds_are_memoised_but_never_shared():
    """trs and Scene.bounds are cached (the viewer asks every frame), yet each call returns its own array and a
    moved object gets its own matrix and box."""
    m = cam.trs((1.0, 2.0, 3.0), (10.0, 20.0, 30.0), (1.0, 2.0, 0.5))
    m[0, 0] = 99.0
    again = cam.trs([1, 2, 3], np.array([10.0, 20.0, 30.0]), (1, 2, 0.5))
    assert again[0, 0] != 99.0
    expected = np.identity(4)
    expected[:3, :3] = cam.euler_xyz((10.0, 20.0, 30.0)) @ np.diag([1.0, 2.0, 0.5])
    expected[:3, 3] = (1.0, 2.0, 3.0)
    np.testing.assert_allclose(again, expected, atol=1e-12)
    with pytest.raises(ValueError, match="three 3-vectors"):
        cam.trs((0.0, 0.0), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))

    scene = load_scene("cornell")
    b = scene.bounds()
    b[:] = 0.0
    assert np.ptp(scene.bounds(), axis=0).min() > 0.1
    name = scene.default.objects[-1].name
    moved = scene.default.replace_object(name, position=(0.0, 5.0, 0.0))
    assert scene.bounds(moved)[1, 1] >= 5.0 > scene.bounds()[1, 1]


def test_the_shadow_map_size_is_the_scenes_and_not_its_identity(tmp_path):
    """``[scene] shadow_size`` sets the rasterizer's map (2048 unless the file says otherwise); the path tracer does
    not see it, so the scene's identity, which models and evaluation sets record, stays the same."""
    head = '[scene]\nname = "s"\n'
    plain = load_scene(write(tmp_path, head + BASE, "a.toml"))
    sized = load_scene(write(tmp_path, head + "shadow_size = 4096\n" + BASE, "b.toml"))
    assert (plain.shadow_size, sized.shadow_size) == (2048, 4096)
    assert sized.file_hash == plain.file_hash
    moved = load_scene(write(tmp_path, head + BASE.replace("direction = [0, -1, 0]", "direction = [0, -1, 1]"), "c.toml"))
    assert moved.file_hash != plain.file_hash
    assert load_scene("sponza").shadow_size == 8192 and load_scene("cornell").shadow_size == 2048
