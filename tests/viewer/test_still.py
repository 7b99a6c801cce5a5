"""A still view converges: the motion state machine without GL, then a window session against scale 1."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as hs

from diviewer.scene import load_scene
from diviewer.viewer.scale import ScaleController, ScaleSettings
from diviewer.viewer.state import ViewerState
from diviewer.viewer.still import MOTION_STATES, StillSettings, StillTracker
from tests.viewer.test_app import _in_window_process, _png, _settings, display  # noqa: F401 (a fixture)


def test_a_still_key_waits_refines_then_rests():
    t = StillTracker(StillSettings(wait=2, refine_frames=3))
    states = [t.update("a") for _ in range(8)]
    assert states == ["moving"] * 2 + ["refining"] * 3 + ["still"] * 3
    assert t.update("b") == "moving"  # a change returns to the dynamic scale at once
    assert t.counts == {"moving": 3, "refining": 3, "still": 3}


def test_rest_waits_for_can_rest_and_refine_off_never_refines():
    t = StillTracker(StillSettings(wait=0, refine_frames=1))
    assert [t.update(1, can_rest=False) for _ in range(4)] == ["refining"] * 4
    assert t.update(1) == "still"
    off = StillTracker(StillSettings(refine=False))
    assert {off.update(0) for _ in range(10)} == {"moving"}
    with pytest.raises(ValueError):
        StillTracker(StillSettings(refine_frames=0))


@settings(max_examples=60, deadline=None)
@given(hs.lists(hs.integers(0, 2), min_size=1, max_size=40), hs.integers(0, 3), hs.integers(1, 4))
def test_state_follows_how_long_the_key_held(keys, wait, refine_frames):
    """Whatever the sequence: moving exactly while the key has held for fewer than ``wait`` frames, still only
    after ``refine_frames`` refining frames of the same key; the counts add up to the frames."""
    t = StillTracker(StillSettings(wait=wait, refine_frames=refine_frames))
    held = 0
    for i, k in enumerate(keys):
        held = held + 1 if i and k == keys[i - 1] else 0
        state = t.update(k)
        assert state == ("moving" if held < wait else "refining" if held - wait < refine_frames else "still")
    assert sum(t.counts.values()) == len(keys) and set(t.counts) == set(MOTION_STATES)


def test_the_scale_controller_resumes_where_it_was():
    c = ScaleController(ScaleSettings(target_fps=100.0, settle=2, window=2, steps=10))
    for _ in range(12):
        c.update(40.0)
    low = c.scale
    assert low < 1.0
    c.resume()
    assert c.scale == low
    assert c.update(1.0) == low and c.update(1.0) == low  # the settle frames after a refined view are not measured


def test_overview_camera_stands_outside_the_box_looking_at_its_centre():
    st = ViewerState(load_scene("cornell"))
    lo, hi = st.scene_bounds()
    cam = st.overview_camera().camera
    pos, target = np.asarray(cam.position), np.asarray(cam.target)
    np.testing.assert_allclose(target, 0.5 * (lo + hi), atol=1e-9)
    assert np.any(pos < lo) or np.any(pos > hi), "the overview camera is inside the scene's box"
    assert pos[1] > hi[1] or pos[1] > target[1], "the overview camera does not look down"
    r = 0.5 * np.linalg.norm(hi - lo)
    assert np.linalg.norm(pos - target) + r < cam.far


def _converge_session(tmp_path: Path) -> None:
    from diviewer.viewer.run import run_viewer

    # The camera moves for 24 frames against a frame rate the machine cannot hold: the scale drops to the floor;
    # then the view stays still for 60 frames; then it moves again: that frame is drawn at the controller's scale.
    fly = [(i, "fly", {"forward": 0.02, "dt": 1.0 / 60}) for i in range(24)]
    scales = []
    script = fly + [(23, lambda v: scales.append(v.render_scale)),
                    (83, "screenshot", {"path": tmp_path / "dynamic.png"}),
                    (84, lambda v: scales.append(v.render_scale)), (84, "look", {"dx": 3.0, "dy": 0.0}),
                    (85, lambda v: scales.append(v.render_scale))]
    run_viewer("cornell", frames=86, script=script, stats=tmp_path / "s.json",
               settings=_settings(model="auto", target_fps=1000.0, scale_floor=0.4))
    run_viewer("cornell", frames=26, screenshot=tmp_path / "full.png", script=fly,
               settings=_settings(model="auto", render_scale=1.0))
    (tmp_path / "scales.json").write_text(json.dumps(scales))


@pytest.mark.slow
def test_a_still_view_converges_to_the_scale_1_frame(display, tmp_path):
    """After motion at the floor scale, 60 still frames later the view is the ``--render-scale 1`` frame of the
    same state (display PSNR >= 45 dB; refined at scale 1, it is that frame)."""
    from diviewer.metrics import psnr

    _in_window_process(_converge_session, tmp_path)
    moving, still, moved = json.loads((tmp_path / "scales.json").read_text())
    assert moving < 0.75, "the motion did not lower the scale"
    assert still == 1.0 and moved == moving, "a still view is refined at 1, motion returns to the controller's scale"
    a, b = _png(tmp_path / "dynamic.png") / 255.0, _png(tmp_path / "full.png") / 255.0
    assert psnr(a, b) >= 45.0
    motion = json.loads((tmp_path / "s.json").read_text())["motion"]
    assert motion["state"] == "moving" and motion["frames"]["still"] >= 50 and motion["frames"]["refining"] >= 1
