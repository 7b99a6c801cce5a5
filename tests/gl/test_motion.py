"""Motion vectors (gl/motion.py) on a headless EGL context: the velocity target against the reprojection computed
here from the depth, the camera and the objects' poses (tests/gl/test_temporal.py resolves a moving object with
them)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from diviewer.gl.renderer import Renderer, RenderSettings
from diviewer.gl.temporal import jitter_offset
from diviewer.scene import camera as cam
from diviewer.scene import load_scene

SIZE = 48
TOL_PX = 0.02
"""Velocity tolerance in pixels: the target holds half floats (11 significant bits of offsets below 1)."""


@pytest.fixture(scope="module")
def cornell():
    return load_scene("cornell")


def _read(tex, comps: int | None = None) -> np.ndarray:
    """A texture as float32 (H, W, C), rows bottom first (GL's)."""
    dtype = np.float16 if tex.dtype == "f2" else np.float32
    a = np.frombuffer(tex.read(), dtype).reshape(tex.height, tex.width, tex.components).astype(np.float32)
    return a[..., :comps] if comps else a


def _expected(r: Renderer, prev_view, prev_proj, to_previous=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """From the last frame's depth: each pixel's (unjittered) texture coordinates now and in the previous frame,
    and its depth change; ``to_previous(world) -> world`` moves a point back to where it was (None: nowhere)."""
    fv, (w, h), (jx, jy) = r.frame_view, (r.width, r.height), r.jitter
    z = _read(r.textures["depth"])[..., 0]
    ys, xs = np.mgrid[0:h, 0:w]
    uv = np.stack([(xs + 0.5 - jx) / w, (ys + 0.5 - jy) / h], axis=-1)
    ndc = uv * 2.0 - 1.0
    pv = np.stack([ndc[..., 0] / fv.proj[0, 0] * z, ndc[..., 1] / fv.proj[1, 1] * z, -z, np.ones_like(z)], -1)
    world = pv @ np.linalg.inv(fv.view).T
    if to_previous is not None:
        world = to_previous(world)
    q = world @ prev_view.T
    clip = q @ prev_proj.T
    prev_uv = clip[..., :2] / clip[..., 3:] * 0.5 + 0.5
    return prev_uv - uv, -q[..., 2] - z, z > 0.0


def _frames(ctx, scene, configs, size=SIZE):
    """Render ``configs`` in turn with motion vectors on and a new jitter each; yields the renderer after each."""
    r = Renderer(ctx, scene, size, size, RenderSettings(shadow_size=256))
    r.motion_vectors = True
    try:
        for k, config in enumerate(configs):
            r.jitter = jitter_offset(k, 8)
            r.render(config)
            yield r
    finally:
        r.release()


def test_a_static_scene_under_a_still_camera_has_no_motion(ctx, cornell):
    config = cornell.default
    for k, r in enumerate(_frames(ctx, cornell, [config] * 3)):
        vel = _read(r.velocity)
        covered = _read(r.textures["depth"])[..., 0] > 0.0
        np.testing.assert_array_equal(vel[..., 3], covered.astype(np.float32))
        assert np.abs(vel[..., :3]).max() == 0.0, k


def test_under_a_moving_camera_the_velocity_is_the_camera_reprojection(ctx, cornell):
    a = cornell.default
    cams = [a.camera, dataclasses.replace(a.camera, position=(0.25, 1.2, 3.0), target=(0.1, 0.9, 0.0))]
    configs = [dataclasses.replace(a, camera=c) for c in cams]
    prev = None
    for r in _frames(ctx, cornell, configs):
        if prev is not None:
            vel = _read(r.velocity)
            move, change, covered = _expected(r, *prev)
            assert covered.mean() > 0.9
            err = np.abs(vel[..., :2] - move)[covered] * SIZE
            assert err.max() < TOL_PX, err.max()
            assert np.abs(move[covered]).max() * SIZE > 2.0  # the camera moved by pixels, not by round-off
            np.testing.assert_allclose(vel[..., 2][covered], change[covered], atol=2e-3)
        prev = (r.frame_view.view, r.frame_view.proj)


def _object_moved(ctx, cornell, a, b):
    """Frames of configurations ``a`` then ``b``: the renderer after ``b``, ``a``'s view and projection, ``b``'s
    velocity, the pixels of the centre object (by its albedo), its model matrix's change (world to world), and the
    frames (close them when done with the renderer)."""
    before, after = (next(o for o in c.objects if o.name == "center").matrix() for c in (a, b))
    frames = _frames(ctx, cornell, [a, b])
    r = next(frames)
    prev = (r.frame_view.view, r.frame_view.proj)
    r = next(frames)
    vel = _read(r.velocity)
    albedo = _read(r.textures["albedo"], 3)
    on_object = np.all(np.abs(albedo - cornell.materials["object"].albedo) < 1e-6, axis=-1)
    return r, prev, vel, on_object, before @ np.linalg.inv(after), frames


@pytest.mark.parametrize("change", [{"position": (0.15, 0.8, 0.1)}, {"rotation": (20.0, 50.0, 10.0)},
                                    {"scale": (1.2, 1.0, 0.9)}])
def test_a_moving_object_s_pixels_move_by_its_screen_space_motion(ctx, cornell, change):
    """Under a still camera the object's pixels (found by its albedo) carry its motion, projected from its two
    poses; every other pixel none."""
    a = cornell.default
    b = a.replace_object("center", **change)
    r, prev, vel, on_object, change_of_pose, frames = _object_moved(ctx, cornell, a, b)
    move, depth_change, covered = _expected(r, *prev, lambda w: w @ change_of_pose.T)
    assert on_object.sum() > 50
    err = np.abs(vel[..., :2] - move)[on_object] * SIZE
    assert err.max() < TOL_PX, err.max()
    assert np.abs(move[on_object]).max() * SIZE > 1.0
    np.testing.assert_allclose(vel[..., 2][on_object], depth_change[on_object], atol=2e-3)
    assert np.abs(vel[..., :3][covered & ~on_object]).max() == 0.0
    frames.close()


_offset = st.tuples(*[st.floats(-0.25, 0.25)] * 3)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(move=_offset, turn=st.tuples(*[st.floats(0.0, 360.0)] * 3), scale=st.floats(0.7, 1.3), eye=_offset)
def test_any_pose_change_under_any_camera_move_is_reprojected(ctx, cornell, move, turn, scale, eye):
    """The object moved, turned and scaled while the camera moved: each pixel's velocity and change of depth are
    its surface point's, the object's pixels by both motions, the rest by the camera's alone."""
    a = cornell.default
    b = dataclasses.replace(a.replace_object("center", position=tuple(np.add((0.0, 0.75, 0.0), move)),
                                             rotation=turn, scale=(scale,) * 3),
                            camera=dataclasses.replace(a.camera, position=tuple(np.add(a.camera.position, eye))))
    r, prev, vel, on_object, change_of_pose, frames = _object_moved(ctx, cornell, a, b)
    still, still_change, covered = _expected(r, *prev)
    moved, moved_change, _ = _expected(r, *prev, lambda w: w @ change_of_pose.T)
    want = np.where(on_object[..., None], moved, still)
    change = np.where(on_object, moved_change, still_change)
    assert covered.mean() > 0.8
    err = np.abs(vel[..., :2] - want)[covered] * SIZE
    assert err.max() < TOL_PX + 1e-3 * np.abs(want[covered]).max() * SIZE, err.max()  # half floats: relative
    np.testing.assert_allclose(vel[..., 2][covered], change[covered], atol=2e-3, rtol=2e-3)
    frames.close()


def test_an_object_new_since_the_last_frame_has_no_motion(ctx, cornell):
    a = cornell.default
    without = dataclasses.replace(a, objects=tuple(o for o in a.objects if o.name != "center"))
    moved = a.replace_object("center", position=(0.3, 0.75, 0.0))
    for k, r in enumerate(_frames(ctx, cornell, [without, moved])):
        if k == 1:
            vel = _read(r.velocity)
            assert np.abs(vel[..., :3]).max() == 0.0


@pytest.mark.parametrize("emissive", [False, True])
def test_frames_without_temporal_upsampling_are_drawn_as_before(ctx, cornell, emissive):
    """Motion vectors change no other buffer, with or without an emitting material (the emission target, left out
    of the G-buffer pass without one), and, turned off, leave no velocity target to read."""
    scene = cornell
    if emissive:
        glow = dataclasses.replace(cornell.materials["object"], emission=(1.0, 0.5, 0.25))
        scene = dataclasses.replace(cornell, materials={**cornell.materials, "object": glow})
    a = scene.default
    b = a.replace_object("center", position=(0.2, 0.7, 0.0))
    r = Renderer(ctx, scene, SIZE, SIZE, RenderSettings(shadow_size=256))

    def buffers(config):
        r.render(config)
        return {name: r.read(name) for name in ("depth", "normal", "albedo", "emission", "direct")}
    try:
        plain = buffers(b)
        assert r.velocity is None
        r.motion_vectors = True
        r.render(a)
        with_mv = buffers(b)
        moving = np.abs(_read(r.velocity)[..., :2]).max() * SIZE
        r.motion_vectors = False
        again = buffers(b)
        assert r.velocity is None
        assert moving > 1.0  # the object moved by pixels between a and b
        assert (np.abs(plain["emission"]).max() > 0.0) == emissive
        for name in plain:
            np.testing.assert_array_equal(with_mv[name], plain[name], err_msg=name)
            np.testing.assert_array_equal(again[name], plain[name], err_msg=name)
    finally:
        r.release()
