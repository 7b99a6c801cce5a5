"""Camera paths: interpolation through the keys (C1 positions), the scene's own walk in the same form, the file
format read back exactly, thinning a recording, and every bad file refused with its file and field named."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diviewer.errors import DiviewerError
from diviewer.scene import load_scene
from diviewer.scene.camera_path import (
    FORMAT, CameraPath, PathKey, frame_times, read_path, scene_camera_path, slerp_rotation, slerp_vector,
    thin_keys, write_path,
)
from diviewer.scene.model import Camera
from diviewer.scene.sampler import camera_on_path


@pytest.fixture(scope="module")
def cornell():
    return load_scene("cornell")


@pytest.fixture(scope="module")
def atrium():
    return load_scene("atrium")


def _path(times, seed=0, closed=False, scene="s", scene_hash="h"):
    rng = np.random.default_rng(seed)
    keys = []
    for t in times:
        p = rng.uniform(-5, 5, 3)
        keys.append(PathKey(float(t), Camera(position=tuple(p), target=tuple(p + rng.uniform(-1, 1, 3) + [0, 0, -3]),
                                              up=tuple(cam_up(rng)), fov=float(rng.uniform(30, 60)))))
    return CameraPath(tuple(keys), scene, scene_hash, closed)


def cam_up(rng):
    v = np.array([0.0, 1.0, 0.0]) + rng.uniform(-0.2, 0.2, 3)
    return v / np.linalg.norm(v)


@settings(max_examples=30, deadline=None)
@given(gaps=st.lists(st.floats(0.05, 3.0), min_size=1, max_size=7), seed=st.integers(0, 1000))
def test_interpolation_passes_through_the_keys_and_is_c1(gaps, seed):
    path = _path(np.concatenate([[0.0], np.cumsum(gaps)]), seed)
    for k in path.keys:
        assert path.camera_at(k.time) == k.camera  # exactly the key
    eps = 1e-4 * min(gaps)

    def slope(field, t, h):  # one-sided difference quotient, Richardson-extrapolated (error O(h^2))
        def d(h):
            return np.subtract(getattr(path.camera_at(t + h), field), getattr(path.camera_at(t), field)) / h
        return 2 * d(h / 2) - d(h)

    for k in path.keys[1:-1]:  # at interior keys, one tangent from both sides (C1 in time)
        for field in ("position", "target"):
            left, right = slope(field, k.time, -eps), slope(field, k.time, eps)
            assert np.allclose(left, right, rtol=1e-5, atol=1e-5 * (1 + np.abs(left).max())), (field, left, right)
    # continuous: halving the step halves the largest change between samples
    def largest_step(n):
        ts = np.linspace(path.start, path.end, n)
        pos = np.array([path.camera_at(t).position for t in ts])
        return np.max(np.linalg.norm(np.diff(pos, axis=0), axis=1)) if n > 1 else 0.0

    if path.duration > 0:
        assert largest_step(2001) <= 0.55 * largest_step(1001)
    ts = np.linspace(path.start, path.end, 50)
    ups = np.array([path.camera_at(t).up for t in ts])
    assert np.allclose(np.linalg.norm(ups, axis=1), 1.0)


def test_slerp_of_directions_and_rotations():
    a, b = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    mid = slerp_vector(a, b, 0.5)
    np.testing.assert_allclose(mid, [math.sqrt(0.5), math.sqrt(0.5), 0.0], atol=1e-12)
    assert slerp_vector(a, a, 0.3) == a
    np.testing.assert_allclose(slerp_rotation((0, 0, 0), (0, 90, 0), 0.5), (0, 45, 0), atol=1e-9)
    np.testing.assert_allclose(slerp_rotation((10, 20, 30), (40, -20, 5), 0.0), (10, 20, 30), atol=1e-9)
    np.testing.assert_allclose(slerp_rotation((10, 20, 30), (40, -20, 5), 1.0), (40, -20, 5), atol=1e-9)
    # the short arc: 350 degrees to 10 degrees passes through 0, not 180
    np.testing.assert_allclose(slerp_rotation((0, 0, 350), (0, 0, 10), 0.5), (0, 0, 0), atol=1e-9)


@pytest.mark.parametrize("closed", [False, True])
def test_the_scene_walk_is_the_samplers_path(atrium, closed):
    walk = dataclasses.replace(atrium.ranges.camera, closed=closed)
    atrium = dataclasses.replace(atrium, ranges=dataclasses.replace(atrium.ranges, camera=walk))
    path = scene_camera_path(atrium)
    assert path is not None and path.scene_hash == atrium.file_hash and path.closed == closed
    for s in np.linspace(0.0, 1.0, 37):
        got = path.camera_at(path.start + s * path.duration)
        want = camera_on_path(atrium, float(s))
        np.testing.assert_allclose(got.position, want.position, atol=1e-9)
        np.testing.assert_allclose(got.target, want.target, atol=1e-9)
        assert got.up == want.up and got.fov == want.fov


def test_no_walk_no_path(cornell):
    assert scene_camera_path(cornell) is None


def test_wrap_loops_closed_paths_and_bounces_open_ones():
    open_path = _path([0.0, 1.0, 2.0])
    assert open_path.wrap(1.5) == 1.5 and open_path.wrap(2.5) == pytest.approx(1.5) and open_path.wrap(4.5) == pytest.approx(0.5)
    closed = dataclasses.replace(open_path, closed=True)
    assert closed.wrap(2.5) == pytest.approx(0.5)


def test_frame_times():
    path = _path([0.0, 1.0, 2.0])
    assert frame_times(path, frames=5) == [0.0, 0.5, 1.0, 1.5, 2.0]
    assert len(frame_times(path, fps=10)) == 21 and frame_times(path, fps=10)[-1] == pytest.approx(2.0)
    assert frame_times(path, frames=1) == [0.0]


def _file_path(scene, n=4):
    keys = []
    for i in range(n):
        c = dataclasses.replace(scene.default.camera, position=tuple(np.add(scene.default.camera.position, [0.1 * i, 0, 0])))
        lights = tuple(dataclasses.replace(l, color=(1.0, 1.0 - 0.1 * (i >= 2), 1.0)) for l in scene.default.lights)
        keys.append(PathKey(0.25 * i, c, lights, scene.default.objects))
    return CameraPath(tuple(keys), scene.name, scene.file_hash)


def test_the_file_reads_back_exactly_and_writes_tracks_only_where_they_change(cornell, tmp_path):
    path = _file_path(cornell)
    write_path(tmp_path / "p.json", path)
    data = json.loads((tmp_path / "p.json").read_text())
    assert data["format"] == FORMAT and data["version"] == 1 and data["scene_hash"] == cornell.file_hash
    assert ["lights" in k for k in data["keys"]] == [True, False, True, False]
    assert ["objects" in k for k in data["keys"]] == [True, False, False, False]
    back, _ = read_path(tmp_path / "p.json", cornell)
    assert back.keys == path.keys
    for t in (0.1, 0.3, 0.6):
        assert back.config_at(t, cornell.default) == path.config_at(t, cornell.default)
    # a path without lights or objects leaves the frame's own
    bare = CameraPath(tuple(dataclasses.replace(k, lights=None, objects=None) for k in path.keys), "c", "h")
    assert bare.config_at(0.3, cornell.default).lights == cornell.default.lights


def test_thinning_keeps_what_the_motion_needs():
    times = np.arange(120) / 60.0
    keys = [PathKey(float(t), Camera(position=(math.sin(t), 0.0, math.cos(t) + 3.0), target=(0.0, 0.0, 0.0)))
            for t in times]
    thin = thin_keys(keys, scale=4.0)
    assert 12 <= len(thin) < 120 and thin[0] == keys[0] and thin[-1] == keys[-1]
    path = CameraPath(tuple(thin), "s", "h")
    for k in keys:
        assert np.max(np.abs(np.subtract(path.camera_at(k.time).position, k.camera.position))) < 4e-3
    assert thin_keys(keys, scale=4.0, tolerance=None) == keys


# --- bad files: one error naming the file and the field ------------------------------------------------------------

def _bad(cornell, tmp_path, change):
    data = _file_path(cornell).to_dict()
    change(data)
    f = tmp_path / "bad.json"
    f.write_text(json.dumps(data))
    with pytest.raises(DiviewerError) as info:
        read_path(f, cornell)
    return info.value


@pytest.mark.parametrize("change, field", [
    (lambda d: d.update(version=2), "version"),
    (lambda d: d.update(format="something"), "format"),
    (lambda d: d.update(scene_hash="0" * 64), "scene_hash"),
    (lambda d: d.update(keys=[]), "keys"),
    (lambda d: d["keys"][1].update(time=0.0), "keys[1].time"),
    (lambda d: d["keys"][2].update(time=float("nan")), "keys[2].time"),
    (lambda d: d["keys"][1]["camera"].update(position=[0.0, float("nan"), 1.0]), "keys[1].camera.position"),
    (lambda d: d["keys"][0]["lights"][0].update(irradiance=float("inf")), "keys[0].lights[0].irradiance"),
    (lambda d: d["keys"][1].pop("camera"), "keys[1].camera"),
    (lambda d: d["keys"][0]["objects"][0].update(mesh="nope"), "keys[0].objects[0].mesh"),
])
def test_bad_files_are_refused_naming_file_and_field(cornell, tmp_path, change, field):
    err = _bad(cornell, tmp_path, change)
    assert err.field == field and str(err.path).endswith("bad.json")
    assert str(err).startswith(f"{err.path}: {field}: ")


def test_a_path_of_another_scene_is_refused(cornell, atrium, tmp_path):
    write_path(tmp_path / "a.json", scene_camera_path(atrium))
    with pytest.raises(DiviewerError, match="recorded in scene 'atrium'") as info:
        read_path(tmp_path / "a.json", cornell)
    assert info.value.field == "scene_hash"
