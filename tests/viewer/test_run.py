"""Scripted sessions (``session.run_viewer``) with a fixed time step: motion follows the frame count, not the clock."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.viewer.test_app import _in_window_process, _png, _settings, display  # noqa: F401 (a fixture)

STEP = 0.05


def _fixed_step_session(tmp_path: Path) -> None:
    from diviewer.viewer.run import run_viewer

    for run, scale in (("a", 0.5), ("b", 0.5), ("full", 1.0)):
        script = [(0, lambda v: setattr(v.state, "animate_light", True))]
        script += [(f, "screenshot", {"path": tmp_path / f"{run}_{f}.png"}) for f in (4, 11)]
        run_viewer("cornell", frames=12, script=script,
                   settings=_settings(model="auto", render_scale=scale, fixed_step=STEP, temporal=True))


@pytest.mark.slow
def test_the_fixed_step_reproduces_a_moving_frame_bit_for_bit(display, tmp_path):
    """The light animated under ``--fixed-step``: two runs save the same bytes at the same frame (temporal
    upsampling and the neural GI included), the light moved between frames, and a run at scale 1 draws the same
    state (the frame JSON's light) at that frame."""
    from diviewer.frames import load_frame_json
    from diviewer.scene import load_scene

    _in_window_process(_fixed_step_session, tmp_path)
    cornell = load_scene("cornell")
    for f in (4, 11):
        assert (tmp_path / f"a_{f}.png").read_bytes() == (tmp_path / f"b_{f}.png").read_bytes(), f"frame {f}"
        a, full = (load_frame_json(cornell, tmp_path / f"{r}_{f}.json") for r in ("a", "full"))
        assert a == full
    assert abs(_png(tmp_path / "a_4.png") - _png(tmp_path / "a_11.png")).mean() > 0.5, "the light did not move"
    first, last = (load_frame_json(cornell, tmp_path / f"a_{f}.json").lights for f in (4, 11))
    assert first != last
