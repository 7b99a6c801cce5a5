"""The evaluation set (resumable, apart from training data) and `diviewer eval` on it: every row, strict JSON."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from diviewer.cli import main
from diviewer.data.capture import CaptureSettings, plan_frames
from diviewer.data.dataset import Dataset
from diviewer.errors import DiviewerError
from diviewer.evalset import EVAL_SPLITS, EvalSetSettings, build_evalset, configs_apart, plan_evalset
from diviewer.scene import load_scene

from onnx_models import base_meta, direct_times

TINY = EvalSetSettings(frames_per_split=2, width=16, height=16, spp=16, ladder=(1, 4), max_depth=4, thumbs=1)


def quiet(*_):
    pass


def _center_mesh(f: dict) -> str:
    return next(o["mesh"] for o in f["config"]["objects"] if o["name"] == "center")


@pytest.mark.slow
def test_plan_is_reproducible_split_by_objects_and_apart_from_captures():
    scene = load_scene("cornell")
    plan = plan_evalset(scene, EvalSetSettings(frames_per_split=24))
    assert plan == plan_evalset(scene, EvalSetSettings(frames_per_split=24))
    assert [f["index"] for f in plan] == list(range(48))
    r = scene.ranges.objects["center"]
    for split, meshes in zip(EVAL_SPLITS, (r.train_meshes, r.test_meshes)):
        frames = [f for f in plan if f["split"] == split]
        assert len(frames) == 24 and all(_center_mesh(f) in meshes for f in frames)
    seeds = [s for f in plan for s in (f["pt_seeds"]["reference"], f["pt_seeds"]["second"], *f["pt_seeds"]["ladder"])]
    assert len(set(seeds)) == len(seeds), "every render of the set has a seed of its own"
    # a capture with the same base seed draws other configurations (its own seed stream)
    for seed in (0, 1):
        capture_plan = plan_frames(scene, CaptureSettings(frames=500, seed=seed))
        assert configs_apart(plan, capture_plan)
    assert plan_evalset(scene, EvalSetSettings(frames_per_split=24, seed=1)) != plan


def test_bad_settings_are_refused():
    with pytest.raises(DiviewerError, match="ladder"):
        EvalSetSettings(spp=64, ladder=(1, 256)).check()
    with pytest.raises(DiviewerError, match="16x16"):
        EvalSetSettings(width=8).check()


@pytest.fixture(scope="module")
def evalset(tmp_path_factory, gl_context):
    pytest.importorskip("mitsuba")
    out = tmp_path_factory.mktemp("evalset") / "cornell"
    summary = build_evalset("cornell", out, TINY, log=quiet)
    return out, summary


@pytest.mark.mitsuba
@pytest.mark.slow
def test_build_writes_a_sound_set_with_its_noise_floor(evalset):
    out, summary = evalset
    ds = Dataset(out)
    assert summary["present"] == 4 and ds.check() == []
    names = [n for n, _ in ds.channels]
    assert names[-3:] == ["pt_b", "pt_spp1", "pt_spp4"]
    f = ds.load(0)
    assert not np.array_equal(f["pt"], f["pt_b"]), "the second render has a seed of its own"
    m = json.loads((out / "manifest.json").read_text())
    assert m["kind"] == "evalset" and m["evalset"]["ladder_spp"] == [1, 4] and m["evalset"]["tonemap"]["exposure"] > 0
    s = json.loads((out / "summary.json").read_text())
    for split in EVAL_SPLITS:
        floor = s["splits"][split]["methods"]["noise_floor"]
        assert math.isfinite(floor["psnr_tm"]["mean"]) and 0 < floor["flip_ldr"]["mean"] < 1
        assert summary["noise_floor"][split]["psnr"]["mean"] == floor["psnr"]["mean"]
        one, four = (s["splits"][split]["methods"][k] for k in ("pt_spp1", "pt_spp4"))
        assert one["psnr"]["mean"] < four["psnr"]["mean"] < floor["psnr"]["mean"], "more samples, less error"


@pytest.mark.mitsuba
@pytest.mark.slow
def test_build_resumes_a_lost_frame_to_the_same_bytes(evalset, tmp_path):
    out, _ = evalset
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    (copy / "frames" / "000003.json").unlink()  # as if killed before the sidecar was written
    summary = build_evalset("cornell", copy, TINY, log=quiet)
    assert summary["present"] == 4
    assert (copy / "frames" / "000003.npy").read_bytes() == (out / "frames" / "000003.npy").read_bytes()
    with pytest.raises(DiviewerError, match="differs in"):
        build_evalset("cornell", copy, EvalSetSettings(**{**TINY.__dict__, "spp": 64}), log=quiet)


@pytest.mark.mitsuba
@pytest.mark.slow
def test_eval_scores_every_row_per_split_as_strict_json(evalset, tmp_path):
    out, _ = evalset
    scene = load_scene("cornell")
    model = direct_times(tmp_path / "twice.onnx", 1.5, meta=base_meta(scene.file_hash, "cornell"))
    res = tmp_path / "eval.json"
    assert main(["eval", "--model", str(model), "--model", str(model), "--evalset", str(out), "--out", str(res)]) == 0
    text = res.read_text()
    assert "NaN" not in text and "Infinity" not in text
    r = json.loads(text)
    assert set(r["splits"]) == set(EVAL_SPLITS)
    for split in EVAL_SPLITS:
        methods = r["splits"][split]["methods"]
        assert set(methods) == {"twice", "twice_1", "direct", "noise_floor", "pt_spp1", "pt_spp4"}
        for m in methods.values():
            for k in ("psnr", "ssim", "psnr_tm", "ssim_tm", "flip_hdr", "flip_ldr"):
                assert math.isfinite(m[k]["mean"]), k
            assert -1 <= m["ssim"]["mean"] <= 1 and 0 <= m["flip_hdr"]["mean"] <= 1
            assert m["equivalent_spp"]["psnr_tm"]["text"]
        assert methods["pt_spp1"]["equivalent_spp"]["psnr_tm"]["text"] == "1"
        assert methods["noise_floor"]["equivalent_spp"]["psnr_tm"]["bound"] == ">="
        assert methods["twice"]["psnr"] == methods["twice_1"]["psnr"]
        # Pooled bias: the model returns 1.5 x direct light, so its summed radiance is 1.5 x the direct
        # light's, and its indirect light (minus the GL direct light) is half the direct light's sum.
        frames = [Dataset(out).load(i) for i in Dataset(out).indices(split)]
        d, pt = (sum(float(np.sum(f[c], dtype=np.float64)) for f in frames) for c in ("direct", "pt"))
        assert methods["twice"]["bias"] == pytest.approx(1.5 * d / pt - 1, rel=1e-4)
        assert methods["twice"]["bias_indirect"] == pytest.approx(0.5 * d / (pt - d) - 1, rel=1e-4)
        assert methods["direct"]["bias_indirect"] == pytest.approx(-1.0)
        assert abs(methods["noise_floor"]["bias"]) < 0.2  # a second unbiased render


@pytest.mark.slow  # alone, it pays for the module's evaluation set (14 s of setup in the inner loop)
@pytest.mark.mitsuba
def test_eval_refuses_a_capture_as_evalset_and_models_of_other_scenes(evalset, tmp_path):
    out, _ = evalset
    other = direct_times(tmp_path / "other.onnx", meta=base_meta("f" * 64, "elsewhere"))
    assert main(["eval", "--model", str(other), "--evalset", str(out)]) == 2
    assert main(["eval", "--model", str(other)]) == 2  # neither --evalset nor --data
    capture_like = tmp_path / "cap"
    capture_like.mkdir()
    m = json.loads((out / "manifest.json").read_text())
    m.pop("kind")
    (capture_like / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(DiviewerError, match="not an evaluation set"):
        from diviewer.evaluate import evaluate_evalset

        evaluate_evalset([], capture_like, log=quiet)
