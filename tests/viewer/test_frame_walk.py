"""The viewer's frame walk: one frame of the window (the G-buffer, the network, the composite, the display and the
panel) passes through each diviewer module without going back (`tests/test_walks.py` defines the walk and a trip
back)."""

from __future__ import annotations

from pathlib import Path

import pytest

from walks import walk
from .test_app import display  # noqa: F401 (the fixture: a display for GLFW)

MODEL = Path(__file__).resolve().parents[2] / "assets" / "models" / "cornell.onnx"


def _events_then_a_frame(viewer, shot):
    """What GLFW's event poll delivers through imgui's callbacks (a key for the screenshot, one for vsync, a click on
    the image), then the frame that follows them."""
    import glfw

    gui, handle = viewer.gui, viewer.window.handle
    viewer.state.shot_path = str(shot)
    for key in (glfw.KEY_F12, glfw.KEY_V):
        gui._on_key(handle, key, 0, glfw.PRESS, 0)
    gui._on_cursor(handle, 32.0, 40.0)
    for action in (glfw.PRESS, glfw.RELEASE):
        gui._on_mouse_button(handle, glfw.MOUSE_BUTTON_LEFT, action, 0)
    return viewer.frame()


@pytest.fixture(scope="module")
def viewer_walks(display, tmp_path_factory):  # noqa: F811
    """A frame of the viewer on cornell with its shipped model and the sun moving (so the frame is drawn, not the
    still image presented again), after three warm-up frames; then input events and the frame after them."""
    from diviewer.gl.renderer import RenderSettings
    from diviewer.scene import load_scene
    from diviewer.viewer.app import Viewer, ViewerSettings

    settings = ViewerSettings(size=(64, 64), vsync=False, model=str(MODEL), target_fps=0.0,
                              render=RenderSettings(shadow_size=256))
    viewer = Viewer(load_scene("cornell"), settings)
    try:
        viewer.state.animate_light = True
        for _ in range(3):
            viewer.frame()
        w = walk(viewer.frame)
        shot = tmp_path_factory.mktemp("shot") / "f12.png"
        events = walk(_events_then_a_frame, viewer, shot)
        vsync, selected = viewer.window.vsync, viewer.state.selected
    finally:
        viewer.close()
    assert w.result and events.result
    assert shot.is_file() and vsync and selected is not None  # each event did what it is bound to
    return w, events


@pytest.fixture(scope="module")
def viewer_walk(viewer_walks):
    return viewer_walks[0]


def test_the_viewer_frame_goes_from_the_gbuffer_to_the_network_to_the_screen(viewer_walk):
    stops = viewer_walk.stops
    first = [stops.index(m) for m in ("diviewer.gl.renderer", "diviewer.gl.neural", "diviewer.gl.display")]
    assert first == sorted(first), stops[:20]


def test_the_viewer_frame_never_goes_back(viewer_walk):
    assert viewer_walk.trips_back() == {}, viewer_walk.summary()


def test_input_events_and_their_frame_never_go_back(viewer_walks):
    events = viewer_walks[1]
    assert {"diviewer.viewer.imgui_gl", "diviewer.viewer.input", "diviewer.viewer.app"} <= set(events.stops)
    assert events.trips_back() == {}, events.summary()
