"""A build's locks (the work folder's for the whole build, each stage's as its command takes it), its scene keyed
by identity (a moved project resumes), and its stop on SIGTERM or Ctrl-C naming the stage and the resume command."""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import signal
import socket
import time

import pytest

import diviewer.builder.pipeline as pipeline
from diviewer.builder.checks import check_splits
from diviewer.builder.plan import make_plan
from diviewer.builder.state import BuildState
from diviewer.cli import main
from diviewer.errors import DiviewerError
from diviewer.locks import holder, lock_path, run_lock
from diviewer.train.recipe import load_recipe

from builder.test_pipeline import CPU, TINY_RECIPE
from scenes import write_tiny_scene


@pytest.fixture
def recipe(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY_RECIPE)
    return load_recipe(path)


def test_a_stale_lock_of_a_dead_build_is_taken_over(tmp_path, monkeypatch, recipe):
    """A build killed (SIGKILL) leaves its lock file, unlocked: the next build takes it and writes itself in."""
    work = tmp_path / "w"
    work.mkdir()
    lock_path(work).write_text(json.dumps({"pid": 2 ** 22 + 7, "host": socket.gethostname(), "command": "build"}))
    monkeypatch.setattr(pipeline, "_run", lambda plan, *_: holder(plan.work))
    plan = make_plan("cornell", recipe, work, machine=CPU)
    assert f"diviewer build, pid {os.getpid()} on host {socket.gethostname()}" in pipeline.run_build(plan, "cmd")
    assert not lock_path(work).exists(), "released at the end"


@pytest.mark.skipif(importlib.util.find_spec("torch") is None, reason="the train stage needs torch")
def test_the_train_stage_takes_the_run_lock_diviewer_train_takes(tmp_path, monkeypatch, recipe):
    """Two builds of one plan, or a `diviewer train --out WORK/train_kK` beside a build, never train one run
    together: the stage holds the run's lock while it trains, and is refused where another run holds it."""
    import diviewer.train.trainer as trainer

    plan = make_plan("cornell", recipe, tmp_path / "w", machine=CPU)
    state = BuildState(tmp_path / "w" / "build.json", {})
    state.data["stages"]["check"] = {"result": {"frames": {"train": 4}}}
    seen = {}

    def train(cfg, resume, log):
        seen["holder"] = holder(cfg.out)
        for name in ("best.ckpt", "metrics.csv"):
            (cfg.out / name).write_text("x")
        return {"step": 2, "stopped_early": False, "best": 0.5}

    monkeypatch.setattr(trainer, "train", train)
    outputs, result = pipeline._train(plan, state, lambda _: None, k=2)
    assert seen["holder"].startswith(f"diviewer train, pid {os.getpid()}") and result["step"] == 2
    assert holder(plan.run_dir(2)) is None
    with run_lock(plan.run_dir(2), "train"):  # another run trains there
        with pytest.raises(DiviewerError, match=r"another run is writing here: diviewer train, pid \d+ on host"):
            pipeline._train(plan, state, lambda _: None, k=2)


def test_a_project_moved_with_its_scene_resumes_and_an_old_state_still_reads(tmp_path, recipe):
    """The state names the scene by identity and by its path from the work folder; a state written when it named
    the scene by its absolute path is the same build while that path is the scene's."""
    scene = write_tiny_scene(tmp_path / "proj")
    plan = make_plan(str(scene), recipe, tmp_path / "proj" / "w", machine=CPU)
    key = pipeline.plan_key(plan)
    assert key["scene"]["path"] == os.path.join("..", "tiny.toml") and len(key["scene"]["hash"]) == 64
    (plan.work / "data").mkdir(parents=True)
    (plan.work / "data" / "manifest.json").write_text("{}")
    BuildState(plan.work / "build.json", key).finish("capture", plan.work, [plan.work / "data" / "manifest.json"])
    shutil.move(tmp_path / "proj", tmp_path / "moved")
    moved = make_plan(str(tmp_path / "moved" / "tiny.toml"), recipe, tmp_path / "moved" / "w", machine=CPU)
    assert pipeline.finished_stages(moved) == {"capture"}
    # a state of the version before: the scene's absolute path
    old = {**pipeline.plan_key(moved), "scene": str((tmp_path / "moved" / "tiny.toml").resolve())}
    (moved.work / "build.json").write_text(json.dumps({**json.loads((moved.work / "build.json").read_text()),
                                                       "plan": old}))
    assert pipeline.finished_stages(moved) == {"capture"}
    elsewhere = {**old, "scene": str(tmp_path / "another" / "tiny.toml")}
    (moved.work / "build.json").write_text(json.dumps({**json.loads((moved.work / "build.json").read_text()),
                                                       "plan": elsewhere}))
    with pytest.raises(DiviewerError, match="another plan .*scene"):
        pipeline.finished_stages(moved)
    # ... unless the capture in the work folder records this scene's identity: the project moved, state and all
    (moved.work / "data" / "manifest.json").write_text(json.dumps({"scene_hash": pipeline.plan_key(moved)["scene"][
        "hash"]}))
    assert pipeline.finished_stages(moved) == set(), "the same plan, its capture's manifest since changed"
    (moved.work / "data" / "manifest.json").write_text(json.dumps({"scene_hash": "0" * 64}))
    with pytest.raises(DiviewerError, match="another plan .*scene"):
        pipeline.finished_stages(moved)
    (moved.work / "data" / "manifest.json").write_text("{}")
    # the scene edited: another build
    (moved.work / "build.json").write_text(json.dumps({**json.loads((moved.work / "build.json").read_text()),
                                                       "plan": pipeline.plan_key(moved)}))
    (tmp_path / "moved" / "tiny.toml").write_text((tmp_path / "moved" / "tiny.toml").read_text().replace(
        "[scene]", "[scene]\n# a comment changes nothing", 1))
    assert pipeline.finished_stages(moved) == {"capture"}


def test_split_fractions_are_checked_as_the_capture_splits(recipe):
    plan = make_plan("cornell", recipe, "w", machine=CPU)
    check_splits(plan.capture)  # 8 frames at 0.5/0.25/0.25: 4/2/2
    import dataclasses

    with pytest.raises(DiviewerError, match=r"\{'train': 8, 'val': 0, 'test': 0\}"):
        check_splits(dataclasses.replace(plan.capture, split_fractions=(0.9, 0.05, 0.05)))
    with pytest.raises(DiviewerError, match="split fractions must be 3 non-negative numbers"):
        check_splits(dataclasses.replace(plan.capture, split_fractions=(1.0, -0.5, 0.5)))


@pytest.mark.parametrize("how, said", [("term", "SIGTERM"), ("int", "interrupted")])
def test_a_build_stopped_by_sigterm_or_ctrl_c_names_the_stage_and_the_command_that_resumes(tmp_path, monkeypatch,
                                                                                          capsys, how, said):
    recipe = tmp_path / "tiny.toml"
    recipe.write_text(TINY_RECIPE)
    before = signal.getsignal(signal.SIGTERM)

    def capture(*_, **__):
        if how == "int":
            raise KeyboardInterrupt
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(10)
        raise AssertionError("SIGTERM did not stop the stage")

    monkeypatch.setitem(pipeline.STAGES, "capture", capture)
    work = tmp_path / "w"
    assert main(["build", "--scene", "cornell", "--recipe", str(recipe), "--work", str(work), "--ks", "2"]) == 130
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last == (f"diviewer build: stopped in stage capture ({said}); resume with: diviewer build --scene cornell "
                    f"--recipe {recipe} --ks 2 --work {work}"), last
    assert signal.getsignal(signal.SIGTERM) == before and holder(work) is None


def test_an_evaluation_set_made_before_is_the_same_when_moved_with_the_project(tmp_path):
    """--evalset's key: its manifest's sha256 and its path from the work folder; a key of the version before (its
    absolute path) is the same while that path is the set's."""
    from diviewer.builder.state import _same

    (tmp_path / "proj" / "evalset").mkdir(parents=True)
    (tmp_path / "proj" / "evalset" / "manifest.json").write_text('{"kind": "evalset"}')
    key = pipeline.evalset_key(tmp_path / "proj" / "evalset", tmp_path / "proj" / "w")
    assert key["path"] == os.path.join("..", "evalset")
    shutil.move(tmp_path / "proj", tmp_path / "moved")
    work = tmp_path / "moved" / "w"
    moved = pipeline.evalset_key(tmp_path / "moved" / "evalset", work)
    assert _same("given_evalset", key, moved, work)
    assert _same("given_evalset", str((tmp_path / "moved" / "evalset").resolve()), moved, work)
    assert not _same("given_evalset", str(tmp_path / "proj" / "evalset"), moved, work)
    (tmp_path / "moved" / "evalset" / "manifest.json").write_text('{"kind": "evalset", "other": 1}')
    assert not _same("given_evalset", key, pipeline.evalset_key(tmp_path / "moved" / "evalset", work), work)


@pytest.mark.slow
def test_a_build_sent_sigterm_while_it_captures_says_where_it_stopped_and_resumes(gl_context, tmp_path):
    """`kill -TERM` on a real build (a subprocess, capturing the tiny scene): one line naming the stage and the
    command that resumes, exit 130, its lock released; that command then goes on with the frames kept."""
    import subprocess
    import sys

    scene, recipe = write_tiny_scene(tmp_path), tmp_path / "recipe.toml"
    recipe.write_text(TINY_RECIPE.replace("frames = 8", "frames = 40"))
    work = tmp_path / "w"
    argv = ["build", "--scene", str(scene), "--recipe", str(recipe), "--work", str(work), "--ks", "2",
            "--stop-after", "capture"]
    proc = subprocess.Popen([sys.executable, "-m", "diviewer", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and proc.poll() is None:
            if len(list((work / "data" / "frames").glob("*.json"))) >= 2:
                proc.send_signal(signal.SIGTERM)
                break
            time.sleep(0.02)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, (out, err)
    last = out.strip().splitlines()[-1]
    assert last.startswith("diviewer build: stopped in stage capture (SIGTERM); resume with: diviewer build ")
    assert f"--work {work}" in last and "Traceback" not in err
    assert holder(work) is None and holder(work / "data") is None
    kept = len(list((work / "data" / "frames").glob("*.json")))
    assert 2 <= kept < 40
    assert main(argv) == 0
    assert len(list((work / "data" / "frames").glob("*.json"))) == 40


def test_an_error_a_library_raises_after_a_stop_signal_ends_the_build_as_stopped(tmp_path, monkeypatch):
    """A SIGTERM that lands inside a library's own callback (Mitsuba's render wraps the handler's exception in its
    RuntimeError) still ends the build as stopped in its stage; without a stop signal the error is the error."""
    scene, recipe = write_tiny_scene(tmp_path), tmp_path / "recipe.toml"
    recipe.write_text(TINY_RECIPE)
    plan = make_plan(str(scene), load_recipe(recipe), tmp_path / "w", machine=CPU)

    def wrapped(*_args, **_kwargs):
        pipeline.STOP_SIGNALS.append("SIGTERM")  # what the build's handler records before it raises
        raise RuntimeError("drjit.custom(<mitsuba.python.util._RenderOp>): error while performing a custom op")

    monkeypatch.setitem(pipeline.STAGES, "capture", wrapped)
    monkeypatch.setattr(pipeline, "STOP_SIGNALS", [])
    with pytest.raises(pipeline.BuildInterrupted) as stopped:
        pipeline.run_build(plan, "diviewer build", log=lambda *_: None)
    assert stopped.value.stage == "capture" and str(stopped.value) == "SIGTERM"

    def failing(*_args, **_kwargs):
        raise RuntimeError("a real failure")

    monkeypatch.setitem(pipeline.STAGES, "capture", failing)
    monkeypatch.setattr(pipeline, "STOP_SIGNALS", [])
    with pytest.raises(RuntimeError, match="a real failure"):
        pipeline.run_build(plan, "diviewer build", log=lambda *_: None)
