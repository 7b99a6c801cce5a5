"""The viewer's frame walk: one frame of the window (the G-buffer, the network, the composite, the display and the
panel) passes through each diviewer module without going back (`tests/test_walks.py` defines the walk and a trip
back)."""

from __future__ import annotations

from pathlib import Path

import pytest

from walks import walk
from .test_app import display  # noqa: F401 (the fixture: a display for GLFW)

MODEL = Path(__file__).resolve().parents[2] / "assets" / "models" / "cornell.onnx"


@pytest.fixture(scope="module")
def viewer_walk(display):  # noqa: F811
    """A frame of the viewer on cornell with its shipped model and the sun moving (so the frame is drawn, not the
    still image presented again), after three warm-up frames."""
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
    finally:
        viewer.close()
    assert w.result
    return w


def test_the_viewer_frame_goes_from_the_gbuffer_to_the_network_to_the_screen(viewer_walk):
    stops = viewer_walk.stops
    first = [stops.index(m) for m in ("diviewer.gl.renderer", "diviewer.gl.neural", "diviewer.gl.display")]
    assert first == sorted(first), stops[:20]


def test_the_viewer_frame_never_goes_back(viewer_walk):
    assert viewer_walk.trips_back() == {}, viewer_walk.summary()
