"""What a build's work folder says of its progress (`diviewer.builder.pace`): the pace of a capture and a training
under way, and whether a complete capture there is taken."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from diviewer.builder import costs
from diviewer.builder.plan import hms, make_plan
from diviewer.data.capture import build_manifest
from diviewer.scene.loader import load_scene
from diviewer.train.recipe import load_recipe

CPU = costs.Machine("cpu", 2, "the test's machine")


def test_a_capture_under_way_tells_this_machines_pace(tmp_path):
    """The frames captured so far (their sidecars' GL and path-tracing seconds) give this machine's pace and the
    capture's time left at it; nothing is said before the first frame, and once every frame is there, that a run
    renders none."""
    from diviewer.builder.pace import capture_pace

    plan = make_plan("cornell", load_recipe("cornell"), tmp_path, machine=CPU)
    assert capture_pace(plan) is None  # no capture yet
    frames = plan.data / "frames"
    frames.mkdir(parents=True)
    done = dataclasses.replace(plan, capture=dataclasses.replace(plan.capture, frames=4))
    (plan.data / "manifest.json").write_text(json.dumps(build_manifest(load_scene("cornell"), done.capture)))
    for i, (gl, gt) in enumerate([(0.5, 9.5), (0.5, 11.5), (0.5, 99.5)]):
        (frames / f"{i:06d}.json").write_text(json.dumps({"index": i, "seconds": {"gl": gl, "gt": gt}}))
    (frames / "000003.json").write_text("{")  # a sidecar being written: left out
    pace = capture_pace(plan)
    line, left = pace.line, plan.capture.frames - 4
    assert pace.stage == "capture" and pace.left == left * 12.0
    assert line.startswith(f"capture so far: 4 of {plan.capture.frames} frames") and "12.0 s a frame here" in line
    assert f"the {left} left take ~{hms(left * 12.0)} at that pace" in line
    assert capture_pace(done).line == (f"capture: all 4 frames already in {plan.data}; its settings are the recipe's: a "
                                  f"run renders none")  # every frame there: nothing left to pace
    assert capture_pace(done).done and not pace.done  # complete and the recipe's: a dry run counts it done
    other = dataclasses.replace(done.capture, spp=done.capture.spp + 1)
    (plan.data / "manifest.json").write_text(json.dumps(build_manifest(load_scene("cornell"), other)))
    assert capture_pace(done).line == (f"capture: all 4 frames already in {plan.data}; but a run refuses it: it is not "
                                  f"the recipe's capture (differs in: spp)")
    assert not capture_pace(done).done
    # a refinement linked in as the capture (runs/sponza512/data -> the 256-spp set): complete or not, nothing to pace;
    # its refined record is no difference, its settings are
    refined = {**build_manifest(load_scene("cornell"), done.capture), "refined": {"from_spp": 2}}
    (plan.data / "manifest.json").write_text(json.dumps(refined))
    assert capture_pace(done).line == (f"capture: {plan.data} is the capture at 2 spp refined to {plan.capture.spp}, "
                                  f"complete: a run takes it for the capture and renders none")
    (plan.data / "manifest.json").write_text(json.dumps({**refined, "max_depth": 9}))
    assert capture_pace(done).line == (f"capture: {plan.data} is the capture at 2 spp refined to {plan.capture.spp}, "
                                  f"complete, but a run refuses it: it is not the recipe's capture (differs in: "
                                  f"max_depth)")
    assert capture_pace(plan).line.endswith(f"4 of {plan.capture.frames} frames: a run refuses it until the rest are "
                                       f"refined")


def test_a_training_under_way_tells_this_machines_pace(tmp_path):
    """A run's metrics.csv (cumulative seconds, resumes included) gives the pace of a build's training and its time
    left; the plan lists it after the capture's."""
    from diviewer.builder.pace import measured_pace, training_pace

    plan = make_plan("cornell", load_recipe("cornell"), tmp_path, machine=CPU)
    metrics = plan.run_dir(8) / "metrics.csv"
    assert training_pace(metrics, 8, plan.steps, 1.0) is None and measured_pace(plan) == []  # nothing started
    metrics.parent.mkdir(parents=True)
    metrics.write_text("epoch,step,val_psnr,seconds\n0.1,500,30.1,150.0\n0.2,1000,31.0,300.0\n")
    pace = training_pace(metrics, 8, plan.steps, 2.0 * plan.steps)
    assert pace.stage == "train_k8" and pace.left == pytest.approx((plan.steps - 1000) * 0.3)
    assert pace.line == (f"train K=8 so far: step 1000 of {plan.steps}, 0.30 s a step here (validations included); the rest "
                    f"take ~{hms((plan.steps - 1000) * 0.3)} at that pace (the plan assumes 2.00 s)")
    assert measured_pace(plan)[0] == training_pace(metrics, 8, plan.steps, plan.stages[3].seconds)
    assert [p.stage for p in measured_pace(plan)] == ["train_k8"] + [f"train_k{k}" for k in plan.ks[1:]]
    assert training_pace(metrics, 8, 1000, 1.0) is None  # done
    metrics.write_text("epoch,step,val_psnr,seconds\n")
    assert training_pace(metrics, 8, plan.steps, 1.0) is None  # a header alone


def test_a_k_not_begun_is_paced_from_the_k_measured_here_nearest_to_it(tmp_path):
    """A K whose training has not begun takes the measured pace of the nearest K in width that has run at least
    MIN_PACE_STEPS steps (done or under way), scaled by the plan's ratio of their costs; fewer steps, or none
    measured, and it has no pace (the plan's estimate stands)."""
    from diviewer.builder.pace import MIN_PACE_STEPS, measured_pace, scaled_training_pace

    plan = make_plan("cornell", load_recipe("cornell"), tmp_path, machine=CPU, ks=(8, 16, 32))
    seconds = {s.name: s.seconds for s in plan.stages}
    metrics = plan.run_dir(16) / "metrics.csv"
    metrics.parent.mkdir(parents=True)
    metrics.write_text(f"epoch,step,val_psnr,seconds\n0.1,{MIN_PACE_STEPS - 1},30.1,100.0\n")
    assert [p.stage for p in measured_pace(plan)] == ["train_k16"]  # too few steps to stand for the others
    metrics.write_text("epoch,step,val_psnr,seconds\n0.1,500,30.1,150.0\n0.2,1000,31.0,400.0\n")
    paces = {p.stage: p for p in measured_pace(plan)}
    assert sorted(paces) == ["train_k16", "train_k32", "train_k8"]
    for k in (8, 32):
        ratio = seconds[f"train_k{k}"] / seconds["train_k16"]
        assert paces[f"train_k{k}"].left == pytest.approx(plan.steps * 0.4 * ratio)
        assert paces[f"train_k{k}"].line == (
            f"train K={k} not begun: ~{0.4 * ratio:.2f} s a step here, K=16's 0.40 s measured over 1000 steps times "
            f"the plan's cost ratio of the two ({ratio:.2f}); ~{hms(plan.steps * 0.4 * ratio)} at that pace (the plan "
            f"assumes {seconds[f'train_k{k}'] / plan.steps:.2f} s)")
    # a done K counts too, and the nearest in width is taken (K = 8 for 16, not 32; a tie goes to the narrower)
    done = plan.run_dir(8) / "metrics.csv"
    done.parent.mkdir(parents=True)
    done.write_text(f"epoch,step,val_psnr,seconds\n1.0,{plan.steps},33.0,{0.1 * plan.steps}\n")
    metrics.unlink()
    k16 = {p.stage: p for p in measured_pace(plan)}["train_k16"]
    assert k16.line.startswith(f"train K=16 not begun: ~{0.1 * seconds['train_k16'] / seconds['train_k8']:.2f} s a "
                               f"step here, K=8's 0.10 s measured over {plan.steps} steps")
    two = {8: (100, 10.0, 4.0), 16: (100, 30.0, 6.0)}  # K = 12 is nearer 16 (log ratio): 0.30 s x 5 / 6, 10 steps
    assert scaled_training_pace(12, 10, 5.0, two).left == pytest.approx(2.5)
    assert "K=2's" in scaled_training_pace(4, 10, 5.0, {2: (100, 10.0, 4.0), 8: (100, 30.0, 6.0)}).line  # a tie
    assert scaled_training_pace(8, 10, 5.0, {}) is None


def test_the_plan_counts_a_stage_under_way_at_this_machines_pace():
    """The time left counts a stage under way at its measured pace, the others at the plan's estimate; without a
    measured stage the line is not there."""
    from diviewer.builder.plan import describe

    plan = make_plan("cornell", load_recipe("cornell"), Path("w"), machine=CPU)
    assert not any(line.startswith("left with") for line in describe(plan, {"capture"}))
    lines = describe(plan, {"capture"}, {"train_k8": 600.0, "capture": 5.0})
    rest = sum(s.seconds for s in plan.stages if s.name not in ("capture", "train_k8"))
    assert lines[-1] == (f"left with train_k8 at this machine's measured pace (below) and the rest as estimated: "
                         f"~{hms(600.0 + rest)}")
