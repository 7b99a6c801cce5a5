"""Scene files at the extremes (no GL): float32 range, near/far, fov, procedural parameters, mesh files."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from diviewer.errors import DiviewerError
from diviewer.scene.loader import MAX_FAR_NEAR, load_scene, parse_scene


def scene_dict(**over) -> dict:
    """A minimal valid scene as a dict; ``over`` replaces top-level tables."""
    data = {
        "scene": {"name": "x"},
        "camera": {"position": [0, 0, 5], "target": [0, 0, 0], "fov": 45, "near": 0.1, "far": 50},
        "materials": {"m": {"albedo": [0.5, 0.5, 0.5]}},
        "meshes": {"b": {"shape": "box"}},
        "objects": [{"name": "o", "mesh": "b", "material": "m"}],
        "lights": [{"name": "sun", "type": "directional", "direction": [0, -1, 0], "irradiance": 1.0}],
    }
    data.update(over)
    return data


def refused(data: dict, field: str) -> str:
    with pytest.raises(DiviewerError) as exc:
        parse_scene(data)
    assert field in str(exc.value), str(exc.value)
    return str(exc.value)


# --- float32 range: checked in the loader, before anything is rendered or written (issue case 4) ----
POINT = {"name": "p", "type": "point", "position": [0, 2, 0], "intensity": 1.0}
SUN = {"name": "sun", "type": "directional", "direction": [0, -1, 0], "irradiance": 1.0}


@pytest.mark.parametrize("light,field", [
    ({**POINT, "intensity": 1e39}, "lights[0].intensity"),
    ({**SUN, "irradiance": 1e39}, "lights[0].irradiance"),
    ({**SUN, "irradiance": 3.5e38}, "lights[0].irradiance"),
    ({**POINT, "color": [1e39, 1, 1]}, "lights[0].color"),
    ({**POINT, "intensity": 1e20, "color": [1e20, 1, 1]}, "lights[0].intensity"),  # the product overflows
    ({**POINT, "position": [1e39, 0, 0]}, "lights[0].position"),
])
def test_light_outside_float32_is_refused(light, field):
    assert "float32" in refused(scene_dict(lights=[light]), field)


def test_emission_outside_float32_is_refused():
    refused(scene_dict(materials={"m": {"albedo": [0.5] * 3, "emission": [1e39, 0, 0]}}), "materials.m.emission")


def test_light_range_that_draws_beyond_float32_is_refused():
    data = scene_dict(lights=[{**SUN, "irradiance": 1e37}], ranges={"lights": {"sun": {"intensity": [1.0, 100.0]}}})
    refused(data, "ranges.lights.sun.intensity")


@pytest.mark.parametrize("value", [0.0, 1e-8, 1.0, 1e8, 1e30, 3e38])
def test_light_strengths_within_float32_load(value):
    scene = parse_scene(scene_dict(lights=[{**POINT, "intensity": value}]))
    assert scene.default.lights[0].intensity == value


def test_colour_channel_zero_loads():
    scene = parse_scene(scene_dict(lights=[{**SUN, "color": [0.0, 1.0, 1.0]}]))
    assert scene.default.lights[0].color[0] == 0.0


# --- camera ------------------------------------------------------------------------------------
@pytest.mark.parametrize("near,far", [(0.1, 50.0), (1e-3, 100.0), (1e-4, 10.0), (1.0, 1e5), (2.9, 3.1)])
def test_near_far_within_the_depth_buffer_load(near, far):
    parse_scene(scene_dict(camera={"position": [0, 0, 5], "near": near, "far": far}))


@pytest.mark.parametrize("near,far", [(1e-7, 10.0), (1e-6, 10.0), (1e-5, 10.0), (1e-4, 1e4), (1e-9, 1.0)])
def test_near_far_beyond_the_depth_buffer_is_refused(near, far):
    """Issue case 6: near 1e-7, far 10 rendered black with exit 0; now refused, saying what to raise near to."""
    msg = refused(scene_dict(camera={"position": [0, 0, 5], "near": near, "far": far}), "camera.near")
    assert f"{far / MAX_FAR_NEAR:.3g}" in msg


@pytest.mark.parametrize("fov", [1.0, 179.0, 1e-3, 179.99])
def test_extreme_fov_loads(fov):
    assert parse_scene(scene_dict(camera={"position": [0, 0, 5], "fov": fov})).default.camera.fov == fov


@pytest.mark.parametrize("fov", [0.0, 180.0, -1.0, 360.0])
def test_impossible_fov_is_refused(fov):
    refused(scene_dict(camera={"position": [0, 0, 5], "fov": fov}), "camera.fov")


@pytest.mark.parametrize("camera,field", [
    ({"position": [0, 0, 0], "target": [0, 0, 0]}, "camera.target"),
    ({"position": [0, 0, 5], "up": [0, 0, 1]}, "camera.up"),
    ({"position": [0, 0, 5], "up": [0, 0, 0]}, "camera.up"),
])
def test_degenerate_camera_is_refused(camera, field):
    refused(scene_dict(camera=camera), field)


# --- procedural shapes (issue case 8) ------------------------------------------------------------
@pytest.mark.parametrize("mesh,field", [
    ({"shape": "sphere", "subdivisions": 10}, "meshes.b.subdivisions"),
    ({"shape": "sphere", "subdivisions": 1.5}, "meshes.b.subdivisions"),
    ({"shape": "sphere", "subdivisions": True}, "meshes.b.subdivisions"),
    ({"shape": "sphere", "subdivisions": -1}, "meshes.b.subdivisions"),
    ({"shape": "cylinder", "sections": 1}, "meshes.b.sections"),
    ({"shape": "cylinder", "sections": 2}, "meshes.b.sections"),
    ({"shape": "cone", "sections": 100000}, "meshes.b.sections"),
    ({"shape": "capsule_cluster", "count": 1.5}, "meshes.b.count"),
    ({"shape": "capsule_cluster", "count": 0}, "meshes.b.count"),
    ({"shape": "capsule_cluster", "count": 1000}, "meshes.b.count"),
    ({"shape": "torus_knot", "p": 2.5}, "meshes.b.p"),
    ({"shape": "sphere", "radius": 1e7}, "meshes.b.radius"),
    ({"shape": "sphere", "radius": 0}, "meshes.b.radius"),
    ({"shape": "sphere", "radius": "big"}, "meshes.b.radius"),
    ({"shape": "box", "size": [1, 2]}, "meshes.b.size"),
    ({"shape": "box", "size": []}, "meshes.b.size"),
    ({"shape": "plane", "size": [1, 2, 3]}, "meshes.b.size"),
    ({"shape": "torus", "major_radius": 0.2, "minor_radius": 0.3}, "meshes.b.minor_radius"),
    ({"shape": "pipe", "radius": 0.2, "inner_radius": 0.2}, "meshes.b.inner_radius"),
    ({"shape": "pipe", "sections": 2}, "meshes.b.sections"),
    ({"shape": "box_cluster", "count": 0}, "meshes.b.count"),
    ({"shape": "frame", "depth": 0}, "meshes.b.depth"),
])
def test_bad_procedural_parameters_are_refused(mesh, field):
    refused(scene_dict(meshes={"b": mesh}), field)


@pytest.mark.parametrize("mesh", [
    {"shape": "sphere", "subdivisions": 0}, {"shape": "sphere", "subdivisions": 5},
    {"shape": "cylinder", "sections": 3}, {"shape": "cone", "sections": 3},
    {"shape": "capsule_cluster", "count": 1}, {"shape": "box", "size": 2.0},
    {"shape": "sphere", "radius": 1e-3}, {"shape": "box", "size": [1e4, 1e-3, 1.0]},
    {"shape": "torus_knot", "p": 1, "q": 1},
    {"shape": "pipe", "sections": 3}, {"shape": "frame", "thickness": 10.0}, {"shape": "box_cluster", "count": 1},
])
def test_extreme_but_valid_procedural_parameters_build(mesh):
    m = parse_scene(scene_dict(meshes={"b": mesh})).meshes["b"]
    assert len(m.faces) > 0 and np.all(np.isfinite(m.vertices)) and np.all(np.isfinite(m.normals))
    assert np.allclose(np.linalg.norm(m.normals, axis=1), 1.0, atol=1e-5)


def test_the_holed_concave_and_several_part_shapes_are_what_they_say():
    """pipe: a watertight tube with a hole through it (Euler number 0); frame: four bars around an empty square;
    box_cluster: as many separate boxes as asked (the training shapes unlike the five convex ones)."""
    import trimesh

    from diviewer.scene.shapes import SHAPES

    pipe = SHAPES["pipe"][0](radius=0.35, inner_radius=0.25, height=0.6, sections=48)
    assert pipe.is_watertight and pipe.euler_number == 0
    frame = SHAPES["frame"][0](size=0.7, thickness=0.15, depth=0.2)
    inner = 0.35 - 0.15
    assert not np.any((np.abs(frame.vertices[:, 0]) < inner - 1e-9) & (np.abs(frame.vertices[:, 1]) < inner - 1e-9))
    assert np.allclose(frame.bounds, [[-0.35, -0.35, -0.1], [0.35, 0.35, 0.1]])
    cluster = SHAPES["box_cluster"][0](count=4, size=0.2)
    assert len(trimesh.graph.connected_components(cluster.face_adjacency, min_len=1)) == 4 and len(cluster.faces) == 4 * 12
    for mesh in ({"shape": "pipe"}, {"shape": "frame"}, {"shape": "box_cluster"}):
        m = parse_scene(scene_dict(meshes={"b": mesh})).meshes["b"]
        assert len(m.faces) > 0 and np.allclose(np.linalg.norm(m.normals, axis=1), 1.0, atol=1e-5)


@pytest.mark.parametrize("scale", [[1e-3] * 3, [1e4] * 3, [1e-3, 1e4, 1.0], [-1.0, 1.0, 1.0]])
def test_extreme_object_scales_load(scale):
    scene = parse_scene(scene_dict(objects=[{"name": "o", "mesh": "b", "material": "m", "scale": scale}]))
    assert scene.default.objects[0].scale == tuple(scale)


def test_zero_scale_is_refused():
    refused(scene_dict(objects=[{"name": "o", "mesh": "b", "material": "m", "scale": [1, 0, 1]}]), "objects[0].scale")


def test_empty_scene_is_refused():
    refused(scene_dict(objects=[]), "objects")


# --- mesh files --------------------------------------------------------------------------------
def _load_with_file(tmp_path, name, content):
    (tmp_path / name).write_bytes(content if isinstance(content, bytes) else content.encode())
    toml = f"""
[camera]
position = [0, 0, 5]
[materials.m]
albedo = [0.5, 0.5, 0.5]
[meshes.b]
file = "{name}"
[[objects]]
name = "o"
mesh = "b"
material = "m"
"""
    (tmp_path / "s.toml").write_text(toml)
    return load_scene(tmp_path / "s.toml")


TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"


@pytest.mark.parametrize("name,content", [
    ("empty.obj", b""),
    ("points.obj", TRI),
    ("garbage.obj", b"\x00\xff\x13binary nonsense\x00" * 20),
    ("degenerate.obj", TRI + "v 2 0 0\nf 1 2 4\n"),  # collinear: zero area
    ("nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n"),
    ("inf.obj", "v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n"),
    ("truncated.glb", b"glTF\x02\x00\x00\x00"),
    ("empty.ply", b"ply\nformat ascii 1.0\nend_header\n"),
])
def test_bad_mesh_files_are_refused(tmp_path, name, content):
    with pytest.raises(DiviewerError) as exc:
        _load_with_file(tmp_path, name, content)
    assert "meshes.b" in str(exc.value) and str(tmp_path / "s.toml") in str(exc.value)


@pytest.mark.parametrize("name,content", [
    ("dup.obj", TRI + "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 4 5 6\n"),  # duplicate vertices and faces
    ("flipped.obj", TRI + "f 1 3 2\n"),  # clockwise winding
    ("zero_normals.obj", TRI + "vn 0 0 0\nf 1//1 2//1 3//1\n"),  # zero-length normals in the file
    ("tiny.obj", "v 0 0 0\nv 1e-3 0 0\nv 0 1e-3 0\nf 1 2 3\n"),
    ("huge.obj", "v 0 0 0\nv 1e4 0 0\nv 0 1e4 0\nf 1 2 3\n"),
])
def test_odd_but_valid_mesh_files_load_with_unit_normals(tmp_path, name, content):
    mesh = _load_with_file(tmp_path, name, content).meshes["b"]
    assert len(mesh.faces) >= 1
    n = np.linalg.norm(mesh.normals, axis=1)
    assert np.all(np.isfinite(mesh.normals)) and np.allclose(n, 1.0, atol=1e-5)


# --- scene files themselves --------------------------------------------------------------------
@pytest.mark.parametrize("content", [b"", b"\xff\xfe\x00binary", b"[camera\nfov = 4", b"[camera]\nfov = 45\n" * 1])
def test_broken_scene_files_are_one_error(tmp_path, content):
    p = tmp_path / "s.toml"
    p.write_bytes(content)
    with pytest.raises(DiviewerError) as exc:
        load_scene(p)
    assert str(p) in str(exc.value)


def test_truncated_shipped_scene_is_one_error(tmp_path):
    from diviewer.scene.loader import resolve_scene_path

    text = resolve_scene_path("cornell").read_bytes()
    for cut in (len(text) // 3, len(text) // 2, len(text) - 5):
        p = tmp_path / f"cut{cut}.toml"
        p.write_bytes(text[:cut])
        with pytest.raises(DiviewerError):
            load_scene(p)


# --- property: any number in any numeric field loads or is one DiviewerError naming the field ----
NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64), st.integers(-10**40, 10**40),
                    st.sampled_from([0.0, -0.0, 1e-8, 1e8, 1e38, 1e39, 3.4028235e38, 3.5e38, -1e-300]))


@given(value=NUMBERS, field=st.sampled_from(["fov", "near", "far"]))
def test_any_camera_number_loads_or_names_its_field(value, field):
    data = scene_dict()
    data["camera"][field] = value
    try:
        scene = parse_scene(data)
    except DiviewerError as exc:
        assert "camera." in str(exc)
        return
    c = scene.default.camera
    assert 0 < c.fov < 180 and 0 < c.near < c.far and c.far / c.near <= MAX_FAR_NEAR


@given(value=NUMBERS, field=st.sampled_from(["irradiance", "color", "direction"]))
def test_any_light_number_loads_finite_in_float32(value, field):
    light = dict(SUN)
    light[field] = [value, 1.0, 1.0] if field in ("color", "direction") else value
    try:
        scene = parse_scene(scene_dict(lights=[light]))
    except DiviewerError as exc:
        assert f"lights[0].{field}" in str(exc)
        return
    l = scene.default.lights[0]
    assert np.all(np.isfinite(np.float32(np.multiply(l.color, l.irradiance))))
    assert math.isclose(float(np.linalg.norm(l.direction)), 1.0, rel_tol=1e-9)


@given(params=st.dictionaries(st.sampled_from(["radius", "subdivisions"]), NUMBERS, max_size=2))
def test_any_sphere_parameters_build_or_name_the_field(params):
    try:
        mesh = parse_scene(scene_dict(meshes={"b": {"shape": "sphere", **params}})).meshes["b"]
    except DiviewerError as exc:
        assert "meshes.b" in str(exc)
        return
    assert len(mesh.faces) <= 20 * 4 ** 7 and np.all(np.isfinite(mesh.vertices))
