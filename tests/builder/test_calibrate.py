"""Where a build's costs come from: the user's scene timed here, a previous build's actuals, or the constants
(diviewer.builder.calibrate), and the evaluation set's frames as the plan, the render and the scoring count them."""

from __future__ import annotations

import json

import pytest

from diviewer.builder import costs
from diviewer.builder.calibrate import ACTUALS_FILE, CALIBRATION_FILE, basis, calibrate, machine_key
from diviewer.builder.plan import describe, make_plan
from diviewer.train.recipe import capture_settings, load_recipe
from scenes import write_tiny_scene
from builder.test_pipeline import TINY_RECIPE

CPU = costs.Machine("cpu", 2, "the test's machine")


def _recipe(tmp_path):
    path = tmp_path / "tiny_recipe.toml"
    path.write_text(TINY_RECIPE)
    return load_recipe(str(path))


def test_without_a_measurement_the_plan_says_an_unmeasured_scene_is_costed_as_sponza(tmp_path):
    scene = write_tiny_scene(tmp_path)
    plan = make_plan(str(scene), _recipe(tmp_path), tmp_path / "w", machine=CPU)
    text = "\n".join(describe(plan))
    assert "costs of capture, evalset: Sponza's constants: this scene's own cost is unmeasured" in text
    assert "costs of train_k2, train_k4: the training constants" in text
    assert "costs of export_k2, export_k4: an allowance, not a measurement" in text


@pytest.mark.mitsuba
@pytest.mark.gl
def test_the_scene_is_timed_here_once_and_the_plan_names_the_measurement(gl_context, tmp_path):
    scene, recipe, work = write_tiny_scene(tmp_path), _recipe(tmp_path), tmp_path / "w"
    cap = capture_settings(recipe)
    lines = []
    rec = calibrate(scene, "tiny", cap, work, lines.append)
    assert rec is not None and rec["gl_seconds"] > 0 and rec["pt_frame_seconds"] > 0, lines
    assert (work / CALIBRATION_FILE).is_file() and "timed tiny here at 32x32" in lines[0]
    assert calibrate(scene, "tiny", cap, work, lines.append) == rec and len(lines) == 1  # cached: not timed again
    b = basis("tiny", cap, rec, None)
    plan = make_plan(str(scene), recipe, work, machine=CPU, basis=b)
    text = "\n".join(describe(plan))
    assert "costs of capture, evalset: measured on this scene (32x32" in text
    const = make_plan(str(scene), recipe, work, machine=CPU)
    cap_m, cap_c = (next(s for s in p.stages if s.name == "capture") for p in (plan, const))
    assert cap_m.seconds == pytest.approx(cap_c.seconds * b.factors["capture"])
    assert cap_m.seconds == pytest.approx(cap.frames * (rec["pt_frame_seconds"] + rec["gl_seconds"]), rel=0.05)


def test_a_previous_builds_actuals_cost_the_next_plan(tmp_path):
    from types import SimpleNamespace

    cap = SimpleNamespace(width=32, height=32, spp=2)
    actuals = {"capture": {"factor": 3.0, "actual_seconds": 60.0}, "train_k2": {"factor": 0.5, "actual_seconds": 9.0}}
    b = basis("tiny", cap, None, actuals)
    assert b.of("capture")[0] == 3.0 and "a previous build's actuals" in b.of("capture")[1]
    assert b.of("train_k2")[0] == 0.5 and b.of("train_k4")[0] == 1.0
    from diviewer.builder.calibrate import actuals_key, previous_actuals

    (tmp_path / ACTUALS_FILE).write_text(json.dumps({"key": actuals_key("abc", cap), "stages": actuals}))
    assert previous_actuals(tmp_path, "abc", cap) == actuals
    assert previous_actuals(tmp_path, "another scene", cap) is None
    assert previous_actuals(tmp_path, "abc", SimpleNamespace(width=64, height=32, spp=2)) is None  # another size
    assert actuals_key("abc", cap)["machine"] == machine_key()


def test_the_evaluation_sets_counts_agree_between_plan_render_and_score(tmp_path):
    """The plan counts the frames the render plans (every split the scene has) and the crops the scoring scores
    (the window_shapes split at each window width), at the width it renders."""
    from diviewer.evaluation.evalset import plan_evalset, plan_splits
    from diviewer.scene.loader import load_scene

    plan = make_plan("cornell", load_recipe("cornell"), tmp_path / "w", machine=CPU, budget_hours=3)
    ev, counts = plan.evalset, plan.evalset_counts
    scene = load_scene("cornell")
    rendered = plan_evalset(scene, ev)
    splits, _ = plan_splits(scene, ev)
    scored = sum(len(s["shapes"]) for s in splits.values()) * ev.frames_per_split
    assert counts.rendered(ev.frames_per_split) == len(rendered)
    assert counts.scored(ev.frames_per_split) == scored and counts.render_width == ev.render_width
    title = next(s.title for s in plan.stages if s.name == "evalset")
    assert f"= {len(rendered)} rendered at {ev.render_width}x{ev.height}, {scored} crops scored" in title
    share = next(s.seconds for s in plan.stages if s.name == "evalset") / (3 * 3600)
    assert share <= 0.2 + 1e-9  # docs/build.md: at most a fifth of the budget


def test_the_build_reports_plan_against_actual_and_the_next_plan_costs_from_it(tmp_path):
    from types import SimpleNamespace

    from diviewer.builder.actuals import keep_actuals
    from diviewer.builder.calibrate import plan_basis

    scene, recipe, work = write_tiny_scene(tmp_path), _recipe(tmp_path), tmp_path / "w"
    work.mkdir()
    plan = make_plan(str(scene), recipe, work, machine=CPU)
    planned = {s.name: s.seconds for s in plan.stages}
    state = SimpleNamespace(data={"stages": {"export_k2": {"done": True, "seconds": 3 * planned["export_k2"]}}})
    lines = []
    rows = keep_actuals(plan, state, lines.append)
    assert rows["export_k2"]["ratio"] == pytest.approx(3.0) and (work / ACTUALS_FILE).is_file()
    assert lines[0] == "plan against actual:" and "3.00x; cost from an allowance" in lines[1]
    b, _ = plan_basis(str(scene), recipe, work, log=lines.append, keep=False)
    assert b.of("export_k2")[0] == pytest.approx(3.0) and b.of("export_k4")[0] == 1.0
    again = make_plan(str(scene), recipe, work, machine=CPU, basis=b)
    assert next(s for s in again.stages if s.name == "export_k2").seconds == pytest.approx(3 * planned["export_k2"])
    assert "costs of export_k2: a previous build's actuals in this work folder" in "\n".join(describe(again))
