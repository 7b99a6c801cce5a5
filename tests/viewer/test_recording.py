"""Recording camera paths in the viewer and playing them back: the recorder's keys and file, the state's
record/replay (exact with a fixed step), and a window session recorded then replayed pixel for pixel."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from diviewer.scene import load_scene
from diviewer.scene.camera_path import read_path
from diviewer.viewer.recording import Recorder, free_name
from diviewer.viewer.state import ViewerState
from .test_app import display  # noqa: F401 (the fixture: a display for GLFW)

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def atrium():
    return load_scene("atrium")


def test_free_name_never_overwrites(atrium, tmp_path):
    first = free_name(atrium, tmp_path)
    assert first.name == "diviewer_atrium_path.json"
    first.write_text("{}")
    assert free_name(atrium, tmp_path).name == "diviewer_atrium_path_2.json"


def _record(state: ViewerState, frames: int, dt: float) -> list:
    """Fly and turn the light for ``frames`` frames of ``dt`` while recording; the configurations drawn."""
    drawn = []
    for i in range(frames):
        if i % 3 == 0:
            state.fly(forward=1.0, right=0.3 * np.sin(i), dt=dt)
        if i == 4:
            state.set_light_direction(30.0, 40.0)
        state.look(2.0, 0.5 * (i % 2))
        drawn.append(state.step(dt))
    return drawn


def test_record_then_replay_gives_each_frame_exactly_with_a_fixed_step(atrium, tmp_path):
    rec = ViewerState(atrium)
    rec.begin(record=tmp_path / "p.json", exact=True)
    drawn = _record(rec, 30, 0.05)
    assert rec.stop_recording().startswith("recorded 30 frames")
    path, _ = read_path(tmp_path / "p.json", atrium)
    assert len(path.keys) == 30 and path.keys[1].time == 0.05
    play = ViewerState(atrium)
    play.begin(path=tmp_path / "p.json")
    replayed = [play.step(0.05) for _ in range(30)]
    assert replayed == drawn


def test_a_recording_at_the_clock_is_thinned_but_follows_the_flight(atrium, tmp_path):
    rec = ViewerState(atrium)
    rec.record_file = str(tmp_path / "p.json")
    rec.toggle_recording()
    assert rec.recorder is not None and "recording" in rec.message
    steps = np.random.default_rng(1).uniform(0.01, 0.03, 120)
    drawn = []
    for i, dt in enumerate(steps):
        rec.fly(forward=1.0, dt=1 / 60)
        rec.look(3.0 + 5.0 * (i > 60), 0.0)  # the turn quickens half way
        drawn.append(rec.step(float(dt)))
    rec.toggle_recording()
    assert rec.recorder is None and "120 frames" in rec.message
    path, _ = read_path(tmp_path / "p.json", atrium)
    assert 12 <= len(path.keys) < 120
    times = np.concatenate([[0.0], np.cumsum(steps[1:])])  # the clock: the frames' steps summed
    np.testing.assert_allclose([k.time for k in path.keys][-1], times[-1], rtol=1e-12)
    size = float(np.linalg.norm(np.ptp(atrium.bounds(), axis=0)))
    for t, c in zip(times, drawn):  # every frame drawn lies within the recording's tolerance of the path
        got = path.camera_at(float(t))
        assert np.abs(np.subtract(got.position, c.camera.position)).max() <= 1.01e-3 * size
        assert np.abs(np.subtract(got.target, c.camera.target)).max() <= 1.01e-3 * size


def test_p_plays_the_loaded_path_else_the_scene_walk(atrium, tmp_path):
    state = ViewerState(atrium)
    assert state.playable_path() is not None and state.path is None  # the scene file's walk
    assert state.toggle_path()
    c0 = state.step(0.0).camera
    c1 = state.step(3.0).camera
    assert c0 == state.playable_path().camera_at(0.0) and c1 != c0
    # the scene walk sets only the camera: a light the user turned stays
    state.set_light_direction(10.0, 20.0)
    assert state.step(0.1).lights == state.config.lights
    cornell = ViewerState(load_scene("cornell"))
    assert cornell.playable_path() is None and not cornell.toggle_path()


def _view(*args, timeout=240):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    # a fixed render scale: dynamic resolution follows the wall clock, which no two runs share
    return subprocess.run([sys.executable, "-m", "diviewer", "view", "--size", "64x48", "--model", "none",
                           "--no-vsync", "--render-scale", "1", *map(str, args)], capture_output=True, text=True, timeout=timeout, env=env,
                          cwd=ROOT)


@pytest.mark.slow
def test_record_then_replay_in_the_window_draws_the_same_frames(display, tmp_path):
    """The command line: a walk with the light moving recorded at a fixed step, then replayed from the file alone:
    the last frame's view and configuration come back bit for bit."""
    rec = _view("--scene", "atrium", "--frames", "12", "--fixed-step", "0.25", "--camera-moving", "--light-moving",
                "--record-path", tmp_path / "walk.json", "--screenshot", tmp_path / "rec.png")
    assert rec.returncode == 0, rec.stderr
    assert "saved" in rec.stdout and str(tmp_path / "walk.json") in rec.stdout
    data = json.loads((tmp_path / "walk.json").read_text())
    assert len(data["keys"]) == 12 and "lights" in data["keys"][5]
    play = _view("--scene", "atrium", "--frames", "12", "--fixed-step", "0.25", "--path", tmp_path / "walk.json",
                 "--screenshot", tmp_path / "play.png")
    assert play.returncode == 0, play.stderr
    from diviewer.imageio import read_png

    a, b = read_png(tmp_path / "rec.png"), read_png(tmp_path / "play.png")
    assert a.shape == (48, 64, 3) and np.array_equal(a, b)
    ra, rb = (json.loads((tmp_path / f"{n}.json").read_text())["config"] for n in ("rec", "play"))
    assert ra == rb
    # a path of another scene, a path file with a bad version and an unwritable recording: refused before a window
    bad = _view("--scene", "cornell", "--frames", "1", "--path", tmp_path / "walk.json")
    assert bad.returncode == 2 and "scene_hash" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
    data["version"] = 99
    (tmp_path / "v99.json").write_text(json.dumps(data))
    bad = _view("--scene", "atrium", "--frames", "1", "--path", tmp_path / "v99.json")
    assert bad.returncode == 2 and "v99.json: version:" in bad.stderr
    bad = _view("--scene", "atrium", "--frames", "1", "--record-path", tmp_path / "walk.txt")
    assert bad.returncode == 2 and "--record-path" in bad.stderr


def test_a_second_recording_does_not_overwrite_the_first(atrium, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    state = ViewerState(atrium)
    state.begin(record=tmp_path / "first.json")
    state.step(0.1)
    state.toggle_recording()
    first = (tmp_path / "first.json").read_text()
    state.toggle_recording()
    state.fly(forward=1.0)
    state.step(0.1)
    assert "diviewer_atrium_path.json" in state.toggle_recording()
    assert (tmp_path / "first.json").read_text() == first and (tmp_path / "diviewer_atrium_path.json").is_file()
    assert state.stop_recording() == ""  # nothing in progress: nothing written


def test_view_refuses_bad_paths_and_steps_before_a_window(atrium, tmp_path, capsys):
    from diviewer.cli import main
    from diviewer.scene.camera_path import scene_camera_path, write_path

    write_path(tmp_path / "walk.json", scene_camera_path(atrium))
    for args, words in ((["--scene", "cornell", "--path", tmp_path / "walk.json"], ("walk.json: scene_hash:",)),
                        (["--fixed-step", "0"], ("--fixed-step",)),
                        (["--record-path", tmp_path / "walk.json", "--path", tmp_path / "walk.json"],
                         ("--record-path",)),
                        # a flight recorded before is never written over, even when nothing plays it
                        (["--scene", "atrium", "--record-path", tmp_path / "walk.json"],
                         ("--record-path", "a recorded camera path"))):
        assert main(["view", "--frames", "1", "--model", "none", *map(str, args)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and all(w in err for w in words), err
