"""The interactive viewer: state actions and camera math without pixels, then scripted window sessions.

The window tests need a display: an existing DISPLAY, or Xvfb started here for the session. Without
either they skip, unless DIVIEWER_REQUIRE_GL=1 (CI), where they fail.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.scene import load_scene
from diviewer.scene.model import Camera
from diviewer.scene.lights import angles_to_vector, vector_to_angles
from diviewer.scene.picking import pixel_ray
from diviewer.viewer.controls import FlyController, OrbitController, direction, yaw_pitch
from diviewer.viewer.state import ViewerState
from diviewer.viewer.stats import Stats
from diviewer.viewer.view_modes import VIEW_MODE_NAMES, VIEW_MODES, produce, single_modes, view_mode

REQUIRE_GL = os.environ.get("DIVIEWER_REQUIRE_GL", "") not in ("", "0")


@pytest.fixture(scope="module")
def cornell():
    return load_scene("cornell")


@pytest.fixture
def state(cornell):
    return ViewerState(cornell)


# --- view modes -----------------------------------------------------------------------------------

def test_view_mode_registry_is_complete():
    from diviewer.gl.display import KINDS, LAYOUTS

    expected = {"final", "direct", "reference", "vxgi", "depth", "normal", "albedo", "net_input", "net_output",
                "split", "difference"}
    assert expected <= set(VIEW_MODE_NAMES)
    assert len(set(VIEW_MODE_NAMES)) == len(VIEW_MODES)
    keys = [m.key for m in VIEW_MODES if m.key]
    assert len(keys) == len(set(keys))
    for m in VIEW_MODES:
        assert m.layout in LAYOUTS and m.label
        if m.layout == "single":
            assert callable(m.produce) and m.display in KINDS
        else:
            assert m.produce is None
    assert {m.name for m in single_modes()} == expected - {"split", "difference"}
    with pytest.raises(DiviewerError, match="unknown view mode"):
        view_mode("vxgi-not-yet")


def test_view_mode_produces_from_its_sources():
    class Sources:
        has_model = False

        def buffer(self, name):
            return ("buffer", name)

        def network_output(self):
            return ("net",)

        def final(self):
            return ("final",)

        def reference(self):
            return ("ref",)

        def vxgi(self):
            return ("vxgi",)

    s = Sources()
    assert view_mode("final").produce(s) == ("buffer", "direct")  # no model: direct light only
    s.has_model = True
    assert view_mode("final").produce(s) == ("final",)  # full resolution, the network's GI upsampled into it
    assert view_mode("depth").produce(s) == ("buffer", "depth")
    assert view_mode("reference").produce(s) == ("ref",)
    assert view_mode("net_output").produce(s) == ("net",)
    assert view_mode("vxgi").produce(s) == ("vxgi",)
    # What the app calls: a single-image mode's image; the two-image layouts are drawn from their modes A and B.
    assert produce(view_mode("normal"), s) == ("buffer", "normal") and produce(view_mode("final"), s) == ("final",)
    with pytest.raises(DiviewerError, match="combines two modes"):
        produce(view_mode("split"), s)


def test_set_view_mode_and_compare(state):
    state.set_view_mode("split", a="direct", b="normal")
    assert state.view_mode == "split" and state.compare == ("direct", "normal")
    assert [m.name for m in state.modes_shown()] == ["direct", "normal"]
    state.set_view_mode("depth")
    assert [m.name for m in state.modes_shown()] == ["depth"]
    with pytest.raises(DiviewerError, match="single-image"):
        state.set_compare("split", "final")
    with pytest.raises(DiviewerError):
        state.set_tonemap("filmic")
    state.set_tonemap("reinhard")
    assert state.tonemap == "reinhard"


# --- lights ---------------------------------------------------------------------------------------

def test_light_direction_from_azimuth_and_elevation(state):
    state.set_light_direction(0.0, 90.0)
    np.testing.assert_allclose(state.light().direction, (0.0, -1.0, 0.0), atol=1e-12)  # sun overhead
    state.set_light_direction(90.0, 0.0)
    np.testing.assert_allclose(state.light().direction, (-1.0, 0.0, 0.0), atol=1e-12)  # from +x, travels -x
    state.set_light_direction(-30.0, 45.0)
    az, el = state.light_angles()
    assert az == pytest.approx(-30.0) and el == pytest.approx(45.0)
    for az, el in ((10.0, 20.0), (170.0, -60.0), (-120.0, 5.0)):
        assert vector_to_angles(angles_to_vector(az, el)) == pytest.approx((az, el))


def test_light_intensity_is_a_log_scale_and_colour_is_set(state, cornell):
    base = cornell.default.lights[0].irradiance
    old = state.config
    state.set_light_intensity(1.0)
    assert state.light().irradiance == pytest.approx(2 * base)
    state.set_light_intensity(-2.0)
    assert state.light().irradiance == pytest.approx(base / 4)
    assert state.light_intensity_ev() == pytest.approx(-2.0)
    assert old.lights[0].irradiance == base  # configs are replaced, never changed
    state.set_light_color((0.2, 0.4, 1.0))
    assert state.light().color == (0.2, 0.4, 1.0)
    with pytest.raises(DiviewerError):
        state.set_light_color((-1.0, 0.0, 0.0))


def test_animation_step_turns_the_light_within_its_range(state, cornell):
    d0 = np.array(cornell.default.lights[0].direction)
    assert state.step(0.5).lights[0].direction == tuple(d0)  # off: nothing moves
    assert state.toggle_animation()
    seen = []
    for _ in range(20):
        d = np.array(state.step(0.5).lights[0].direction)
        seen.append(math.degrees(math.acos(np.clip(d @ d0, -1, 1))))
        assert d[1] == pytest.approx(d0[1])  # about the y axis
    assert max(seen) > 5.0 and max(seen) <= 40.0 + 1e-6  # cornell's range: -40..40 degrees
    state.set_light_direction(0.0, 30.0)  # a manual change stops the animation
    assert not state.animate_light


def test_animation_moves_a_point_light_within_its_position_box(tmp_path):
    from room_doc import write_room

    room = load_scene(write_room(tmp_path, "\n[ranges.lights.lamp]\nposition = [[-1.5, 2.0, -1.5], [1.5, 2.8, 1.5]]\n"))
    st = ViewerState(room)
    assert st.toggle_animation()
    p = np.array([st.step(0.25).lights[0].position for _ in range(40)])
    assert np.all(p >= (-1.5, 2.0, -1.5)) and np.all(p <= (1.5, 2.8, 1.5))  # never through the walls
    assert np.all(np.ptp(p, axis=0) > 0.3)


def test_camera_path_plays(state):
    atrium = ViewerState(load_scene("atrium"))
    assert atrium.toggle_path()
    c0 = atrium.step(3.0).camera  # the first frame played shows where the path stands
    c1 = atrium.step(3.0).camera
    assert not np.allclose(c0.position, c1.position)
    assert not state.toggle_path()  # cornell has no camera path


# --- objects --------------------------------------------------------------------------------------

def test_object_actions(state, cornell):
    old = state.config
    state.move_object("center", (0.1, 0.8, -0.2))
    state.rotate_object("center", (10.0, 20.0, 30.0))
    state.scale_object("center", 1.5)
    state.swap_mesh("center", "sphere")
    o = state.object("center")
    assert o.position == (0.1, 0.8, -0.2) and o.rotation == (10.0, 20.0, 30.0)
    assert o.scale == (1.5, 1.5, 1.5) and o.mesh == "sphere"
    state.translate_object("center", (0.0, 0.1, 0.0))
    assert state.object("center").position == pytest.approx((0.1, 0.9, -0.2))
    state.scale_object("center", (1.0, 2.0, 0.5))
    assert state.object("center").scale == (1.0, 2.0, 0.5)
    assert old.objects == cornell.default.objects  # the old configuration is untouched
    with pytest.raises(DiviewerError, match="no mesh"):
        state.swap_mesh("center", "teapot")
    with pytest.raises(DiviewerError, match="non-zero"):
        state.scale_object("center", 0.0)
    state.reset_object("center")
    assert state.object("center") == [o for o in cornell.default.objects if o.name == "center"][0]


def test_load_mesh_file_adds_it_to_the_scene(state, tmp_path):
    import trimesh

    path = tmp_path / "wedge.obj"
    trimesh.creation.cone(radius=0.3, height=0.5, sections=12).export(path)
    key = state.load_mesh(path, "center")
    assert key == "file:wedge" and key in state.scene.meshes and state.scene_revision == 1
    assert state.object("center").mesh == key and state.user_meshes[key] == str(path)
    assert state.base_scene.meshes.keys() != state.scene.meshes.keys()
    with pytest.raises(DiviewerError, match="not found"):
        state.load_mesh(tmp_path / "missing.obj", "center")


def test_picking_selects_the_object_under_the_cursor(state):
    w, h = 128, 128
    assert state.pick(w / 2, h / 2 + 10, w, h) == "center"
    assert state.selected == "center"
    assert state.pick(3, h / 2, w, h) == "left"
    assert state.pick(w / 2, 2, w, h) == "ceiling"
    state.set_camera(Camera(position=(0.0, 1.0, 6.0), target=(0.0, 1.0, 10.0)))  # facing away from the box
    assert state.pick(w / 2, h / 2, w, h) is None and state.selected is None


# --- camera controllers ---------------------------------------------------------------------------

def test_yaw_pitch_round_trip():
    for up in ((0, 1, 0), (0, 0, 1)):
        for yaw, pitch in ((0.0, 0.0), (35.0, -20.0), (-150.0, 60.0)):
            assert yaw_pitch(up, direction(up, yaw, pitch)) == pytest.approx((yaw, pitch))


def test_fly_controller(cornell):
    cam0 = cornell.default.camera
    fly = FlyController.from_camera(cam0, speed=1.0)
    c = fly.camera()
    np.testing.assert_allclose(c.position, cam0.position)
    d0 = np.subtract(cam0.target, cam0.position)
    np.testing.assert_allclose(np.subtract(c.target, c.position) / fly.focus, d0 / np.linalg.norm(d0), atol=1e-12)
    fly.move(1.0, 0.0, 0.0, dt=1.0)  # W for one second at 1 m/s: one metre down -z
    np.testing.assert_allclose(fly.position, np.add(cam0.position, (0, 0, -1)), atol=1e-12)
    fly.move(0.0, 1.0, 1.0, dt=0.5)  # D + E: right and up
    np.testing.assert_allclose(fly.position, np.add(cam0.position, (0.5, 0.5, -1)), atol=1e-12)
    fly.move(1.0, 0.0, 0.0, dt=0.25, fast=True)  # shift: 4x
    np.testing.assert_allclose(fly.position, np.add(cam0.position, (0.5, 0.5, -2)), atol=1e-12)
    fly.look(100.0, 0.0)  # mouse right: turn right (towards +x)
    assert fly.forward()[0] > 0.3
    fly.look(0.0, -1e5)  # far up: pitch clamped below the pole
    assert fly.pitch == pytest.approx(89.0)
    fly.camera().view_matrix()  # still a valid camera
    s = fly.speed
    fly.scroll(2.0)
    assert fly.speed == pytest.approx(s * 1.25 ** 2)


def test_orbit_controller(cornell):
    centre = np.array([0.0, 1.0, 0.0])
    orbit = OrbitController.from_camera(cornell.default.camera, centre)
    assert orbit.distance == pytest.approx(3.4)
    np.testing.assert_allclose(orbit.camera().position, cornell.default.camera.position, atol=1e-12)
    orbit.drag(300.0, 0.0)  # 90 degrees at 0.3 deg/px: the camera swings to -x, still looking at the centre
    c = orbit.camera()
    np.testing.assert_allclose(c.position, (-3.4, 1.0, 0.0), atol=1e-9)
    np.testing.assert_allclose(c.target, centre)
    orbit.drag(0.0, 100.0)  # drag down: the camera rises
    assert orbit.camera().position[1] > 1.0
    assert np.linalg.norm(np.subtract(orbit.camera().position, centre)) == pytest.approx(3.4)
    orbit.scroll(1.0)
    assert orbit.distance == pytest.approx(3.4 * 0.9)


def test_controller_switch_and_reset(state, cornell):
    state.fly(forward=1.0, right=0.5, dt=1.0)
    state.look(40.0, 10.0)
    assert state.config.camera != cornell.default.camera
    state.set_controller("orbit")
    assert state.controller.kind == "orbit"
    np.testing.assert_allclose(state.controller.centre, state.scene_centre())
    state.drag(50.0, 0.0)
    state.scroll(3.0)
    state.reset_camera()
    c, c0 = state.config.camera, cornell.default.camera
    np.testing.assert_allclose(c.position, c0.position, atol=1e-9)
    d, d0 = np.subtract(c.target, c.position), np.subtract(c0.target, c0.position)
    np.testing.assert_allclose(d / np.linalg.norm(d), d0 / np.linalg.norm(d0), atol=1e-9)
    state.toggle_controller()
    assert state.controller.kind == "fly"


def test_pixel_ray_matches_the_camera_convention(cornell):
    from diviewer.scene import camera as cam

    c = cornell.default.camera
    o, d = pixel_ray(c, 64.0, 64.0, 128, 128)
    np.testing.assert_allclose(d, cam.normalize(np.subtract(c.target, c.position)), atol=1e-12)
    rays = cam.pixel_rays_view(4, 3, c.fov)  # pixel (i, j) centre is (j + 0.5, i + 0.5)
    _, d = pixel_ray(c, 2.5, 0.5, 4, 3)
    world = cam.view_to_world(c.view_matrix())[:3, :3] @ rays[0, 2]
    np.testing.assert_allclose(d, world / np.linalg.norm(world), atol=1e-12)


def test_stats_keep_the_last_seconds():
    s = Stats(window_s=1.0)
    for i in range(30):
        s.record(10.0 + i, {"gbuffer": 1.0, "inference": 2.0}, now=i * 0.125)
    assert s.series().tolist() == [float(10 + i) for i in range(21, 30)]  # 2.625 .. 3.625 s
    assert s.series("gbuffer").tolist() == [1.0] * 9
    assert s.mean("inference") == pytest.approx(2.0)
    assert s.last()["frame"] == 39.0 and s.fps == pytest.approx(1000.0 / s.mean("frame"))


def test_letterbox_keeps_the_gi_aspect():
    from diviewer.viewer.window import letterbox

    assert letterbox(200, 100, 1.0) == (50, 0, 100, 100)
    assert letterbox(100, 200, 2.0) == (0, 75, 100, 50)
    assert letterbox(128, 128, 1.0) == (0, 0, 128, 128)
    assert letterbox(1, 1, 4 / 3) == (0, 0, 1, 1)
    assert letterbox(0, 0, 1.0) == (0, 0, 0, 0)


def test_shortcut_list_comes_from_the_key_table():
    from diviewer.viewer.input import BINDINGS, SHORTCUTS, shortcuts_markdown

    chords = [c for b in BINDINGS for c in b.chords]
    assert len(chords) == len(set(chords)), "a key bound twice"
    assert all(b.run is not None for b in BINDINGS if b.chords)
    assert {m.key for m in VIEW_MODES if m.key} <= set(chords)
    assert ("Shift+R", "reset the whole frame (lights, objects, camera)") in SHORTCUTS
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    assert shortcuts_markdown() in readme, "README's controls differ from viewer/input.py (paste shortcuts_markdown())"


def test_one_tone_map_list():
    from diviewer.cli import build_parser
    from diviewer.gl.display import DEFAULT_TONEMAP, TONEMAPS

    from diviewer.commands.parser import arguments, subcommands

    render = subcommands(build_parser())["render"]
    tonemap = next(a for a in arguments(render) if a.dest == "tonemap")
    assert tuple(tonemap.choices) == tuple(TONEMAPS) and tonemap.default == DEFAULT_TONEMAP
    shader = (Path(__file__).resolve().parents[2] / "shaders" / "tonemap.glsl").read_text()
    for name, code in TONEMAPS.items():  # the codes the shader's comment documents
        assert f"{code}: " in shader and (name[:4].lower() in shader.lower())


def test_view_command_line():
    import argparse

    from diviewer.commands.view import add_parser, run

    ap = argparse.ArgumentParser()
    add_parser(ap.add_subparsers(dest="command"))
    args = ap.parse_args(["view", "--model", "none", "--size", "320x240", "--no-vsync", "--frames", "3",
                          "--screenshot", "x.png", "--provider", "cpu"])
    assert args.func is run and args.scene == "cornell" and args.model == "none" and args.no_vsync
    assert args.frames == 3 and args.screenshot == Path("x.png") and args.provider == "cpu"
    args = ap.parse_args(["view"])
    assert args.model == "auto" and args.frames is None and not args.no_vsync and args.shadow_bands
    assert not ap.parse_args(["view", "--no-shadow-bands"]).shadow_bands  # ViewerSettings.rest_in_bands
    with pytest.raises(SystemExit):
        ap.parse_args(["view", "--provider", "opengl"])


@pytest.mark.slow
def test_viewer_imports_no_torch():
    code = ("import sys, diviewer.viewer.app, diviewer.viewer.imgui_gl, diviewer.reference.progressive, "
            "diviewer.viewer.panel, diviewer.gl.neural, diviewer.contract.runtime; assert 'torch' not in sys.modules, 'torch was imported'")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr


def test_model_card_rows():
    from diviewer.viewer.panel import meta_lines

    rows = dict(meta_lines({"K": 8, "resolution": [64, 48], "target": "indirect", "dataset_hash": "ab" * 32,
                            "val": {"psnr": 31.5, "ssim": 0.91234}}))
    assert rows["K"] == "8" and rows["resolution"] == "[64, 48]" and rows["target"] == "indirect"
    assert rows["val.psnr"] == "31.5" and rows["val.ssim"] == "0.9123" and rows["dataset_hash"].endswith("...")


# --- window sessions ------------------------------------------------------------------------------
#
# Each session runs in a child process: a window's GLX context cannot be made current on a thread
# where an EGL context is current (the session's headless one: Mesa answers with an X error that
# ends the process), and a crash in a window session then fails one test instead of the run.

def _fail_or_skip(why: str):
    if REQUIRE_GL:
        pytest.fail(f"DIVIEWER_REQUIRE_GL is set and the viewer cannot open a window: {why}")
    pytest.skip(why)


@pytest.fixture(scope="session")
def display():
    """A display for GLFW: the existing DISPLAY, or an Xvfb started for this session."""
    proc = None
    if not os.environ.get("DISPLAY"):
        xvfb = shutil.which("Xvfb")
        if xvfb is None:
            _fail_or_skip("no DISPLAY and no Xvfb to make one")
        n = next(n for n in range(120, 200) if not os.path.exists(f"/tmp/.X{n}-lock"))
        proc = subprocess.Popen([xvfb, f":{n}", "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.time() + 15
        while not os.path.exists(f"/tmp/.X11-unix/X{n}") and time.time() < deadline and proc.poll() is None:
            time.sleep(0.05)
        if proc.poll() is not None or not os.path.exists(f"/tmp/.X11-unix/X{n}"):
            proc.kill()
            _fail_or_skip(f"Xvfb :{n} did not start")
        os.environ["DISPLAY"] = f":{n}"
    probe = "import glfw, sys; ok = glfw.init(); glfw.terminate(); sys.exit(0 if ok else 1)"
    r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60)
    if r.returncode != 0:
        _fail_or_skip(f"GLFW cannot initialise on DISPLAY={os.environ.get('DISPLAY')}: {r.stderr.strip()[-300:]}")
    yield os.environ["DISPLAY"]
    if proc is not None:
        proc.terminate()
        proc.wait(10)
        del os.environ["DISPLAY"]


def _child(fn, args, queue) -> None:
    import traceback

    try:
        fn(*args)
        queue.put("")
    except BaseException:  # noqa: BLE001 (reported to the parent, which fails the test with it)
        queue.put(traceback.format_exc())


def _in_window_process(fn, *args, timeout: float = 180.0) -> None:
    """Run ``fn(*args)`` (a module-level function) in a fresh process; fail with its traceback."""
    import multiprocessing
    import queue as queue_module

    mp = multiprocessing.get_context("spawn")
    q = mp.Queue()
    p = mp.Process(target=_child, args=(fn, args, q))
    p.start()
    p.join(timeout)
    if p.is_alive():
        p.kill()
        p.join()
        pytest.fail(f"the viewer session did not finish within {timeout:.0f} s")
    try:
        error = q.get(timeout=5)
    except queue_module.Empty:
        error = f"the viewer process died without a report (exit code {p.exitcode})"
    if error:
        pytest.fail(error, pytrace=False)


def _settings(**changes):
    from diviewer.gl.renderer import RenderSettings
    from diviewer.viewer.app import ViewerSettings
    from diviewer.reference.progressive import ReferenceSettings

    base = dict(size=(128, 128), vsync=False, model="none", render=RenderSettings(shadow_size=256), target_fps=0.0,
                reference=ReferenceSettings(variant="scalar_rgb", max_spp=2, pass_spp=1, max_depth=4))
    return ViewerSettings(**{**base, **changes})


def _wait_for_reference(viewer, timeout: float = 60.0):
    deadline = time.time() + timeout
    while viewer.reference.latest() is None and viewer.reference.available and time.time() < deadline:
        time.sleep(0.05)


def _png(path) -> np.ndarray:
    from diviewer.imageio import read_png

    return read_png(path).astype(np.float32)


def _check_image(img: np.ndarray, size) -> None:
    assert img.shape == (size[1], size[0], 3)
    assert img.std() > 5.0, "the screenshot is (nearly) uniform"


# What a screenshot must show, made without the window: the frame its JSON records, rendered again on the
# session's headless context and drawn by the display pass. Arguments a and b pick a buffer of that
# frame and how it is shown: (buffer, display kind, factor).
DIRECT = ("direct", "radiance", 1.0)


def _offscreen_view(ctx, shot: Path, a=DIRECT, b=None, layout: str = "single", window=None,
                    linear: bool = False) -> np.ndarray:
    """The view a screenshot (``shot``: its PNG path) recorded, re-rendered offscreen, (H, W, 3) float.

    Args:
        window: (w, h): draw it letterboxed into a window-sized target cleared with the viewer's background
            (what the window shows with the panel hidden), else at the frame's own resolution.
        linear: sample the image bilinearly (the neural pass's texture) rather than nearest (the G-buffer's).
    """
    import moderngl

    from diviewer.frames import load_frame_json, scene_for_frame_json
    from diviewer.gl.context import unbind_framebuffer
    from diviewer.gl.display import DisplayPass, Image, Look, depth_range, read_rgb8
    from diviewer.gl.renderer import Renderer, RenderSettings
    from diviewer.viewer.app import BACKGROUND
    from diviewer.viewer.window import letterbox

    path = shot.with_suffix(".json")
    record = json.loads(path.read_text())
    scene = scene_for_frame_json(load_scene(record["scene"]), path)
    config = load_frame_json(scene, path)
    w, h = record["resolution"]
    renderer = Renderer(ctx, scene, w, h, RenderSettings(shadow_size=256))  # as _settings()
    display = DisplayPass(ctx, renderer.shaders)
    frame = renderer.frame(config)
    made = []
    neural = None
    if record.get("gi_size"):
        # The neural GI as the viewer ran it: the recorded model at the recorded GI resolution and settings.
        from diviewer.gl.neural import GISettings, NeuralPass
        from diviewer.contract.runtime import NeuralGI

        gi = GISettings(**{**record["gi_settings"], "pipelined": False})
        neural = NeuralPass(ctx, renderer, NeuralGI(record["model"], scene=scene), tuple(record["gi_size"]), gi)
        neural.run()

    def image(spec) -> Image:
        name, kind, factor = spec
        if name == "final":  # the full-resolution composite
            return Image(neural.composite(), False, kind)
        if name == "net_output":  # the network's own output at the GI resolution
            return Image(neural.texture, True, kind)
        arr = np.ascontiguousarray(np.flipud(frame[name] * factor), dtype="f4")
        tex = ctx.texture((w, h), 1 if arr.ndim == 2 else 3, arr.tobytes(), dtype="f4")
        tex.filter = (moderngl.LINEAR, moderngl.LINEAR) if linear else (moderngl.NEAREST, moderngl.NEAREST)
        tex.repeat_x = tex.repeat_y = False
        made.append(tex)
        return Image(tex, False, kind)

    tw, th = window or (w, h)
    target = ctx.texture((tw, th), 4)
    fbo = ctx.framebuffer([target])
    try:
        fbo.use()
        fbo.clear(*BACKGROUND, 1.0)
        rect = letterbox(tw, th, w / h) if window else (0, 0, w, h)
        look = Look(record["display"]["exposure"], record["display"]["tonemap"], depth_range(scene, config),
                    split=0.5, diff_gain=2.0 ** 2.0)  # the state's defaults
        display.show(fbo, rect, image(a), image(b) if b else None, layout, look)
        return read_rgb8(fbo).astype(np.float32)
    finally:
        unbind_framebuffer(ctx)
        for r in (fbo, target, *made):
            r.release()
        if neural is not None:
            neural.release()
        display.release()
        renderer.release()


def _same(shown: np.ndarray, expected: np.ndarray, what: str) -> None:
    """The window's image equals the offscreen one (both llvmpipe: at most one step of rounding apart)."""
    assert shown.shape == expected.shape, f"{what}: {shown.shape} != {expected.shape}"
    diff = np.abs(shown - expected)
    assert diff.max() <= 1.0, f"{what}: differs from the offscreen render by up to {diff.max():.0f} ({diff.mean():.3f} mean)"


def _scripted_session(tmp_path: Path) -> None:
    from diviewer.frames import load_frame_json
    from diviewer.viewer.run import run_viewer
    from diviewer.reference.progressive import mitsuba_missing

    cornell = load_scene("cornell")
    script = [
        (1, "screenshot", {"path": tmp_path / "before.png"}),
        (2, "set_light_direction", {"azimuth": 15.0, "elevation": 20.0}),
        (3, "screenshot", {"path": tmp_path / "light.png"}),
        (3, "pick_window_point", {"x": 64.0, "y": 74.0}),
        (4, "fly", {"forward": 1.0, "right": 0.3, "dt": 0.5}),
        (4, "look", {"dx": 20.0, "dy": 5.0}),
        (5, "screenshot", {"path": tmp_path / "moved.png"}),
    ]
    f = 6
    for name in VIEW_MODE_NAMES:
        script.append((f, "set_view_mode", {"name": name, "a": "final", "b": "normal"}))
        if name == "reference":
            script.append((f + 1, _wait_for_reference))
            f += 1
        script.append((f + 1, "screenshot", {"path": tmp_path / f"mode_{name}.png"}))
        f += 2
    script.append((f, "window_screenshot", {"path": tmp_path / "window.png"}))
    script.append((f, "set_view_mode", {"name": "final"}))
    picked = {}
    script.append((f, lambda v: picked.update(selected=v.state.selected)))
    script.append((f + 1, lambda v: setattr(v.state, "show_panel", False)))
    script.append((f + 1, "window_screenshot", {"path": tmp_path / "window_nopanel.png"}))
    frames = f + 2
    summary = run_viewer(cornell, frames=frames, screenshot=tmp_path / "last.png", script=script,
                         settings=_settings())
    assert summary["frames"] == frames and summary["gl_error"] == "GL_NO_ERROR"
    assert summary["model"] is None and "no model" in summary["model_message"]
    assert picked["selected"] == "center"
    size = summary["gi_size"]
    assert size == (128, 128)
    before, light, moved = (_png(tmp_path / f"{n}.png") for n in ("before", "light", "moved"))
    assert np.abs(before - light).mean() > 2.0, "moving the light did not change the image"
    assert np.abs(light - moved).mean() > 2.0, "moving the camera did not change the image"
    images = {name: _png(tmp_path / f"mode_{name}.png") for name in VIEW_MODE_NAMES}
    assert np.abs(images["depth"] - images["normal"]).mean() > 10.0
    assert np.abs(images["albedo"] - images["direct"]).mean() > 10.0
    # No model: the network's output says why and shows black; the final image is the direct light.
    assert "net_output" in summary["unavailable"] and images["net_output"].max() == 0
    np.testing.assert_array_equal(images["final"], images["direct"])
    # VXGI adds indirect light to the direct light: brighter on average, lit where direct light is not.
    assert "vxgi" in summary["modes_drawn"] and images["vxgi"].mean() > images["direct"].mean() + 2.0
    if mitsuba_missing() is None:
        assert "reference" in summary["modes_drawn"]
        _check_image(images["reference"], size)
    else:
        assert "Mitsuba" in summary["unavailable"]["reference"]
    # Split screen: final on the left, normals on the right.
    half = size[0] // 2
    assert np.abs(images["split"][:, : half - 2] - images["final"][:, : half - 2]).max() <= 1.0
    assert np.abs(images["split"][:, half + 2:] - images["normal"][:, half + 2:]).max() <= 1.0
    # The window shot has the panel on top of the image (compared with the image in the test itself).
    window = _png(tmp_path / "window.png")
    assert window.shape == (128, 128, 3)
    # The screenshot's JSON is a frame.json that `diviewer render --config` reads back.
    record = json.loads((tmp_path / "moved.json").read_text())
    assert record["scene"] == "cornell" and record["view_mode"] == "final"
    config = load_frame_json(cornell, tmp_path / "moved.json")
    np.testing.assert_allclose(config.lights[0].direction, -angles_to_vector(15.0, 20.0), atol=1e-9)
    assert config.camera != cornell.default.camera
    last, now = load_frame_json(cornell, tmp_path / "last.json"), summary["config"]
    assert last.camera == now.camera and last.objects == now.objects
    np.testing.assert_allclose(last.lights[0].direction, now.lights[0].direction, atol=1e-9)


@pytest.mark.slow
def test_scripted_session(display, tmp_path, ctx):
    """Camera moves, light moves, every view mode, picking, screenshots, a clean exit; each screenshot is the
    frame its JSON records, rendered again offscreen, and so is the window with the panel hidden."""
    _in_window_process(_scripted_session, tmp_path)
    for name in ("before", "light", "moved", "last"):
        _same(_png(tmp_path / f"{name}.png"), _offscreen_view(ctx, tmp_path / f"{name}.png"), name)
    normal = ("normal", "normal", 1.0)
    modes = {"final": (DIRECT,), "direct": (DIRECT,), "depth": (("depth", "depth", 1.0),), "normal": (normal,),
             "albedo": (("albedo", "albedo", 1.0),), "net_input": (("direct", "raw", 1.0),),
             "split": (DIRECT, normal, "split"), "difference": (DIRECT, normal, "difference")}
    for name, args in modes.items():
        shot = tmp_path / f"mode_{name}.png"
        _same(_png(shot), _offscreen_view(ctx, shot, *args), f"view mode {name}")
    # What the window showed (no model: the direct light fills the square window) with the panel hidden ...
    alone = _offscreen_view(ctx, tmp_path / "last.png", window=(128, 128))
    _same(_png(tmp_path / "window_nopanel.png"), alone, "the window without the panel")
    # ... and with it: the panel covers its top left corner, the rest is the image.
    window = _png(tmp_path / "window.png")
    assert np.abs(window[:24, :24] - alone[:24, :24]).mean() > 10.0, "no panel in the window shot"


def _resize_session(tmp_path: Path) -> None:
    from diviewer.viewer.run import run_viewer

    sizes = {}
    script = [(1, "resize", {"width": 8, "height": 8}), (3, "resize", {"width": 1, "height": 1}),
              (5, "resize", {"width": 96, "height": 64}), (4, "set_view_mode", {"name": "split"}),
              (2, lambda v: sizes.setdefault(2, v.gi_size)), (4, lambda v: sizes.setdefault(4, v.gi_size)),
              (7, lambda v: sizes.setdefault(7, v.gi_size)), (7, "set_view_mode", {"name": "final"})]
    summary = run_viewer("cornell", frames=8, screenshot=tmp_path / "after.png", script=script, settings=_settings())
    assert summary["gl_error"] == "GL_NO_ERROR" and summary["frames"] == 8
    assert sizes == {2: (8, 8), 4: (1, 1), 7: (96, 64)}


@pytest.mark.slow
def test_resize_to_tiny_and_back(display, tmp_path, ctx):
    _in_window_process(_resize_session, tmp_path)
    _same(_png(tmp_path / "after.png"), _offscreen_view(ctx, tmp_path / "after.png"), "after resizing")


def _cornell_model(path: Path, **meta_changes) -> Path:
    from onnx_models import base_meta, direct_times

    cornell = load_scene("cornell")
    meta = base_meta(scene_hash=cornell.file_hash, scene="cornell")
    meta.update(resolution=[64, 48], multiple=16, val={"psnr": 31.5, "ssim": 0.91}, **meta_changes)
    return direct_times(path, factor=2.0, meta=meta)


def _neural_session(tmp_path: Path) -> None:
    from diviewer.viewer.run import run_viewer
    from diviewer.viewer.scale import moving_map_size
    from diviewer.viewer.settings import ViewerSettings

    model = _cornell_model(tmp_path / "cornell_k8.onnx")
    shadows = []
    script = [(0, lambda v: shadows.append((v.renderer.moving_shadow_size, v.renderer.rest_in_bands))),
              (1, "screenshot", {"path": tmp_path / "final.png"}),
              (2, "set_view_mode", {"name": "direct"}), (3, "screenshot", {"path": tmp_path / "direct.png"}),
              (4, "set_view_mode", {"name": "net_output"}), (5, "screenshot", {"path": tmp_path / "raw.png"}),
              (6, "set_view_mode", {"name": "difference", "a": "final", "b": "direct"}),
              (7, "screenshot", {"path": tmp_path / "diff.png"}),
              (8, "window_screenshot", {"path": tmp_path / "window.png"}),
              (8, "set_view_mode", {"name": "final"}),
              (9, lambda v: setattr(v.state, "show_panel", False)),
              (9, "window_screenshot", {"path": tmp_path / "window_nopanel.png"})]
    summary = run_viewer("cornell", model=model, frames=10, script=script, settings=_settings(size=(128, 96)),
                         stats=tmp_path / "stats.json")
    assert summary["gl_error"] == "GL_NO_ERROR"
    # the viewer's shadow settings reach its renderer (ViewerSettings): a moving sun's map follows the shaded size
    # (128x96: 256 texels) within the settings' limit
    assert shadows == [(moving_map_size(ViewerSettings().moving_shadow_size, (128, 96)), True)] == [(256, True)]
    assert summary["model"] == "cornell_k8.onnx" and summary["provider"] == "CPUExecutionProvider"
    assert summary["gi_size"] == (64, 48) and summary["render_size"] == (128, 96)
    assert summary["stages_ms"]["inference"] > 0.0 and summary["stages_ms"]["upload"] > 0.0
    final, direct = _png(tmp_path / "final.png"), _png(tmp_path / "direct.png")
    lit = direct.sum(axis=-1) > 30
    assert (final[lit] >= direct[lit] - 1).all() and final[lit].mean() > direct[lit].mean() + 5  # + indirect
    record = json.loads((tmp_path / "final.json").read_text())
    assert record["model"].endswith("cornell_k8.onnx") and record["provider"] == "CPUExecutionProvider"
    assert record["resolution"] == [128, 96] and record["gi_size"] == [64, 48]
    stats = json.loads((tmp_path / "stats.json").read_text())
    assert stats["frames"] == 9 and stats["gi_size"] == [64, 48] and stats["render_size"] == [128, 96]
    assert len(stats["frame_ms"]) == 9 and min(stats["frame_ms"]) > 0  # each frame's time, in order
    assert stats["edge_guard"] == 0  # a whole-frame model (its record names no aspect crops): no column guard
    assert stats["fps"] > 0 and {"shadows", "gbuffer", "direct", "readback", "inference", "upsample",
                                 "composite"} <= set(stats["stages_ms"])
    assert stats["timing"] == "GPU timer queries, read after the frame"  # the swap waited: reading them stalls nothing
    assert stats["direct_light"] == "inline"  # cornell has one light: the direct pass ran only for the direct view


@pytest.mark.slow
def test_neural_gi_every_frame(display, tmp_path, ctx):
    """A tiny ONNX model (2 x direct) runs each frame at its GI resolution (64x48) under a 128x96 window; the
    frame is the full-resolution direct light plus the upsampled indirect light; --stats writes the table."""
    pytest.importorskip("onnx")
    _in_window_process(_neural_session, tmp_path)
    final = ("final", "radiance", 1.0)
    for name, args in {"final": (final,), "direct": (DIRECT,), "raw": (("net_output", "raw", 1.0),),
                       "diff": (final, DIRECT, "difference")}.items():
        shot = tmp_path / f"{name}.png"
        _same(_png(shot), _offscreen_view(ctx, shot, *args), name)
    shown = _png(tmp_path / "window_nopanel.png")  # read back from the window itself
    _same(shown, _offscreen_view(ctx, tmp_path / "final.png", final, window=(128, 96)), "the window")


def _readback_session(tmp_path: Path) -> None:
    from diviewer.viewer.run import run_viewer

    model = _cornell_model(tmp_path / "cornell_k8.onnx")  # trained size 64x48, stride 16
    script = [(0, lambda v: setattr(v.state, "show_panel", False))]
    # window larger than the GI (128x96 over 64x48), equal (64x48, GI 1/1), smaller (32x32 under 64x48),
    # then back to a larger one after a resize, its GI a fraction of the window (1/2 of 96x64: 48x32)
    plan = [(None, None), ((64, 48), "1/1"), ((32, 32), "model"), ((96, 64), "1/2")]
    sizes = {}
    for i, (size, gi) in enumerate(plan):
        f = 3 * i
        if size is not None:
            script.append((f, "resize", {"width": size[0], "height": size[1]}))
            script.append((f, "set_gi_res", {"spec": gi}))
        script.append((f + 2, "screenshot", {"path": tmp_path / f"view{i}.png"}))
        script.append((f + 2, "window_screenshot", {"path": tmp_path / f"window{i}.png"}))
        script.append((f + 2, lambda v, i=i: sizes.setdefault(i, (v.render_size, v.gi_size))))
    summary = run_viewer("cornell", model=model, frames=3 * len(plan), script=script,
                         settings=_settings(size=(128, 96)))
    assert summary["gl_error"] == "GL_NO_ERROR"
    # "model": the training rows (48) at the window's shape (a 32x32 window: 48x48, not the trained 64x48)
    assert sizes == {0: ((128, 96), (64, 48)), 1: ((64, 48), (64, 48)), 2: ((32, 32), (48, 48)),
                     3: ((96, 64), (48, 32))}, sizes


@pytest.mark.slow
def test_window_shows_the_offscreen_frame_at_every_size(display, tmp_path, ctx):
    """What the window really shows (its back buffer, read before the swap) is the offscreen render of the same
    frame at the window's size, for a window larger than, equal to and smaller than the GI, and after resizes."""
    pytest.importorskip("onnx")
    _in_window_process(_readback_session, tmp_path)
    final = ("final", "radiance", 1.0)
    for i, size in enumerate([(128, 96), (64, 48), (32, 32), (96, 64)]):
        shown = _png(tmp_path / f"window{i}.png")
        assert shown.shape == (size[1], size[0], 3)
        _same(shown, _offscreen_view(ctx, tmp_path / f"view{i}.png", final, window=size), f"window {size}")


def _refused_session(tmp_path: Path) -> None:
    from onnx_models import base_meta, direct_times

    from diviewer.viewer.run import run_viewer

    path = direct_times(tmp_path / "other.onnx", meta=base_meta(scene_hash="f" * 64, scene="atrium"))
    summary = run_viewer("cornell", model=path, frames=2, settings=_settings())
    assert summary["model"] is None and "trained for scene 'atrium'" in summary["model_message"]
    assert summary["gi_size"] == (128, 128) and summary["gl_error"] == "GL_NO_ERROR"


@pytest.mark.slow
def test_a_model_for_another_scene_is_refused_in_the_panel(display, tmp_path):
    pytest.importorskip("onnx")
    _in_window_process(_refused_session, tmp_path)


def _input_session(tmp_path: Path) -> None:
    import glfw
    import trimesh

    from diviewer.viewer.run import run_viewer

    cornell = load_scene("cornell")

    trimesh.creation.torus(major_radius=0.3, minor_radius=0.1).export(tmp_path / "ring.ply")
    seen = {}

    def keys(v):
        st = v.state
        for key, mode in ((glfw.KEY_4, "depth"), (glfw.KEY_9, "split"), (glfw.KEY_1, "final")):
            v.input.on_key(key, glfw.PRESS, 0)
            seen[mode] = st.view_mode
        az = st.light_angles()[0]
        v.input.on_key(glfw.KEY_RIGHT, glfw.PRESS, 0)
        seen["azimuth"] = st.light_angles()[0] - az
        v.input.on_key(glfw.KEY_C, glfw.PRESS, 0)
        seen["controller"] = st.controller.kind
        v.input.on_key(glfw.KEY_L, glfw.PRESS, 0)
        seen["animate"] = st.animate_light
        v.input.on_key(glfw.KEY_TAB, glfw.PRESS, 0)
        seen["tab"] = st.selected
        v.input.on_key(glfw.KEY_EQUAL, glfw.PRESS, 0)
        seen["exposure"] = st.exposure
        st.set_light_direction(40.0, 30.0)
        v.input.on_key(glfw.KEY_R, glfw.PRESS, 0)  # R: the camera only
        seen["light_kept"] = st.light_angles()
        v.input.on_key(glfw.KEY_R, glfw.PRESS, glfw.MOD_SHIFT)  # Shift+R: the whole frame
        seen["frame_reset"] = st.config.lights == cornell.default.lights
        v.input.on_key(glfw.KEY_C, glfw.PRESS, glfw.MOD_CONTROL)  # Ctrl+C is bound to nothing
        seen["ctrl_c"] = st.controller.kind

    def mouse(v):
        st = v.state
        cam0 = st.config.camera
        v.input.on_cursor(64.0, 64.0)
        v.input.on_mouse_button(glfw.MOUSE_BUTTON_LEFT, glfw.PRESS, 0)
        v.input.on_cursor(90.0, 70.0)  # a drag: orbit, no picking
        v.input.on_mouse_button(glfw.MOUSE_BUTTON_LEFT, glfw.RELEASE, 0)
        seen["orbited"] = st.config.camera != cam0
        seen["after_drag"] = st.selected
        v.input.on_scroll(0.0, 2.0)
        seen["zoom"] = st.controller.distance
        v.input.on_key(glfw.KEY_R, glfw.PRESS, 0)  # reset the camera, then click the centre object
        v.input.on_cursor(64.0, 74.0)
        v.input.on_mouse_button(glfw.MOUSE_BUTTON_LEFT, glfw.PRESS, 0)
        v.input.on_mouse_button(glfw.MOUSE_BUTTON_LEFT, glfw.RELEASE, 0)
        seen["clicked"] = st.selected

    script = [(1, keys), (2, mouse), (3, "load_mesh", {"path": tmp_path / "ring.ply", "name": "center"}),
              (4, "screenshot", {"path": tmp_path / "ring.png"}),
              (5, lambda v: seen.update(gpu="file:ring" in v.renderer.gpu.meshes))]
    summary = run_viewer(cornell, frames=6, script=script, settings=_settings())
    assert summary["gl_error"] == "GL_NO_ERROR"
    assert (seen["depth"], seen["split"], seen["final"]) == ("depth", "split", "final")
    assert seen["azimuth"] == pytest.approx(5.0) and seen["controller"] == "orbit" and seen["animate"]
    assert seen["tab"] == cornell.default.objects[0].name and seen["exposure"] == pytest.approx(0.5)
    assert seen["light_kept"] == pytest.approx((40.0, 30.0)) and seen["frame_reset"] and seen["ctrl_c"] == "orbit"
    assert seen["orbited"] and seen["after_drag"] == seen["tab"]
    assert seen["zoom"] == pytest.approx(3.4 * 0.81)
    assert seen["clicked"] == "center" and seen["gpu"]
    assert summary["config"].objects[-1].mesh == "file:ring"
    record = json.loads((tmp_path / "ring.json").read_text())
    assert record["user_meshes"] == {"file:ring": str(tmp_path / "ring.ply")}


@pytest.mark.slow
def test_keyboard_mouse_and_mesh_loading(display, tmp_path):
    """The input handlers (as GLFW calls them) drive the state; a mesh file loaded mid-session is drawn."""
    _in_window_process(_input_session, tmp_path)


# --- the background reference ---------------------------------------------------------------------

@pytest.mark.mitsuba
def test_progressive_reference_refines_restarts_and_never_blocks(cornell):
    from diviewer.reference.progressive import ProgressiveReference, ReferenceSettings, mitsuba_missing

    if mitsuba_missing():
        pytest.skip("Mitsuba is not installed")
    ref = ProgressiveReference(ReferenceSettings(variant="scalar_rgb", max_spp=3, pass_spp=2, max_depth=3,
                                                 threads=os.cpu_count()))
    try:
        t0 = time.perf_counter()
        ref.request(cornell, cornell.default, 24, 16)
        assert time.perf_counter() - t0 < 0.5  # the frame loop only hands the job over
        deadline = time.time() + 60
        while (ref.latest() is None or ref.latest().spp < 3) and time.time() < deadline:
            time.sleep(0.02)
        img = ref.latest()
        assert img is not None and img.spp == 3 and img.image.shape == (16, 24, 3)  # 1 + 2 spp
        assert np.isfinite(img.image).all() and img.image.mean() > 0.0 and "done" in ref.status()
        moved = cornell.default.replace_light("sun", direction=(-0.3, -0.42, -0.86))
        t0 = time.perf_counter()
        ref.request(cornell, moved, 24, 16)
        assert time.perf_counter() - t0 < 0.5
        assert ref.latest() is None or ref.latest().generation != img.generation  # the old image is dropped
        while ref.latest() is None and time.time() < deadline:
            time.sleep(0.02)
        assert ref.latest() is not None and not np.allclose(ref.latest().image, img.image)
    finally:
        ref.close()
    assert ref._thread is None


def test_reference_without_mitsuba_says_why(monkeypatch, cornell):
    import importlib.util

    from diviewer.reference import progressive as reference

    real = importlib.util.find_spec
    monkeypatch.setattr(reference.importlib.util, "find_spec",
                        lambda name, *a: None if name == "mitsuba" else real(name, *a))
    ref = reference.ProgressiveReference()
    ref.request(cornell, cornell.default, 8, 8)
    assert not ref.available and "Mitsuba" in ref.status() and ref.latest() is None and ref._thread is None
    ref.close()


@pytest.mark.slow
def test_view_command_saves_the_window_itself(display, tmp_path):
    """`diviewer view --frames N --window-screenshot` writes the last frame's window (panel included) at
    the window's size; right of the panel it is the view that `--screenshot` saves; without --frames
    the option is refused before a window opens."""
    window, view = tmp_path / "window.png", tmp_path / "view.png"
    cmd = [sys.executable, "-m", "diviewer", "view", "--model", "none", "--size", "480x200", "--no-vsync",
           "--frames", "2", "--window-screenshot", str(window), "--screenshot", str(view)]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=180, env=os.environ.copy())
    assert r.returncode == 0, r.stderr
    assert f"saved {window}" in r.stdout
    shown, alone = _png(window), _png(view)
    _check_image(shown, (480, 200))
    from diviewer.viewer.panel import PANEL_WIDTH

    right = slice(PANEL_WIDTH + 16, None)  # the panel sits 8 px in from the left
    _same(shown[:, right], alone[:, right], "the window right of the panel")
    assert np.abs(shown[:, :PANEL_WIDTH] - alone[:, :PANEL_WIDTH]).max() > 30  # the panel is in it
    r = subprocess.run(cmd[:-6] + ["--window-screenshot", str(tmp_path / "w2.png")], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2 and "--window-screenshot" in r.stderr and not (tmp_path / "w2.png").exists()


# --- dynamic resolution, the training-range flag, auto exposure -----------------------------------------------

def _bilinear(img: np.ndarray, w: int, h: int) -> np.ndarray:
    """GL's LINEAR magnification in numpy (tests/oracles.py)."""
    from oracles import bilinear

    return bilinear(img, w, h)


def _upscaled_offscreen(ctx, shot: Path) -> np.ndarray:
    """The frame a screenshot recorded, rendered offscreen at its recorded shading resolution with the recorded
    model, composited, upscaled to the window's size in numpy and tone-mapped by the display pass."""
    from diviewer.frames import load_frame_json, scene_for_frame_json
    from diviewer.gl.display import DisplayPass
    from diviewer.gl.neural import GISettings, NeuralPass
    from diviewer.gl.renderer import Renderer, RenderSettings
    from diviewer.contract.runtime import NeuralGI

    path = shot.with_suffix(".json")
    record = json.loads(path.read_text())
    scene = scene_for_frame_json(load_scene(record["scene"]), path)
    config = load_frame_json(scene, path)
    (w, h), (W, H) = record["render_size"], record["resolution"]
    renderer = Renderer(ctx, scene, w, h, RenderSettings(shadow_size=256))
    display = DisplayPass(ctx, renderer.shaders)
    gi = GISettings(**{**record["gi_settings"], "pipelined": False})
    neural = NeuralPass(ctx, renderer, NeuralGI(record["model"], scene=scene), tuple(record["gi_size"]), gi)
    try:
        renderer.frame(config)
        neural.run()
        tex = neural.composite()
        hdr = np.flipud(np.frombuffer(tex.read(), dtype="f2").reshape(h, w, 4)[..., :3]).astype(np.float32)
        up = _bilinear(hdr, W, H)
        return display.to_ldr(up, record["display"]["exposure"], record["display"]["tonemap"]).astype(np.float32)
    finally:
        neural.release()
        display.release()
        renderer.release()


def _scaled_session(tmp_path: Path, size: tuple[int, int], scale: float) -> None:
    from diviewer.viewer.run import run_viewer

    model = _cornell_model(tmp_path / "cornell_k8.onnx")  # trained 64x48, stride 16
    script = [(0, lambda v: setattr(v.state, "show_panel", False)),
              (3, "screenshot", {"path": tmp_path / "scaled.png"}),
              (3, "window_screenshot", {"path": tmp_path / "window.png"})]
    summary = run_viewer("cornell", model=model, frames=4, script=script, stats=tmp_path / "stats.json",
                         settings=_settings(size=size, render_scale=scale))
    shaded = [round(n * scale) for n in size]
    assert summary["gl_error"] == "GL_NO_ERROR"
    assert summary["render_size"] == tuple(shaded) and summary["view_size"] == size
    assert summary["render_scale"] == scale and summary["gi_size"] == (64, 48)  # the model's rows, the window's shape
    record = json.loads((tmp_path / "scaled.json").read_text())
    assert record["resolution"] == list(size) and record["render_size"] == shaded and record["render_scale"] == scale
    stats = json.loads((tmp_path / "stats.json").read_text())
    assert stats["render_scale"] == scale and stats["render_size"] == shaded and stats["window_size"] == list(size)
    assert stats["render_scales"] == {"min": scale, "median": scale, "max": scale, "changes": 0}
    assert stats["scale_ceiling"] == max(scale, 1.0) and stats["scale_floor"] == min(scale, 0.4)
    assert stats["target_fps"] is None and stats["out_of_range"] == [] and stats["frames_out_of_range"] == 0
    assert stats["culling"] is True and stats["back_faces"] is False
    assert stats["drawn_last_frame"]["gbuffer"]["triangles"] > 0


@pytest.mark.parametrize("size,scale", [((128, 96), 0.5), ((64, 48), 2.0)])
def test_fixed_render_scale_window_is_the_offscreen_render_resampled(display, tmp_path, ctx, size, scale):
    """At --render-scale 0.5 a 128x96 window shades 64x48 and shows it upscaled; at 2 (supersampled) a 64x48 window
    shades 128x96 and shows each 2x2 block's mean (GL's linear filter halfway between four texels). Both the view
    screenshot and the window's own back buffer equal the offscreen render at the shading size, resampled
    bilinearly to the window, tone-mapped."""
    pytest.importorskip("onnx")
    _in_window_process(_scaled_session, tmp_path, size, scale)
    expected = _upscaled_offscreen(ctx, tmp_path / "scaled.png")
    _same(_png(tmp_path / "scaled.png"), expected, f"the screenshot at scale {scale}")
    _same(_png(tmp_path / "window.png"), expected, f"the window at scale {scale}")
    _check_image(expected, size)


def _dynamic_session(tmp_path: Path) -> None:
    from diviewer.viewer.run import run_viewer

    scales = {}
    script = [(f, lambda v, f=f: scales.setdefault(f, (v.render_scale, v.render_size))) for f in (0, 5, 20, 29)]
    from diviewer.viewer.still import StillSettings

    # A still view is refined at scale 1 (test_still.py); without refining, every frame is drawn at the dynamic scale.
    summary = run_viewer("cornell", frames=30, script=script, stats=tmp_path / "stats.json",
                         settings=_settings(size=(128, 96), target_fps=10000.0, scale_floor=0.5,
                                            still=StillSettings(refine=False)))
    assert summary["gl_error"] == "GL_NO_ERROR"
    # 10,000 fps cannot be held: after its first measurement (2 settling frames + 6) the scale drops to the floor.
    assert scales[0] == (1.0, (128, 96)) and scales[5] == (1.0, (128, 96))
    assert scales[20] == scales[29] == (0.5, (64, 48))
    stats = json.loads((tmp_path / "stats.json").read_text())
    assert stats["target_fps"] == 10000.0 and stats["render_scale"] == 0.5 and stats["render_size"] == [64, 48]
    assert stats["render_scales"]["min"] == 0.5 and stats["render_scales"]["max"] == 1.0
    assert stats["render_scales"]["changes"] == 1 and stats["window_size"] == [128, 96]
    settled = stats["at_final_scale"]  # frames 8-29 were drawn at the floor
    assert settled["frames"] == 22 and settled["fps"] > 0 and settled["frame_ms_median"] > 0


def test_target_fps_lowers_the_scale_to_its_floor(display, tmp_path):
    _in_window_process(_dynamic_session, tmp_path)


def _range_session(tmp_path: Path) -> None:
    from diviewer.viewer.run import run_viewer

    seen = {}
    script = [(2, lambda v: seen.setdefault("start", list(v.state.out_of_range()))),
              (3, "fly", {"forward": -1.0, "dt": 2.0}),  # back out of the box, past the region's far side
              (4, "screenshot", {"path": tmp_path / "away.png"}),
              (5, lambda v: seen.setdefault("away", list(v.state.out_of_range())))]
    summary = run_viewer("cornell", frames=6, script=script, stats=tmp_path / "stats.json", settings=_settings())
    assert seen["start"] == []
    assert len(seen["away"]) == 1 and "outside the trained region" in seen["away"][0], seen
    assert summary["out_of_range"] == seen["away"]
    stats = json.loads((tmp_path / "stats.json").read_text())
    assert stats["out_of_range"] == seen["away"] and stats["frames_out_of_range"] == 3  # frames 3, 4 and 5 (of 1-5)
    assert json.loads((tmp_path / "away.json").read_text())["out_of_range"] == seen["away"]


def test_the_out_of_range_flag_turns_on_when_the_camera_leaves(display, tmp_path):
    """Flying the camera out of cornell's declared region turns the flag on: the state, the screenshot's
    record and --stats say why."""
    _in_window_process(_range_session, tmp_path)


def _exposure_session(tmp_path: Path, out: str) -> None:
    from diviewer.viewer.run import run_viewer

    evs = []
    script = [(f, lambda v: evs.append(v.state.exposure)) for f in range(1, 8)]
    script.append((4, "set_light_intensity", {"ev": 2.0}))  # four times the sun
    summary = run_viewer("cornell", frames=8, script=script, stats=tmp_path / f"{out}.json",
                         settings=_settings(auto_exposure=True))
    assert summary["gl_error"] == "GL_NO_ERROR"
    (tmp_path / f"{out}_evs.json").write_text(json.dumps(evs))


def test_auto_exposure_follows_the_frame_and_is_deterministic(display, tmp_path):
    """With auto exposure the exposure is metered from the shown frame (a brighter sun: a lower exposure, reached
    gradually); two runs of the same frames give the same exposures; --stats records it."""
    for out in ("a", "b"):
        _in_window_process(_exposure_session, tmp_path, out)
    a, b = (json.loads((tmp_path / f"{o}_evs.json").read_text()) for o in ("a", "b"))
    assert a == b
    assert a[0] != 0.0 and a[1] == a[2] == a[0]  # metered on the first frame; the same frame, the same exposure
    assert a[4] < a[3] and a[5] < a[4] and a[6] < a[5]  # four times the light: the exposure comes down ...
    assert a[3] - a[6] < 2.0  # ... gradually (2 stops is where it goes)
    stats = json.loads((tmp_path / "a.json").read_text())
    assert stats["auto_exposure"] is True and stats["exposure"] < a[3]


def _scene_exposure_session(tmp_path: Path, out: str, choice) -> None:
    from diviewer.viewer.run import run_viewer

    text = (Path(__file__).resolve().parents[2] / "assets" / "scenes" / "cornell.toml").read_text()
    scene = tmp_path / "auto.toml"
    scene.write_text(text.replace("exposure = 0.0\n", "exposure = 0.0\nauto_exposure = true\n", 1))
    seen = []
    summary = run_viewer(str(scene), frames=2, script=[(1, lambda v: seen.append(v.state.auto_exposure))],
                         stats=tmp_path / f"{out}.json", settings=_settings(auto_exposure=choice))
    assert summary["gl_error"] == "GL_NO_ERROR"
    (tmp_path / f"{out}_on.json").write_text(json.dumps(seen))


def test_a_scene_file_that_asks_for_auto_exposure_starts_with_it(display, tmp_path):
    """``[scene] auto_exposure = true`` (sponza's): the viewer starts metering without --auto-exposure, and
    --no-auto-exposure (settings False) keeps the file's fixed exposure."""
    for out, choice in (("scene", None), ("off", False)):
        _in_window_process(_scene_exposure_session, tmp_path, out, choice)
    assert json.loads((tmp_path / "scene_on.json").read_text()) == [True]
    assert json.loads((tmp_path / "scene.json").read_text())["auto_exposure"] is True
    assert json.loads((tmp_path / "off_on.json").read_text()) == [False]
    assert json.loads((tmp_path / "off.json").read_text())["exposure"] == 0.0


def _shape_session(tmp_path: Path) -> None:
    from diviewer.viewer.run import run_viewer

    # trained 64x48 with crops from 9:16 to 16:9 (a model trained on 64x48 alone would add a note that its GI is
    # extrapolated at 80x48: tests/viewer/test_scale.py), stride 16; the runtime pads any shape
    model = _cornell_model(tmp_path / "cornell_k8.onnx", recipe={"train": {"aspect_crops": [0.5625, 1.7778]}})
    seen = {}
    script = [(1, lambda v: seen.setdefault("wide", (v.gi_size, v.gi.note))),
              (1, "resize", {"width": 96, "height": 160}),
              (3, lambda v: seen.setdefault("portrait", (v.gi_size, v.gi.note)))]
    summary = run_viewer("cornell", model=model, frames=4, script=script, stats=tmp_path / "stats.json",
                         settings=_settings(size=(160, 96)))
    assert summary["gl_error"] == "GL_NO_ERROR"
    # A 5:3 window: the network runs at the model's 48 rows and the window's shape, 80x48 (not squashed to 64x48).
    assert seen["wide"] == ((80, 48), "")
    # Portrait 3:5: 29x48, padded to the stride inside the runtime (a runtime that does not pad gets the
    # stride's 32x48 and a note: tests/viewer/test_scale.py).
    assert seen["portrait"] == ((29, 48), "")
    assert json.loads((tmp_path / "stats.json").read_text())["gi_note"] is None  # nothing to explain


def test_the_network_sees_the_window_shape(display, tmp_path):
    pytest.importorskip("onnx")
    _in_window_process(_shape_session, tmp_path)


def _camera_path_session(tmp_path: Path) -> None:
    from diviewer.commands.view import _play_camera_path
    from diviewer.viewer.run import run_viewer

    seen, back_faces = [], []
    script = [(0, _play_camera_path)] + [(f, lambda v: seen.append(v.state.config.camera.position)) for f in (1, 2, 3)]
    script.append((1, lambda v: back_faces.append(v.renderer.back_faces)))
    run_viewer("atrium", frames=4, script=script, settings=_settings(size=(64, 64), back_faces=True))
    assert len(set(seen)) == 3, seen  # the camera walks the path, one step a frame
    assert back_faces == [True]  # ViewerSettings.back_faces reaches the renderer


def test_back_faces_flag_reaches_the_viewer_settings(monkeypatch):
    """`diviewer view --back-faces` opens the viewer with the single-sided materials' back faces drawn; without
    it they are culled."""
    from diviewer.cli import main
    from diviewer.viewer import run as session

    opened = []
    monkeypatch.setattr(session, "run_viewer", lambda scene, **kw: opened.append(kw["settings"]) or {})
    for flag in ([], ["--back-faces"]):
        assert main(["view", "--scene", "atrium", "--model", "none", *flag]) == 0
    assert [s.back_faces for s in opened] == [False, True]


def test_camera_moving_plays_the_path_and_is_refused_without_one(display, tmp_path, capsys):
    """--camera-moving starts the scene's camera path at the first frame (atrium walks it); cornell declares a
    free-camera region, not a path: a one-line error naming the flag, before anything is timed."""
    from diviewer.cli import main

    _in_window_process(_camera_path_session, tmp_path)
    assert main(["view", "--scene", "cornell", "--size", "32x32", "--frames", "2", "--model", "none",
                 "--camera-moving"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--camera-moving" in err and "no camera path" in err and len(err.splitlines()) == 1


def _motion_vector_session(tmp_path: Path) -> None:
    import numpy as np

    from diviewer.viewer.run import run_viewer

    for temporal in (True, False):
        seen = []

        def look(v):
            tex = v.renderer.velocity
            seen.append(None if tex is None else
                        np.abs(np.frombuffer(tex.read(), np.float16).reshape(-1, 4)[:, :2].astype(np.float32)).max())

        script = [(f, lambda v, f=f: v.state.move_object("center", (-0.3 + 0.05 * f, 0.75, 0.0))) for f in range(4)]
        script += [(f, look) for f in (2, 3)]  # the last frame's target, before this frame is drawn
        run_viewer("cornell", frames=4, script=script,
                   settings=_settings(size=(64, 64), render_scale=0.5, fixed_step=0.05, temporal=temporal))
        if temporal:  # the object moved between the frames: its pixels carry that motion
            assert len(seen) == 2 and all(s is not None and s > 0.005 for s in seen), seen
        else:
            assert seen == [None, None], seen


@pytest.mark.slow
def test_temporal_upsampling_draws_motion_vectors_and_frames_without_it_none(display, tmp_path):
    """`--temporal on` has the G-buffer pass draw the velocity target the resolve reads (an object moving: not
    zero); without it the renderer draws none."""
    _in_window_process(_motion_vector_session, tmp_path)
