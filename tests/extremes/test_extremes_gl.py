"""The GL renderer at the extremes: lights, camera, geometry and materials give finite, sensible buffers;
sizes beyond the context are refused up front; `render` never destroys an earlier render."""

from __future__ import annotations

import dataclasses
import errno
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from diviewer.errors import DiviewerError
from diviewer.gl.context import check_render_size, max_render_size
from diviewer.gl.renderer import BUFFERS, Renderer
from scenes import facing_plane

SUN = {"name": "sun", "type": "directional", "direction": [0.0, 0.0, -1.0], "irradiance": 1.0}
RES = 16


def frame(ctx, scene, config=None, size=(RES, RES)):
    r = Renderer(ctx, scene, *size)
    try:
        return r.frame(config or scene.default)
    finally:
        r.release()


def finite(f) -> bool:
    return all(np.all(np.isfinite(f[n])) for n in BUFFERS)


def with_light(scene, **changes):
    lights = tuple(dataclasses.replace(l, **changes) for l in scene.default.lights)
    return dataclasses.replace(scene.default, lights=lights)


@pytest.fixture(scope="module")
def lit_plane():
    return facing_plane(distance=3.0, albedo=(0.5, 0.5, 0.5), lights=[SUN])


# --- lights ------------------------------------------------------------------------------------
@pytest.mark.parametrize("irradiance", [0.0, 1e-8, 1.0, 1e8, 1e30])
def test_light_strengths_give_finite_buffers_linear_in_strength(ctx, lit_plane, irradiance):
    f = frame(ctx, lit_plane, with_light(lit_plane, irradiance=irradiance))
    assert finite(f)
    expected = 0.5 / math.pi * irradiance  # Lambert at normal incidence, albedo 0.5
    np.testing.assert_allclose(f["direct"], expected, rtol=1e-4, atol=1e-30)


def test_colour_channel_zero_stays_zero(ctx, lit_plane):
    f = frame(ctx, lit_plane, with_light(lit_plane, color=(0.0, 1.0, 2.0)))
    assert finite(f) and np.all(f["direct"][..., 0] == 0.0)
    np.testing.assert_allclose(f["direct"][..., 2], 2 * f["direct"][..., 1], rtol=1e-5)


@pytest.mark.parametrize("direction,lit", [
    ((0.0, 0.0, -1.0), True),           # head on
    ((1.0, 0.0, -1e-3), True),          # grazing: cos ~ 1e-3
    ((1.0, 0.0, 0.0), False),           # exactly in the plane
    ((0.3, 0.2, 1.0), False),           # below the horizon (from behind the wall)
])
def test_grazing_and_below_horizon_light(ctx, lit_plane, direction, lit):
    d = np.asarray(direction) / np.linalg.norm(direction)
    f = frame(ctx, lit_plane, with_light(lit_plane, direction=tuple(d)))
    assert finite(f) and np.all(f["direct"] >= 0)
    cos = max(-d[2], 0.0)
    # shadow-map bias can darken grazing light; it never brightens it past Lambert
    assert np.all(f["direct"] <= 0.5 / math.pi * cos * (1 + 1e-4) + 1e-12)
    assert (f["direct"].max() > 0) == lit


@given(base=st.floats(1e-6, 1e6), factor=st.floats(1.0, 1e3))
def test_brightness_is_monotone_in_intensity(ctx, lit_plane, base, factor):
    r = Renderer(ctx, lit_plane, 8, 8)
    try:
        a = r.frame(with_light(lit_plane, irradiance=base))["direct"]
        b = r.frame(with_light(lit_plane, irradiance=base * factor))["direct"]
    finally:
        r.release()
    assert np.all(np.isfinite(b)) and np.all(b >= a * (1 - 1e-6))


def test_point_light_touching_the_wall_stays_finite_or_is_refused_by_render(ctx):
    scene = facing_plane(distance=3.0, lights=[{"name": "p", "type": "point", "position": [0, 0, -2.99],
                                                 "intensity": 1.0}])
    f = frame(ctx, scene)
    assert finite(f) and f["direct"].max() > 0


# --- camera ------------------------------------------------------------------------------------
@pytest.mark.parametrize("size", [(1, 1), (1, 7), (7, 1), (13, 5), (17, 16), (33, 31), (3, 64)])
def test_odd_and_tiny_sizes(ctx, lit_plane, size):
    f = frame(ctx, lit_plane, size=size)
    assert finite(f) and f["direct"].shape == (size[1], size[0], 3)
    covered = f["depth"] > 0  # wide images see past the plane's sides (it is fitted to the vertical fov)
    assert covered[size[1] // 2, size[0] // 2]
    np.testing.assert_allclose(f["depth"][covered], 3.0, rtol=1e-4)


@pytest.mark.parametrize("fov", [1.0, 179.0])
def test_extreme_fov(ctx, fov):
    scene = facing_plane(distance=3.0, fov=fov, lights=[SUN])
    f = frame(ctx, scene)
    assert finite(f)
    # a plane facing the camera at distance 3 has view depth 3 everywhere, whatever the fov
    covered = f["depth"] > 0
    assert covered.mean() > 0.5 and np.allclose(f["depth"][covered], 3.0, rtol=1e-3)


@pytest.mark.parametrize("near,far,distance", [(1e-4, 10.0, 9.0), (1e-4, 10.0, 1e-3), (1.0, 1e5, 9e4)])
def test_largest_allowed_far_near_ratio_renders_correct_depth(ctx, near, far, distance):
    """The counterpart of the loader's refusal: at far/near = 1e5 the whole range still renders."""
    scene = facing_plane(distance=distance, near=near, far=far, lights=[SUN])
    f = frame(ctx, scene)
    assert finite(f)
    np.testing.assert_allclose(f["depth"], distance, rtol=1e-3)


def test_camera_touching_a_wall(ctx):
    scene = facing_plane(distance=0.1, near=0.1, far=10.0, lights=[SUN])  # the wall on the near plane
    f = frame(ctx, scene)
    assert finite(f) and np.all(f["direct"] >= 0)
    # The near plane clips the wall's face (or keeps it, by rounding); behind it is the wall's back face.
    d = f["depth"]
    assert np.all(np.isclose(d, 0.1, rtol=1e-3) | np.isclose(d, 0.6, rtol=1e-3))


def test_camera_inside_an_object(ctx):
    box = {"name": "cage", "mesh": "cage", "material": "occ", "position": [0, 0, 0]}
    scene = facing_plane(distance=3.0, lights=[SUN], extra_objects=[box],
                         extra_meshes={"cage": {"shape": "box", "size": [1.0, 1.0, 1.0]}})
    f = frame(ctx, scene)
    assert finite(f) and np.all(f["direct"] >= 0)


# --- geometry ----------------------------------------------------------------------------------
@pytest.mark.parametrize("scale", [1e-3, 1e4])
def test_extreme_object_scales_render_finite(ctx, scale):
    obj = {"name": "s", "mesh": "ball", "material": "occ", "position": [0, 0, -1.5], "scale": [scale] * 3}
    scene = facing_plane(distance=3.0, lights=[SUN], extra_objects=[obj],
                         extra_meshes={"ball": {"shape": "sphere", "subdivisions": 2, "radius": 0.2}})
    assert finite(frame(ctx, scene))


def test_nothing_in_view_is_background(ctx):
    scene = facing_plane(distance=3.0, lights=[SUN])
    cam = dataclasses.replace(scene.default.camera, target=(0.0, 0.0, 1.0))  # looking away from the wall
    f = frame(ctx, scene, dataclasses.replace(scene.default, camera=cam))
    assert finite(f) and np.all(f["depth"] == 0) and np.all(f["direct"] == 0)


# --- materials ---------------------------------------------------------------------------------
@pytest.mark.parametrize("albedo", [0.0, 1.0])
def test_albedo_extremes(ctx, albedo):
    scene = facing_plane(distance=3.0, albedo=(albedo,) * 3, lights=[SUN])
    f = frame(ctx, scene)
    assert finite(f)
    np.testing.assert_allclose(f["direct"], albedo / math.pi, rtol=1e-4, atol=1e-12)


def test_emission_only(ctx):
    from scenes import facing_plane as fp

    scene = fp(distance=3.0, lights=[])
    mats = dict(scene.materials)
    mats["m"] = dataclasses.replace(mats["m"], emission=(2.0, 0.0, 0.5))
    scene = dataclasses.replace(scene, materials=mats)
    f = frame(ctx, scene)
    assert finite(f)
    np.testing.assert_allclose(f["direct"], np.broadcast_to([2.0, 0.0, 0.5], f["direct"].shape), rtol=1e-5)


# --- sizes from the GL context (issue case 9) ---------------------------------------------------
def test_render_size_limits_come_from_the_context(ctx):
    mw, mh = max_render_size(ctx)
    assert mw == min(ctx.info["GL_MAX_TEXTURE_SIZE"], ctx.info["GL_MAX_RENDERBUFFER_SIZE"])
    with pytest.raises(DiviewerError, match="--size"):
        check_render_size(ctx, mw + 1, 8, "--size")
    with pytest.raises(DiviewerError, match="--res"):
        check_render_size(ctx, 8, mh + 1)
    check_render_size(ctx, 1, 1)
    check_render_size(ctx, 64, 48)


@pytest.mark.slow
def test_a_size_within_limits_the_driver_cannot_allocate_is_refused_up_front(ctx):
    mw, mh = max_render_size(ctx)
    try:
        check_render_size(ctx, mw, mh)  # RGBA32F at the maximum: 4 GiB at 16384, beyond most drivers
    except DiviewerError as exc:
        assert "--res" in str(exc) and "too large" in str(exc)
    assert ctx.error == "GL_NO_ERROR"


# --- `diviewer render`: nothing written on failure, an earlier render intact (issue case 4) ------
SCENE_TOML = """
[camera]
position = [0, 0, 0]
target = [0, 0, -1]
near = 0.1
far = 20
[materials.m]
albedo = [0.5, 0.5, 0.5]
[meshes.wall]
shape = "box"
size = [10, 10, 0.5]
[[objects]]
name = "wall"
mesh = "wall"
material = "m"
position = [0, 0, -3.25]
[[lights]]
name = "p"
type = "point"
position = [0, 0, {z}]
intensity = {intensity}
"""


def _snapshot(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_render_overflow_leaves_the_earlier_render_intact(tmp_path, capsys):
    from diviewer.cli import main

    good, bad, out = tmp_path / "good.toml", tmp_path / "bad.toml", tmp_path / "out"
    good.write_text(SCENE_TOML.format(z=-1.0, intensity=1.0))
    # within float32 as a number, but intensity / r^2 at r = 0.01 overflows in the shader
    bad.write_text(SCENE_TOML.format(z=-2.99, intensity=3e38))
    assert main(["render", "--scene", str(good), "--res", "16", "--out", str(out)]) == 0
    before = _snapshot(out)
    capsys.readouterr()
    assert main(["render", "--scene", str(bad), "--res", "16", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "lights[0].intensity" in err and str(bad) in err and "Traceback" not in err
    assert _snapshot(out) == before


def test_render_of_1e39_is_refused_before_anything_is_written(tmp_path, capsys):
    from diviewer.cli import main

    bad, out = tmp_path / "bad.toml", tmp_path / "out"
    bad.write_text(SCENE_TOML.format(z=-1.0, intensity=1e39))
    assert main(["render", "--scene", str(bad), "--res", "16", "--out", str(out)]) == 2
    assert "lights[0].intensity" in capsys.readouterr().err
    assert not out.exists()


def test_disk_full_during_render_leaves_the_earlier_render_intact(tmp_path, capsys, monkeypatch):
    from diviewer import imageio
    from diviewer.cli import main

    scene, out = tmp_path / "s.toml", tmp_path / "out"
    scene.write_text(SCENE_TOML.format(z=-1.0, intensity=1.0))
    assert main(["render", "--scene", str(scene), "--res", "16", "--out", str(out)]) == 0
    before = _snapshot(out)
    scene.write_text(SCENE_TOML.format(z=-1.0, intensity=2.0))
    real, calls = imageio.write_png, []

    def full_disk(path, image):
        calls.append(path)
        if len(calls) == 3:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        real(path, image)

    monkeypatch.setattr(imageio, "write_png", full_disk)
    capsys.readouterr()
    assert main(["render", "--scene", str(scene), "--res", "16", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "No space left on device" in err and err.count("\n") == 1
    assert _snapshot(out) == before  # no new file, no temporary left behind, the old ones unchanged
