"""`diviewer build`: the plan and its estimate (--dry-run, --budget), the state file, and the whole pipeline on
a tiny procedural scene, killed and resumed."""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from diviewer.builder import costs
from diviewer.builder.plan import make_plan, planned_steps
from diviewer.builder.state import BuildState
from diviewer.cli import main
from diviewer.errors import DiviewerError
from diviewer.train.recipe import load_recipe

from scenes import write_tiny_scene

CPU = costs.Machine("cpu", 2, "the test's machine")
CUDA = costs.Machine("cuda", 16, "the test's machine")

TINY_RECIPE = """
[recipe]
name = "tinyrecipe"
description = "a build in seconds: 8 frames at 32x32, K 2 and 4, two steps each"

[capture]
frames = 8
width = 32
height = 32
spp = 2
max_depth = 3
split_fractions = [0.5, 0.25, 0.25]
thumbs = 0

[evalset]
frames_per_split = 1
spp = 2
ladder = [1]
max_depth = 3
thumbs = 0

[train]
K = 2
ndf = 8
batch_size = 2
epochs = 1
target = "indirect"
divide_albedo = true
gan_weight = 0.0
device = "cpu"

[export]
fp16 = false
verify_frames = 1

[ladder]
K = [2, 4]
tolerance_db = 0.5
"""


def test_dry_run_prints_the_plan_and_its_estimate_and_does_nothing(tmp_path, capsys):
    work = tmp_path / "work"
    assert main(["build", "--scene", "cornell", "--dry-run", "--work", str(work)]) == 0
    out = capsys.readouterr().out
    for stage in ("capture", "check", "evalset", "train_k8", "export_k8", "train_k16", "evaluate", "pick", "ship"):
        assert f" {stage} " in out, stage
    assert "recipe cornell" in out and "estimated total:" in out and "capture 6000 frames at 228x128, 64 spp" in out
    assert "dry run: nothing was done" in out
    assert f"(diviewer build --scene cornell --work {work})" in out  # the command to run names the folders given
    assert not work.exists()
    assert main(["build", "--recipe", "sponza", "--dry-run", "--work", str(work)]) == 0  # the recipe's scene
    out = capsys.readouterr().out
    assert out.splitlines()[1].startswith("build sponza (sponza) with recipe sponza") and "train_k32" in out
    assert out.startswith(("costs: timed sponza here at 228x128", "costs: sponza could not be timed here"))
    assert not work.exists()  # the timing is kept only in a folder already there
    assert main(["build", "--recipe", "paper", "--dry-run"]) == 2  # the paper's recipe names no scene
    assert "recipe.scene" in capsys.readouterr().err


def test_a_stop_after_names_a_stage_of_the_plan(tmp_path, capsys):
    work = tmp_path / "work"
    assert main(["build", "--scene", "cornell", "--work", str(work), "--ks", "8", "--stop-after", "train_k16"]) == 2
    err = capsys.readouterr().err
    assert "--stop-after" in err and "'train_k16' is not a stage of this build's plan" in err and "train_k8" in err
    assert not work.exists()
    assert main(["build", "--scene", "cornell", "--work", str(work), "--ks", "8", "--stop-after", "check",
                 "--dry-run"]) == 0
    assert "--stop-after check: a run stops there; not run: evalset, train_k8, export_k8, evaluate, pick, ship" in (
        capsys.readouterr().out)
    assert not work.exists()


def test_a_dry_run_counts_a_complete_capture_done_before_any_build_recorded_it(tmp_path, capsys):
    """A work folder whose data/ holds every frame (a capture linked in from another build, or a refined set) with
    no build.json: the run would render none, so the dry run marks the capture done and leaves it out of the time
    left; with a frame missing, or with other settings than the recipe's (the run would refuse it), it is not."""
    import dataclasses

    from diviewer.data.capture import build_manifest
    from diviewer.scene.loader import load_scene

    (tmp_path / "r.toml").write_text(TINY_RECIPE)
    work = tmp_path / "work"
    frames = work / "data" / "frames"
    frames.mkdir(parents=True)
    settings = make_plan("cornell", load_recipe(tmp_path / "r.toml"), work).capture
    (work / "data" / "manifest.json").write_text(json.dumps(build_manifest(load_scene("cornell"), settings)))
    for i in range(7):
        (frames / f"{i:06d}.json").write_text("{}")
    argv = ["build", "--scene", "cornell", "--recipe", str(tmp_path / "r.toml"), "--work", str(work), "--dry-run"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    capture_done = lambda text: any(line.split()[1:3] == ["capture", "done"] for line in text.splitlines()
                                    if line.startswith("   1."))
    assert not capture_done(out) and " left" not in out
    (frames / "000007.json").write_text("{}")
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert capture_done(out), out
    assert "left (stages done in" in out and not (work / "build.json").exists()
    # every frame there, but of other settings: the run would refuse the folder, so the capture is not counted done
    other = build_manifest(load_scene("cornell"), dataclasses.replace(settings, max_depth=4))
    (work / "data" / "manifest.json").write_text(json.dumps(other))
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert not capture_done(out) and " left" not in out


def test_a_dry_run_on_a_folder_of_another_plan_says_the_run_would_refuse_it(tmp_path, capsys):
    """The dry run prints the plan, then the refusal the run would stop with (one line naming the state file and
    the field), not a plan with nothing done as if the folder were empty."""
    work = tmp_path / "work"
    work.mkdir()
    (work / "a.txt").write_text("one")
    BuildState(work / "build.json", {"recipe": {"name": "cornell", "model_sha256": "another"}}).finish(
        "capture", work, [work / "a.txt"])
    assert main(["build", "--scene", "cornell", "--dry-run", "--work", str(work)]) == 2
    out, err = capsys.readouterr()
    assert " train_k8 " in out and "a run of this command would refuse the work folder" in out
    line = err.strip().splitlines()[-1]
    assert "another plan" in line and str(work / "build.json") in line and "plan" in line, err
    assert json.loads((work / "build.json").read_text())["plan"]["recipe"]["model_sha256"] == "another"


def test_the_estimate_follows_the_measured_costs():
    plan = make_plan("cornell", load_recipe("cornell"), Path("w"), machine=CPU)
    steps = planned_steps(plan.capture, {**plan.train, "K": 8})
    est = {s.name: s.seconds for s in plan.stages}
    # costs are measured at 128x128 and scale with the pixels a step sees: the recipe's 228x128 frames cut to its
    # aspect crops, 72 to 227 columns wide
    crops = (72 + 227) / 2 * 128 / (128 * 128)
    assert est["train_k8"] == pytest.approx(steps * costs.TRAIN_SECONDS_PER_STEP[("cpu", 8)] * crops)
    assert est["train_k16"] == pytest.approx(steps * costs.TRAIN_SECONDS_PER_STEP[("cpu", 16)] * crops)
    px = 228 * 128 / (128 * 128)  # the rendering's pixels: the whole frame
    # cornell's 4,800 train frames at batch 4, 40 epochs: the 48,000 steps the shipped model took
    assert steps == 48000
    # the measured set (48 frames), made in two passes, at the one pass's share (diviewer.reference.split_path), for
    # the frames the set renders now: every split cornell has (4) times the recipe's 24 frames per split
    cornell = costs.EVALSET_MEASURED["cornell"]
    frames = plan.evalset_counts.rendered(plan.evalset.frames_per_split)
    assert frames == 4 * 24 and plan.evalset_counts.render_width == 228
    assert est["evalset"] == pytest.approx(cornell["seconds"] * px * costs.ONE_PASS_SHARE * frames / 48, rel=1e-3)
    # each scene's sets at its own measured ratio: Sponza's, measured in one pass, is its time a frame
    sponza = costs.EVALSET_MEASURED["sponza"]
    ladder = tuple(sponza["ladder"])
    assert costs.evalset_seconds("cpu", "sponza", 72, 228, 128, 1024, ladder) == pytest.approx(72 * sponza["seconds"])
    assert costs.evalset_seconds("cpu", "elsewhere", 7, 64, 64, 256, (1, 4)) == pytest.approx(
        costs.evalset_seconds("cpu", "sponza", 7, 64, 64, 256, (1, 4)))  # a scene not measured: costed as Sponza
    on_gpu = make_plan("cornell", load_recipe("cornell"), Path("w"), machine=CUDA)
    assert on_gpu.seconds < plan.seconds / 4
    # the direct light over each pixel's area renders the GL light again at s x s the pixels
    area = costs.capture_seconds("cpu", "cornell", 10, 128, 128, 64, direct_samples=4)
    assert area - costs.capture_seconds("cpu", "cornell", 10, 128, 128, 64) == pytest.approx(
        10 * costs.GL_AREA_SECONDS_PER_PASS["cpu"] * 16)


def test_a_budget_scales_frames_and_steps_together_and_keeps_the_schedule():
    rec = load_recipe("cornell")
    full = make_plan("cornell", rec, Path("w"), machine=CPU)
    plan = make_plan("cornell", rec, Path("w"), budget_hours=1.0, machine=CPU)
    assert plan.seconds <= 3600 and plan.scale < 1
    assert plan.capture.frames < full.capture.frames and plan.steps < full.steps
    assert plan.capture.frames / full.capture.frames == pytest.approx(plan.scale, rel=0.02)
    # the anneal starts at the same fraction of the run; validations in proportion
    assert plan.train["lr_decay_start"] / plan.steps == pytest.approx(20000 / 48000, rel=0.05)
    assert plan.overrides["lr_decay_start"] == plan.train["lr_decay_start"]
    assert plan.train["patience"] == rec.train["patience"]
    generous = make_plan("cornell", rec, Path("w"), budget_hours=1000, machine=CPU)
    assert generous == full and generous.scale == 1.0, "a generous budget never grows the recipe"
    with pytest.raises(DiviewerError, match="--budget.*below the smallest plan"):
        make_plan("cornell", rec, Path("w"), budget_hours=0.01, machine=CPU)
    with pytest.raises(DiviewerError, match="--budget"):
        make_plan("cornell", rec, Path("w"), budget_hours=-1, machine=CPU)


def test_an_evaluation_set_made_before_costs_nothing_and_brings_its_own_settings():
    """--evalset (here the compact set cornell ships): the stage is a check, its settings are the set's (5 or 6
    frames a split of the full set's 1024 spp, not the recipe's 24), and a budget goes to capture and training."""
    rec = load_recipe("cornell")
    shipped = Path(__file__).resolve().parents[2] / "assets" / "evalsets" / "cornell"
    own = make_plan("cornell", rec, Path("w"), machine=CPU)
    given = make_plan("cornell", rec, Path("w"), machine=CPU, evalset_dir=shipped)
    est = {s.name: s.seconds for s in given.stages}
    assert est["evalset"] == 0.0 and given.seconds == pytest.approx(own.seconds - own.stages[2].seconds)
    manifest = json.loads((shipped / "manifest.json").read_text())
    assert given.evalset.frames_per_split == manifest["compact"]["frames_per_split"] < rec.evalset["frames_per_split"]
    assert given.evalset.spp == manifest["spp"] and given.evalset_dir == shipped
    budgeted = make_plan("cornell", rec, Path("w"), budget_hours=1.0, machine=CPU, evalset_dir=shipped)
    smaller = make_plan("cornell", rec, Path("w"), budget_hours=1.0, machine=CPU)
    assert budgeted.seconds <= 3600 and budgeted.scale > smaller.scale  # the evaluation set's share goes to the rest
    assert budgeted.evalset == given.evalset


def test_the_state_skips_only_unchanged_outputs_and_refuses_another_plan(tmp_path):
    out = tmp_path / "a.txt"
    out.write_text("one")
    state = BuildState(tmp_path / "build.json", {"scene": "x"})
    state.finish("capture", tmp_path, [out], {"frames": 3})
    again = BuildState(tmp_path / "build.json", {"scene": "x"})
    assert again.done("capture", tmp_path)["result"] == {"frames": 3}
    assert again.done("train_k8", tmp_path) is None
    out.write_text("two")
    assert again.done("capture", tmp_path) is None, "an output changed since: the stage runs again"
    with pytest.raises(DiviewerError, match="another plan .*scene"):
        BuildState(tmp_path / "build.json", {"scene": "y"})
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(DiviewerError, match="bad.json.*not a build state file"):
        BuildState(tmp_path / "bad.json", {})



def test_an_output_through_a_link_or_outside_the_work_folder_is_found_from_any_working_folder(tmp_path, monkeypatch):
    # a work folder whose data/ links to another build's capture: the capture stage must find the manifest it
    # recorded from any working folder, not look for it under the work folder and run again every time
    shared, work, elsewhere = tmp_path / "first" / "data", tmp_path / "second", tmp_path / "elsewhere"
    shared.mkdir(parents=True)
    work.mkdir()
    elsewhere.mkdir()
    (work / "data").symlink_to(shared)
    (shared / "manifest.json").write_text("{}")
    outside = tmp_path / "first" / "other.json"
    outside.write_text("[]")
    monkeypatch.chdir(tmp_path)
    state = BuildState(work / "build.json", {"scene": "x"})
    state.finish("capture", Path("second"), [Path("second/data/manifest.json"), Path("first/other.json")])
    assert set(state.data["stages"]["capture"]["outputs"]) == {"data/manifest.json", str(outside.resolve())}
    monkeypatch.chdir(elsewhere)
    again = BuildState(work / "build.json", {"scene": "x"})
    assert again.done("capture", work) is not None
    outside.write_text("[1]")
    assert again.done("capture", work) is None, "an output outside the work folder changed: the stage runs again"


def test_a_longer_ladder_keeps_every_k_trained_before_and_redoes_the_stages_over_the_ladder(tmp_path):
    out = tmp_path / "a.txt"
    out.write_text("one")
    state = BuildState(tmp_path / "build.json", {"scene": "x", "ks": [8]})
    for stage in ("capture", "train_k8", "export_k8", "evaluate", "pick", "ship"):
        state.finish(stage, tmp_path, [out])
    grown = BuildState(tmp_path / "build.json", {"scene": "x", "ks": [8, 16]})
    assert grown.ladder_change == ([8], [8, 16])
    assert {s for s in ("capture", "train_k8", "export_k8") if grown.done(s, tmp_path)} == {"capture", "train_k8",
                                                                                              "export_k8"}
    assert [s for s in ("evaluate", "pick", "ship", "train_k16") if grown.done(s, tmp_path)] == []
    grown.finish("train_k16", tmp_path, [out])
    again = BuildState(tmp_path / "build.json", {"scene": "x", "ks": [8, 16]})
    assert again.ladder_change is None and again.done("train_k16", tmp_path) is not None
    with pytest.raises(DiviewerError, match="another plan .*ks, scene"):
        BuildState(tmp_path / "build.json", {"scene": "y", "ks": [8]})


def test_the_pick_weighs_each_split_of_the_evaluation_set_by_its_frames():
    from diviewer.builder.pipeline import evalset_psnr_tm

    splits = {"a": {"psnr_tm": 40.0, "frames": 6}, "b": {"psnr_tm": 30.0, "frames": 2},
              "refused": {"psnr_tm": None, "frames": 6}}
    assert evalset_psnr_tm(splits) == pytest.approx((40 * 6 + 30 * 2) / 8)
    with pytest.raises(DiviewerError, match="scored no frames"):
        evalset_psnr_tm({"refused": {"psnr_tm": None, "frames": 6}})


def test_the_pick_ships_the_smallest_sufficient_k_among_those_within_the_size_cap(tmp_path):
    from diviewer.builder.pipeline import pick_within

    rows = [{"K": 8, "bytes": 1.4e6, "evalset_psnr_tm": 35.0}, {"K": 16, "bytes": 5.3e6, "evalset_psnr_tm": 36.0},
            {"K": 32, "bytes": 21e6, "evalset_psnr_tm": 37.5}]
    pick, over = pick_within(rows, 0.5, None)
    assert (pick["K"], pick["best_K"], over) == (32, 32, [])
    pick, over = pick_within(rows, 0.5, 8)
    assert (pick["K"], pick["best_K"], pick["best_psnr"], over) == (16, 16, 36.0, [32])
    pick, over = pick_within(rows, 1.0, 8)
    assert (pick["K"], over) == (8, [32]), "within the tolerance of the best K that fits"
    with pytest.raises(DiviewerError, match=r"bad.toml.*ladder.max_mb.*K = 8, is 1.40 MB"):
        pick_within(rows, 0.5, 1.0, tmp_path / "bad.toml")


def test_a_pick_by_another_rule_or_a_ship_of_another_ladder_runs_again(tmp_path):
    from types import SimpleNamespace

    from diviewer.builder.pipeline import PICK_MEASURE, _stale

    (tmp_path / "ladder.json").write_text('{"chosen_K": 8}')
    plan = SimpleNamespace(work=tmp_path, ship=tmp_path / "ship", recipe=SimpleNamespace(max_mb=None))
    # a build made while the pick read the capture's 64-spp test split: picked again on the evaluation set
    assert _stale("pick", {"result": {"chosen_K": 8}}, plan)
    assert not _stale("pick", {"result": {"chosen_K": 8, "measure": PICK_MEASURE}}, plan)
    capped = SimpleNamespace(work=tmp_path, ship=tmp_path / "ship", recipe=SimpleNamespace(max_mb=8.0))
    assert _stale("pick", {"result": {"chosen_K": 8, "measure": PICK_MEASURE}}, capped), "a new size cap: re-picked"
    assert not _stale("pick", {"result": {"chosen_K": 8, "measure": PICK_MEASURE, "max_mb": 8.0}}, capped)
    from diviewer.data.dataset import sha256_file

    shipped = {"result": {"to": str(plan.ship), "ladder_sha256": sha256_file(tmp_path / "ladder.json")}}
    assert not _stale("ship", shipped, plan)
    (tmp_path / "ladder.json").write_text('{"chosen_K": 16}')
    assert _stale("ship", shipped, plan), "the pick changed: the ship follows it"
    assert _stale("ship", {"result": {"to": str(plan.ship)}}, plan), "a ship recorded before its ladder was"
    assert _stale("ship", shipped, SimpleNamespace(work=tmp_path, ship=tmp_path / "elsewhere"))
    nowhere = SimpleNamespace(work=tmp_path, ship=None)  # a plan that ships nowhere: its ship stage is done once
    assert not _stale("ship", {"result": {"to": None}}, nowhere)
    assert _stale("ship", shipped, nowhere)
    assert not _stale("capture", {"result": {}}, plan)


def test_an_edited_export_table_exports_again_and_keeps_every_training(tmp_path):
    out = tmp_path / "a.txt"
    out.write_text("one")
    recipe = {"name": "sponza", "sha256": "bytes-1", "content_sha256": "with-export-1", "model_sha256": "model-1"}
    key = {"recipe": recipe, "export": {"fp16": False, "half_weights": False}, "ks": [8, 16]}
    state = BuildState(tmp_path / "build.json", key)
    for stage in ("capture", "train_k8", "export_k8", "train_k16", "export_k16", "evaluate", "pick", "ship"):
        state.finish(stage, tmp_path, [out])
    edited = {**key, "recipe": {**recipe, "sha256": "bytes-2", "content_sha256": "with-export-2"},
              "export": {"fp16": False, "half_weights": True}}
    again = BuildState(tmp_path / "build.json", edited)
    assert again.export_change == (key["export"], edited["export"]) and again.ladder_change is None
    kept = ("capture", "train_k8", "train_k16", "export_k8", "export_k16", "evaluate", "pick", "ship")
    assert [s for s in kept if again.done(s, tmp_path)] == ["capture", "train_k8", "train_k16"]
    with pytest.raises(DiviewerError, match="another plan .*recipe"):  # what the model is trained on is another build
        BuildState(tmp_path / "build.json", {**edited, "recipe": {**edited["recipe"], "model_sha256": "model-2"}})


def test_the_training_settings_may_change_until_a_k_is_trained(tmp_path):
    """A capture refined for hours, then the recipe's [train] edited: while no stage from the training on has
    finished, the build goes on with the new settings and keeps every stage; once a K is trained it is another
    build, as is a changed capture at any time."""
    out = tmp_path / "a.txt"
    out.write_text("one")
    recipe = {"name": "sponza", "sha256": "bytes-1", "content_sha256": "c-1", "model_sha256": "model-1"}
    key = {"recipe": recipe, "capture": {"spp": 256}, "train": {"lr": 2e-4}, "ks": [8]}
    state = BuildState(tmp_path / "build.json", key)
    for stage in ("capture", "refine", "check", "evalset"):
        state.finish(stage, tmp_path, [out])
    edited = {**key, "recipe": {**recipe, "model_sha256": "model-2"}, "train": {"lr": 2e-4, "ssim_weight": 0.1}}
    again = BuildState(tmp_path / "build.json", edited, save_upgrade=True)
    assert again.train_change == ({"lr": 2e-4}, {"lr": 2e-4, "ssim_weight": 0.1})
    assert [s for s in ("capture", "refine", "check", "evalset") if again.done(s, tmp_path)] == [
        "capture", "refine", "check", "evalset"]
    assert json.loads((tmp_path / "build.json").read_text())["plan"] == edited
    with pytest.raises(DiviewerError, match="another plan .*capture"):
        BuildState(tmp_path / "build.json", {**edited, "capture": {"spp": 512}})
    again.finish("train_k8", tmp_path, [out])
    with pytest.raises(DiviewerError, match="another plan .*recipe, train"):
        BuildState(tmp_path / "build.json", key)
    assert BuildState(tmp_path / "build.json", edited).train_change is None


@pytest.mark.skipif(importlib.util.find_spec("torch") is None, reason="trains a tiny run")
def test_a_k_begun_under_the_former_training_settings_is_kept_beside_and_trained_from_the_start(tmp_path):
    """What the state allows (the recipe's [train] edited before any K finished) the training would refuse to
    resume: the run begun before is renamed, not resumed and not lost; a change the training may resume over
    (epochs) keeps it."""
    from diviewer.builder.pipeline import _set_aside_if_begun_otherwise
    from diviewer.train.trainer import train
    from train.test_trainer import make_dataset, quiet, tiny

    data, run, said = tmp_path / "data", tmp_path / "train_k4", []
    make_dataset(data)
    train(tiny(data, run, epochs=1), log=quiet)
    _set_aside_if_begun_otherwise(tiny(data, run, epochs=3), run, said.append)
    assert (run / "last.ckpt").is_file() and said == []
    _set_aside_if_begun_otherwise(tiny(data, run, ssim_weight=0.1), run, said.append)
    kept = [p for p in tmp_path.iterdir() if p.name.startswith("train_k4_before_")]
    assert not run.exists() and len(kept) == 1 and (kept[0] / "last.ckpt").is_file()
    assert len(said) == 1 and "ssim_weight: 0.0 -> 0.1" in said[0] and kept[0].name in said[0]
    _set_aside_if_begun_otherwise(tiny(data, run, ssim_weight=0.1), run, said.append)  # nothing there: nothing done
    assert len(said) == 1


def test_a_key_of_the_version_before_is_the_same_plan_and_is_upgraded_when_a_build_runs(tmp_path):
    """A state file written before the export settings were keyed apart (its recipe hash covers [export]): the same
    recipe is the same plan; a running build writes this version's key at once (a dry run does not), so that the
    next run may edit [export]. While the old key stands, an edited [export] is another plan, as it was."""
    out = tmp_path / "a.txt"
    out.write_text("one")
    old_key = {"recipe": {"name": "sponza", "sha256": "bytes-1", "content_sha256": "with-export-1"}, "ks": [8]}
    first = BuildState(tmp_path / "build.json", old_key)
    for stage in ("capture", "train_k8"):  # a K trained: the recipe may no longer change (but for [export])
        first.finish(stage, tmp_path, [out])
    new_key = {"recipe": {**old_key["recipe"], "model_sha256": "model-1"}, "export": {"half_weights": False},
               "ks": [8]}
    edited = {"recipe": {**new_key["recipe"], "content_sha256": "with-export-2"}, "export": {"half_weights": True},
              "ks": [8]}
    with pytest.raises(DiviewerError, match="another plan .*recipe"):
        BuildState(tmp_path / "build.json", edited)
    dry = BuildState(tmp_path / "build.json", new_key)
    assert dry.done("capture", tmp_path) is not None
    assert json.loads((tmp_path / "build.json").read_text())["plan"] == old_key, "a dry run writes nothing"
    BuildState(tmp_path / "build.json", new_key, save_upgrade=True)
    assert json.loads((tmp_path / "build.json").read_text())["plan"] == new_key
    again = BuildState(tmp_path / "build.json", edited)
    assert again.export_change == ({"half_weights": False}, {"half_weights": True})
    assert again.done("capture", tmp_path) is not None


def test_the_recipe_is_the_same_plan_when_only_its_comments_changed(tmp_path):
    out = tmp_path / "a.txt"
    out.write_text("one")
    recipe = {"name": "cornell", "sha256": "bytes-1", "content_sha256": "values-1"}

    def trained(path: Path, key: dict) -> None:  # a K trained: another recipe is another build from then on
        state = BuildState(path, key)
        for stage in ("capture", "train_k8"):
            state.finish(stage, tmp_path, [out])

    trained(tmp_path / "build.json", {"recipe": recipe})
    comment = BuildState(tmp_path / "build.json", {"recipe": {**recipe, "sha256": "bytes-2"}})
    assert comment.done("capture", tmp_path) is not None
    with pytest.raises(DiviewerError, match="another plan .*recipe"):
        BuildState(tmp_path / "build.json", {"recipe": {**recipe, "content_sha256": "values-2"}})
    # a state file written before the content was hashed: the same bytes are the same recipe, and it is upgraded
    old = tmp_path / "old" / "build.json"
    trained(old, {"recipe": {"name": "cornell", "sha256": "bytes-1"}})
    with pytest.raises(DiviewerError, match="another plan .*recipe"):
        BuildState(old, {"recipe": {**recipe, "sha256": "bytes-2"}})
    upgraded = BuildState(old, {"recipe": recipe})
    assert upgraded.done("capture", tmp_path) is not None and upgraded.data["plan"]["recipe"] == recipe

needs_pipeline = pytest.mark.skipif(any(importlib.util.find_spec(m) is None for m in ("torch", "mitsuba", "onnx")),
                                    reason="the pipeline needs the train extra: pip install 'diviewer[train]'")


@pytest.mark.slow
@needs_pipeline
def test_build_a_tiny_scene_killed_and_resumed(gl_context, tmp_path, capsys):
    """The whole pipeline shrunk: killed (SIGKILL) once the capture is recorded, resumed to the shipped model,
    then run again with nothing left to do."""
    from diviewer.contract.runtime import read_metadata

    scene, recipe = write_tiny_scene(tmp_path), tmp_path / "tinyrecipe.toml"
    recipe.write_text(TINY_RECIPE)
    work, ship = tmp_path / "work", tmp_path / "ship"
    argv = ["build", "--scene", str(scene), "--recipe", str(recipe), "--work", str(work), "--ship", str(ship)]
    proc = subprocess.Popen([sys.executable, "-m", "diviewer", *argv], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    state = work / "build.json"
    try:
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline and proc.poll() is None:
            if state.is_file() and "capture" in json.loads(state.read_text())["stages"]:
                os.killpg(proc.pid, signal.SIGKILL)
                break
            time.sleep(0.05)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, "killed after its capture was recorded, before the end"
    frames = {p: p.stat().st_mtime_ns for p in (work / "data" / "frames").glob("*.npy")}
    assert len(frames) == 8
    recorded = json.loads(state.read_text())["stages"]
    assert "ship" not in recorded

    capsys.readouterr()
    assert main([*argv, "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert [line.split()[1] for line in out.splitlines() if line.split()[2:3] == ["done"]][:1] == ["capture"]
    assert "left (stages done in" in out
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "capture: done before, outputs checked; skipped" in out
    assert {p: p.stat().st_mtime_ns for p in (work / "data" / "frames").glob("*.npy")} == frames, "not rendered again"

    card = json.loads((ship / "tiny.json").read_text())
    assert read_metadata(ship / "tiny.onnx") == card, "the card beside the model is the model's own metadata"
    ladder = json.loads((ship / "tiny_ladder.json").read_text())
    assert card["K"] == ladder["chosen_K"] in (2, 4) and [r["K"] for r in ladder["rows"]] == [2, 4]
    assert card["ladder"]["chosen_K"] == card["K"] and card["ladder"]["file"] == "tiny_ladder.json"
    assert card["rebuild"].startswith("diviewer build --scene ") and "--recipe" in card["rebuild"]
    rec = card["recipe"]["train"]["recipe"]
    assert rec["name"] == "tinyrecipe" and rec["sha256"] == load_recipe(recipe).sha256
    assert rec["overrides"] == ({"K": 4} if card["K"] == 4 else {})
    assert (ship / "tiny_curves.png").is_file() and (ship / "tiny_metrics.csv").is_file()
    assert card["ladder"]["curves"] == "tiny_ladder_curves.png" and (ship / "tiny_ladder_curves.png").is_file()
    for r in ladder["rows"]:
        # the scene camera's splits and, as every evaluation set has them now, 4:3 and 16:9 at the model's rows
        assert set(r["evalset"]) == {"unseen_configs", "unseen_objects", "window_shapes_42x32", "window_shapes_56x32"}
        assert r["steps"] == 2
    # the pick reads the evaluation set's truth, every frame of it, as the bench does
    by_k = {r["K"]: r["evalset_psnr_tm"] for r in ladder["rows"]}
    assert ladder["measure"] == "evalset_psnr_tm" and "over the evaluation set" in ladder["rule"]
    assert ladder["chosen_K"] == min(k for k, v in by_k.items() if v >= max(by_k.values()) - 0.5)

    assert main(argv) == 0  # nothing left to do: every stage skipped after its outputs are checked
    out = capsys.readouterr().out
    assert out.count("done before, outputs checked; skipped") == 10

    # the recipe's [export] edited: each K exported again with its weights stored as float16, nothing trained
    ckpts = {p: p.stat().st_mtime_ns for p in work.glob("train_k*/best.ckpt")}
    recipe.write_text(TINY_RECIPE.replace("fp16 = false\n", "fp16 = false\nhalf_weights = true\n"))
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "the recipe's [export] changed (half_weights False -> True)" in out
    assert "train_k2: done before" in out and "train_k4: done before" in out
    assert {p: p.stat().st_mtime_ns for p in work.glob("train_k*/best.ckpt")} == ckpts
    assert json.loads((ship / "tiny.json").read_text())["weights"] == "fp16"

    # A second build scored on the first's evaluation set (--evalset): checked, never rendered into its own folder;
    # the card's rebuild command names it. One of another scene file is refused before any stage runs.
    work2, ship2 = tmp_path / "work2", tmp_path / "ship2"
    argv2 = ["build", "--scene", str(scene), "--recipe", str(recipe), "--work", str(work2), "--ship", str(ship2),
             "--ks", "2", "--evalset", str(work / "evalset")]
    assert main(argv2) == 0
    out = capsys.readouterr().out
    assert "evaluation set made before" in out and "not rendered again" in out
    assert not (work2 / "evalset").exists()
    ladder2 = json.loads((ship2 / "tiny_ladder.json").read_text())
    assert set(ladder2["rows"][0]["evalset"]) == set(ladder["rows"][0]["evalset"])
    assert json.loads((ship2 / "tiny.json").read_text())["rebuild"].endswith(f"--evalset {work / 'evalset'}")
    # The second build shipped to the first's folder: the model there is the first build's, not its own. It is scored
    # on the same evaluation set by the ladder's own code (the first ladder's figure for that model), and replaced
    # only where the new one scores at least as well, or with --replace-worse; the replaced files are kept.
    old_score, new_score = by_k[ladder["chosen_K"]], ladder2["rows"][0]["evalset_psnr_tm"]
    argv3 = [*argv2[:argv2.index("--ship") + 1], str(ship), *argv2[argv2.index("--ship") + 2:]]
    shipped = (ship / "tiny.onnx").read_bytes()
    rc = main(argv3)
    out, err = capsys.readouterr()
    assert f"the new K = 2 scores {new_score:.2f} dB against {old_score:.2f} dB" in out, out
    if new_score < old_score:
        assert rc == 2 and "scores worse than the one it would replace" in err and "nothing replaced" in err
        assert (ship / "tiny.onnx").read_bytes() == shipped and (work2 / "models" / "tiny_k2.onnx").is_file()
        assert main([*argv3, "--replace-worse"]) == 0
        capsys.readouterr()
    else:
        assert rc == 0
    assert (ship / "tiny.onnx").read_bytes() != shipped
    kept = next((work2 / "replaced").iterdir())
    assert (kept / "tiny.onnx").read_bytes() == shipped and (kept / "tiny_ladder.json").is_file()
    replaced = json.loads((work2 / "build.json").read_text())["stages"]["ship"]["result"]["replaced"]
    assert replaced["evalset_psnr_tm"] == pytest.approx(old_score, abs=1e-3) and replaced["kept_in"] == str(kept)
    assert main(argv3) == 0, "its own model now: shipped again without a comparison"
    assert "ship: done before" in capsys.readouterr().out

    cornell_set = Path(__file__).resolve().parents[2] / "assets" / "evalsets" / "cornell"
    assert main([*argv2[:-1], str(cornell_set), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert "cornell/manifest.json: scene_hash: this evaluation set was made for another scene file" in err
    assert main([*argv2[:-1], str(tmp_path / "nothing"), "--dry-run"]) == 2
    assert "nothing: --evalset: no evaluation set here" in capsys.readouterr().err

    # `diviewer train --recipe` on the build's data records the recipe in the checkpoint
    from diviewer.train.checkpoint import load_checkpoint

    run = tmp_path / "run"
    assert main(["train", "--data", str(work / "data"), "--out", str(run), "--recipe", str(recipe), "--k", "4",
                 "--max-steps", "1"]) == 0
    cfg = load_checkpoint(run / "last.ckpt")["config"]
    assert cfg["K"] == 4 and cfg["recipe"]["name"] == "tinyrecipe" and cfg["recipe"]["overrides"] == {"K": 4}


@pytest.mark.slow
@needs_pipeline
def test_a_build_stops_after_the_stage_asked_and_the_same_command_goes_on(gl_context, tmp_path, capsys):
    """`--stop-after check`: the data rendered and checked, nothing trained; the same command without it resumes
    from the next stage with the capture kept."""
    scene, recipe = write_tiny_scene(tmp_path), tmp_path / "tinyrecipe.toml"
    recipe.write_text(TINY_RECIPE.replace("K = [2, 4]", "K = [2]"))
    work = tmp_path / "work"
    argv = ["build", "--scene", str(scene), "--recipe", str(recipe), "--work", str(work), "--ship", str(tmp_path / "s")]
    assert main([*argv, "--stop-after", "check"]) == 0
    out = capsys.readouterr().out
    assert "stopped after check as asked (--stop-after); the same command without it goes on from evalset" in out
    assert set(json.loads((work / "build.json").read_text())["stages"]) == {"capture", "check"}
    frames = {p: p.stat().st_mtime_ns for p in (work / "data" / "frames").glob("*.npy")}
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "capture: done before, outputs checked; skipped" in out and "stopped after" not in out
    assert {p: p.stat().st_mtime_ns for p in (work / "data" / "frames").glob("*.npy")} == frames
    assert "ship" in json.loads((work / "build.json").read_text())["stages"]


def _refining(recipe: str, low: int, spp: int) -> str:
    """TINY_RECIPE (or another) captured at ``low`` spp and refined to ``spp``."""
    return recipe.replace("spp = 2\nmax_depth = 3\nsplit_fractions",
                          f"spp = {spp}\nrefine_from = {low}\nmax_depth = 3\nsplit_fractions", 1)


def test_a_recipe_that_refines_its_capture_plans_the_capture_at_the_lower_count_then_the_refinement(tmp_path):
    """[capture] refine_from: the capture at that count into WORK/data, a refine stage to the recipe's spp into
    WORK/data_<spp>spp, which the trainings read; the plan's key says so (a build without it keeps its key)."""
    from diviewer.builder.pipeline import plan_key

    (tmp_path / "r.toml").write_text(_refining(TINY_RECIPE, 2, 8))
    plan = make_plan("cornell", load_recipe(tmp_path / "r.toml"), tmp_path / "w", machine=CPU)
    assert [s.name for s in plan.stages][:4] == ["capture", "refine", "check", "evalset"]
    assert plan.capture.spp == 2 and plan.refine_spp == 8
    assert plan.capture_dir == tmp_path / "w" / "data" and plan.data == tmp_path / "w" / "data_8spp"
    assert plan.train_fields(2)["data"] == plan.data
    refine = next(s for s in plan.stages if s.name == "refine")
    assert refine.seconds == pytest.approx(costs.refine_seconds("cpu", "cornell", 8, 32, 32, 6))
    assert plan_key(plan)["refine_spp"] == 8
    (tmp_path / "t.toml").write_text(TINY_RECIPE)
    plain = make_plan("cornell", load_recipe(tmp_path / "t.toml"), tmp_path / "w", machine=CPU)
    assert "refine_spp" not in plan_key(plain) and plain.data == plain.capture_dir and plain.refine_spp is None


def test_a_capture_folder_that_links_to_a_set_not_yet_made_is_refused_not_captured_through(tmp_path, capsys):
    """A build's data/ linked to another build's refined set before that set exists: a run of the later build then must not capture at its refine_from spp through the link (hours, into the
    other build's folder); the dry run says so, and the run stops on one line naming the link, having made nothing."""
    (tmp_path / "r.toml").write_text(_refining(TINY_RECIPE, 2, 8))
    work, later = tmp_path / "w", tmp_path / "other" / "data_2spp"
    work.mkdir()
    (work / "data").symlink_to(later)
    argv = ["build", "--scene", "cornell", "--recipe", str(tmp_path / "r.toml"), "--work", str(work)]
    assert main(argv + ["--dry-run"]) == 0
    out = capsys.readouterr().out
    assert f"capture: {work / 'data'} links to {later}, which is not there: a run refuses it" in out
    assert main(argv) == 2
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert str(work / "data") in line and "which is not there" in line and "remove the link" in line, line
    assert not later.exists() and not (tmp_path / "other").exists()


def test_a_refinement_under_way_tells_this_machines_pace(tmp_path):
    """The frames refined so far (each sidecar's ``refined.seconds``) give the refinement's pace and its time left,
    listed after the capture's; a plan without a refine stage says nothing of it."""
    from diviewer.builder.pace import measured_pace, refine_pace
    from diviewer.builder.plan import hms

    (tmp_path / "r.toml").write_text(_refining(TINY_RECIPE, 2, 8))
    plan = make_plan("cornell", load_recipe(tmp_path / "r.toml"), tmp_path / "w", machine=CPU)
    assert refine_pace(plan) is None  # nothing refined yet
    frames = plan.data / "frames"
    frames.mkdir(parents=True)
    (plan.data / "manifest.json").write_text("{}")
    for i, s in enumerate([3.0, 5.0, 40.0]):
        (frames / f"{i:06d}.json").write_text(json.dumps({"index": i, "refined": {"seconds": s}}))
    pace = refine_pace(plan)
    line, left = pace.line, plan.capture.frames - 3
    assert line.startswith(f"refine so far: 3 of {plan.capture.frames} frames") and "5.0 s a frame here" in line
    assert f"the {left} left take ~{hms(left * 5.0)} at that pace" in line and pace in measured_pace(plan)
    assert pace.stage == "refine" and pace.left == left * 5.0
    (tmp_path / "t.toml").write_text(TINY_RECIPE)
    assert refine_pace(make_plan("cornell", load_recipe(tmp_path / "t.toml"), tmp_path / "w", machine=CPU)) is None


def test_a_refinement_not_begun_is_paced_from_the_captures_path_tracing_here(tmp_path):
    """Before its first frame the refinement's pace is the capture's path tracing on this machine (each sidecar's
    ``gt`` seconds over the capture's spp, or a refined capture's ``refined`` seconds over its samples; median), times
    the samples a frame it adds; frames traced by another kind of variant (a CUDA device's on a CPU) are left out."""
    from diviewer.builder.pace import refine_pace

    (tmp_path / "r.toml").write_text(_refining(TINY_RECIPE, 2, 8))
    plan = make_plan("cornell", load_recipe(tmp_path / "r.toml"), tmp_path / "w", machine=CPU)
    frames, n = plan.capture_dir / "frames", plan.capture.frames
    frames.mkdir(parents=True)
    (plan.capture_dir / "manifest.json").write_text("{}")
    assert refine_pace(plan) is None  # no frame captured: nothing to pace from
    for i, (variant, gt) in enumerate([("llvm_ad_rgb", 2.0), ("llvm_ad_rgb", 4.0), ("llvm_ad_rgb", 100.0),
                                       ("cuda_ad_rgb", 0.5)]):
        (frames / f"{i:06d}.json").write_text(json.dumps({"index": i, "variant": variant,
                                                          "seconds": {"gl": 0.5, "gt": gt}}))
    pace = refine_pace(plan)  # 4.0 s for 2 spp: 2 s a sample, 6 samples a frame to add
    assert pace.stage == "refine" and pace.left == pytest.approx(n * 12.0)
    assert pace.line.startswith("refine not begun: ~12.0 s a frame here") and f"the {n} frames take" in pace.line
    cuda = make_plan("cornell", load_recipe(tmp_path / "r.toml"), tmp_path / "w", machine=CUDA)
    assert refine_pace(cuda).left == pytest.approx(n * 1.5)  # its own variant's frame alone
    for i in range(4):  # a capture that is itself a refinement: its refinement's seconds over its samples
        (frames / f"{i:06d}.json").write_text(json.dumps({"index": i, "variant": "llvm_ad_rgb",
                                                          "seconds": {"gl": 0.5, "gt": 1.0},
                                                          "refined": {"variant": "llvm_ad_rgb", "seconds": 9.0,
                                                                      "extra_spp": 3}}))
    assert refine_pace(plan).left == pytest.approx(n * 18.0)
    (plan.data / "frames").mkdir(parents=True)  # the first refined frame: its own pace from then on
    (plan.data / "manifest.json").write_text("{}")
    (plan.data / "frames" / "000000.json").write_text(json.dumps({"index": 0, "refined": {"seconds": 5.0}}))
    assert refine_pace(plan).line.startswith(f"refine so far: 1 of {n} frames")


@pytest.mark.slow
def test_build_a_tiny_scene_that_refines_its_capture(gl_context, tmp_path, capsys):
    """The pipeline with a refinement: the capture at 2 spp (made before, linked in: not rendered again), refined
    to 6, the model trained on the refined truth; its card's capture record reads back as the recipe's [capture]
    table (refine_from included)."""
    from diviewer.data.dataset import Dataset

    from diviewer.data.capture import capture
    from diviewer.train.recipe import capture_settings

    scene, recipe = write_tiny_scene(tmp_path), tmp_path / "tinyrecipe.toml"
    recipe.write_text(_refining(TINY_RECIPE, 2, 6).replace("K = [2, 4]", "K = [2]"))
    # the capture at 2 spp made before (by a build at 2 spp, say): the refining build's data/ links to it
    first = tmp_path / "first" / "data"
    capture(str(scene), first, capture_settings(load_recipe(recipe), spp=2), log=lambda *_: None)
    rendered = {p: p.stat().st_mtime_ns for p in (first / "frames").glob("*.npy")}
    work, ship = tmp_path / "work", tmp_path / "ship"
    work.mkdir()
    (work / "data").symlink_to(first, target_is_directory=True)
    assert main(["build", "--scene", str(scene), "--recipe", str(recipe), "--work", str(work), "--ship",
                 str(ship)]) == 0
    assert {p: p.stat().st_mtime_ns for p in (first / "frames").glob("*.npy")} == rendered, "not rendered again"
    captured, refined = Dataset(work / "data"), Dataset(work / "data_6spp")
    assert captured.manifest["spp"] == 2 and refined.manifest["spp"] == 6 and refined.check() == []
    assert refined.manifest["refined"]["from_hash"] == captured.hash
    card = json.loads((ship / "tiny.json").read_text())
    assert card["dataset_hash"] == refined.hash
    first_step = json.loads(refined.path(refined.indices()[0], ".json").read_text())["refined"]
    held = first_step["from_spp"] + first_step["extra_spp"]
    assert card["truth_spp"] == {"min": held, "max": held} and held >= 6  # the samples its truth really holds
    cap = card["recipe"]["capture"]
    assert cap["spp"] == 6 and cap["refine_from"] == 2
    assert {k: cap[k] for k in load_recipe(recipe).capture if k in cap} == {
        k: (list(v) if isinstance(v, tuple) else v) for k, v in load_recipe(recipe).capture.items() if k in cap}

    # refined again (6 spp to 12: Sponza's 256 to 512): a build whose data/ links to the refined set takes it for
    # the capture at 6, renders none of it, and weighs each frame by its own effective count (2 + 4, not 6)
    again, more = tmp_path / "again", tmp_path / "more.toml"
    more.write_text(_refining(TINY_RECIPE, 6, 12).replace("K = [2, 4]", "K = [2]"))
    again.mkdir()
    (again / "data").symlink_to(work / "data_6spp", target_is_directory=True)
    kept = {p: p.stat().st_mtime_ns for p in (work / "data_6spp" / "frames").glob("*.npy")}
    assert main(["build", "--scene", str(scene), "--recipe", str(more), "--work", str(again), "--ks", "2"]) == 0
    assert {p: p.stat().st_mtime_ns for p in (work / "data_6spp" / "frames").glob("*.npy")} == kept
    twice = Dataset(again / "data_12spp")
    assert twice.manifest["spp"] == 12 and twice.check() == []
    assert twice.manifest["refined"]["from_hash"] == refined.hash
    assert twice.manifest["refined"]["before"] == refined.manifest["refined"]
    for i in twice.indices():
        step = json.loads(twice.path(i, ".json").read_text())["refined"]
        first_step = json.loads(refined.path(i, ".json").read_text())["refined"]
        assert step["before"] == first_step and step["from_spp"] == first_step["from_spp"] + first_step["extra_spp"]
    state = json.loads((again / "build.json").read_text())["stages"]
    assert state["capture"]["result"]["present"] == 8 and list(state["capture"]["outputs"]) == ["data/manifest.json"]
    # a refined set of other settings, or with frames missing, is refused by name
    other = tmp_path / "other.toml"
    other.write_text(_refining(TINY_RECIPE, 6, 12).replace("max_depth = 3\nsplit", "max_depth = 4\nsplit", 1))
    for name in ("third", "fourth"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "data").symlink_to(work / "data_6spp", target_is_directory=True)
    capsys.readouterr()
    assert main(["build", "--scene", str(scene), "--recipe", str(other), "--work", str(tmp_path / "third")]) == 2
    assert "a refined dataset of other settings is there (differs in: max_depth)" in capsys.readouterr().err
    next(iter(sorted((work / "data_6spp" / "frames").glob("*.npy")))).unlink()
    assert main(["build", "--scene", str(scene), "--recipe", str(more), "--work", str(tmp_path / "fourth")]) == 2
    assert "1 of its 8 frames missing: refine them first" in capsys.readouterr().err


def _filtering(recipe: str, table: str = "{ levels = 1 }") -> str:
    """TINY_RECIPE (or another) with its truth filtered before training ([capture] truth_filter)."""
    return recipe.replace("max_depth = 3\nsplit_fractions", f"truth_filter = {table}\nmax_depth = 3\nsplit_fractions", 1)


def test_a_recipe_that_filters_its_truth_plans_the_filter_after_the_refinement_and_trains_on_its_output(tmp_path):
    """[capture] truth_filter: a filter stage from the truth as rendered (the capture, or its refinement) into
    WORK/data_<spp>spp_filtered, which the trainings read; the plan's key records the settings; a bad table is refused
    when the recipe is read, naming the field."""
    from diviewer.builder.pipeline import plan_key

    (tmp_path / "r.toml").write_text(_filtering(_refining(TINY_RECIPE, 2, 8)))
    plan = make_plan("cornell", load_recipe(tmp_path / "r.toml"), tmp_path / "w", machine=CPU)
    assert [s.name for s in plan.stages][:5] == ["capture", "refine", "filter", "check", "evalset"]
    assert plan.truth_dir == tmp_path / "w" / "data_8spp" and plan.data == tmp_path / "w" / "data_8spp_filtered"
    assert plan.train_fields(2)["data"] == plan.data
    assert plan_key(plan)["truth_filter"] == {"levels": 1, "normal_power": 32.0, "plane": 0.01}
    (tmp_path / "c.toml").write_text(_filtering(TINY_RECIPE, "{ levels = 2, plane = 0.02 }"))
    plan = make_plan("cornell", load_recipe(tmp_path / "c.toml"), tmp_path / "w", machine=CPU)
    assert [s.name for s in plan.stages][:3] == ["capture", "filter", "check"]
    assert plan.truth_dir == plan.capture_dir and plan.data == tmp_path / "w" / "data_2spp_filtered"
    assert next(s for s in plan.stages if s.name == "filter").seconds == pytest.approx(
        8 * 2 * costs.FILTER_FRAME_SECONDS)
    (tmp_path / "g.toml").write_text(_filtering(TINY_RECIPE, "{ levels = 2, range_sigma = 0.6 }"))
    plan = make_plan("cornell", load_recipe(tmp_path / "g.toml"), tmp_path / "w", machine=CPU)
    stage = next(s for s in plan.stages if s.name == "filter")  # the range term's guide: one level more
    assert "a range term" in stage.title and stage.seconds == pytest.approx(8 * 3 * costs.FILTER_FRAME_SECONDS)
    assert plan_key(plan)["truth_filter"] == {"levels": 2, "normal_power": 32.0, "plane": 0.01, "range_sigma": 0.6}
    (tmp_path / "bad.toml").write_text(_filtering(TINY_RECIPE, "{ levels = 0 }"))
    with pytest.raises(DiviewerError) as err:
        load_recipe(tmp_path / "bad.toml")
    assert "bad.toml" in str(err.value) and "capture.truth_filter.levels" in str(err.value)


@pytest.mark.slow
def test_build_a_tiny_scene_on_a_filtered_truth(gl_context, tmp_path, capsys):
    """The pipeline with the truth filtered: the model trains on the filtered set; its card's capture record reads
    back as the recipe's [capture] table (truth_filter included), and `diviewer eval` reports no margin read from
    the set's unfiltered ladder for it."""
    from diviewer.data.dataset import Dataset
    from diviewer.evaluation.truthmargin import FILTERED_MARGIN

    scene, recipe = write_tiny_scene(tmp_path), tmp_path / "tinyrecipe.toml"
    recipe.write_text(_filtering(TINY_RECIPE).replace("K = [2, 4]", "K = [2]"))
    work, ship = tmp_path / "work", tmp_path / "ship"
    assert main(["build", "--scene", str(scene), "--recipe", str(recipe), "--work", str(work), "--ship",
                 str(ship)]) == 0
    captured, filtered = Dataset(work / "data"), Dataset(work / "data_2spp_filtered")
    assert filtered.check() == [] and filtered.manifest["truth_filter"]["from_hash"] == captured.hash
    card = json.loads((ship / "tiny.json").read_text())
    assert card["dataset_hash"] == filtered.hash
    assert card["recipe"]["capture"]["truth_filter"] == {"levels": 1, "normal_power": 32.0, "plane": 0.01}
    scores = json.loads((work / "evalset_eval.json").read_text())
    for split in scores["splits"].values():  # what measures it instead, named; no figure read from the ladder
        assert split["methods"]["tiny_k2"]["truth_margin"] == {
            "truth_filter": {"levels": 1, "normal_power": 32.0, "plane": 0.01}, "from": FILTERED_MARGIN}
    assert "its training truth was filtered; the set's ladder is not filtered" in capsys.readouterr().out
    state = json.loads((work / "build.json").read_text())["stages"]
    assert state["filter"]["result"]["present"] == 8 and state["filter"]["result"]["levels"] == 1
