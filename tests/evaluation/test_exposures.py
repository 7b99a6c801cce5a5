"""`diviewer eval --exposure` (diviewer.evaluation.exposures): the scene's one exposure unchanged, each frame at its
truth's metered exposure, a fixed number of stops; an unlit frame falls back and is counted; a bad value is refused
before any work. On a copy of the shipped compact set of cornell (one split) and a tiny dataset."""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest

from diviewer.cli import main
from diviewer.errors import DiviewerError
from diviewer.evaluation.evaluate import evaluate, evaluate_evalset
from diviewer.evaluation.exposures import FrameExposures, exposure_mode
from diviewer.evaluation.frames import EvalFrames, crop_frame, default_evalset
from diviewer.evaluation.scoring import regions, score, score_frame_regions
from diviewer.exposure import SHOWN, WHITE_POINTS, metered_ev
from diviewer.metrics import flat_mask
from diviewer.scene import load_scene
from onnx_models import base_meta, direct_times
from tiny_datasets import tiny_capture

SPLIT = "moved_camera"


def quiet(*_):
    pass


@pytest.fixture
def one_split(tmp_path):
    """A copy of cornell's shipped compact set listing only ``SPLIT``'s frames, and a model giving 1.5 x direct."""
    copy = tmp_path / "one_split"
    shutil.copytree(default_evalset("cornell"), copy)
    manifest = json.loads((copy / "manifest.json").read_text())
    manifest["frame_list"] = [f for f in manifest["frame_list"] if f["split"] == SPLIT][:2]
    manifest["frames"] = len(manifest["frame_list"])
    (copy / "manifest.json").write_text(json.dumps(manifest))
    model = direct_times(tmp_path / "twice.onnx", 1.5, meta={**base_meta(load_scene("cornell").file_hash, "cornell"),
                                                             "multiple": 2})
    return copy, model


def _untimed(r: dict) -> dict:
    for split in r["splits"].values():
        for m in split["methods"].values():
            m.pop("inference_ms", None)
    return r


def _by_hand(ev: EvalFrames, factor_of) -> dict[str, list[dict]]:
    """Each frame of ``SPLIT`` scored as eval scores it, at ``factor_of(truth)``, the regions at the set's exposure."""
    out = {"twice": [], "direct": []}
    for i in ev.present(SPLIT, []):
        f = crop_frame(ev.load(i), ev.splits()[SPLIT][0][0])
        mask = flat_mask(f["depth"], f["normal"], f["albedo"], f["direct"])
        x = factor_of(f["pt"])
        out["twice"].append(score_frame_regions(1.5 * f["direct"], f, x, mask, ev.exposure))
        out["direct"].append(score_frame_regions(f["direct"], f, x, mask, ev.exposure))
    return out


def _check_rows(split: dict, hand: dict[str, list[dict]]) -> None:
    for name, rows in hand.items():
        got = split["methods"][name]["per_frame"]
        assert [r["psnr_tm"] for r in got] == pytest.approx([r["psnr_tm"] for r in rows], rel=1e-4), name
        assert [r["ssim_tm"] for r in got] == pytest.approx([r["ssim_tm"] for r in rows], rel=1e-4), name
        assert split["methods"][name]["psnr_tm"]["mean"] == pytest.approx(np.mean([r["psnr_tm"] for r in rows]),
                                                                          rel=1e-4)


@pytest.mark.slow
def test_scene_mode_is_the_default_and_scores_at_the_sets_exposure(one_split):
    root, model = one_split
    default = _untimed(evaluate_evalset([model], root, log=quiet))
    scene = _untimed(evaluate_evalset([model], root, log=quiet, exposure="scene"))
    assert json.dumps(default, sort_keys=True) == json.dumps(scene, sort_keys=True)
    ev = EvalFrames(root)
    assert scene["exposure"] == {"mode": "scene", "scene_exposure": ev.exposure}
    split = scene["splits"][SPLIT]
    assert "exposure" not in split and "ladder_left_out" not in scene
    _check_rows(split, _by_hand(ev, lambda truth: ev.exposure))
    assert split["methods"]["pt_spp1"]["equivalent_spp"]["psnr_tm"]["text"] == "1"  # the stored ladder


@pytest.mark.slow
def test_metered_mode_scores_each_frame_at_its_truths_metered_exposure(one_split, capsys):
    root, model = one_split
    ev = EvalFrames(root)
    out = root.parent / "metered.json"
    assert main(["eval", "--model", str(model), "--evalset", str(root), "--exposure", "metered", "--jobs", "1",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    r = json.loads(out.read_text())
    evs = [metered_ev(crop_frame(ev.load(i), ev.splits()[SPLIT][0][0])["pt"], SHOWN, WHITE_POINTS["aces"])
           for i in ev.present(SPLIT, [])]
    assert all(e is not None for e in evs) and len(set(evs)) > 1
    split = r["splits"][SPLIT]
    _check_rows(split, _by_hand(ev, lambda truth: 2.0 ** metered_ev(truth, SHOWN, WHITE_POINTS["aces"])))
    assert split["exposure"] == {"ev_min": pytest.approx(min(evs)), "ev_median": pytest.approx(float(np.median(evs))),
                                 "ev_max": pytest.approx(max(evs)), "frames": len(evs), "fell_back": 0}
    assert r["exposure"]["mode"] == "metered" and r["tonemap_exposure"] == ev.exposure
    # a compact set's ladder is stored as scores at the set's exposure: left out here, and said so
    assert "pt_spp1" not in split["methods"] and "ladder_left_out" in r
    assert split["methods"]["twice"]["equivalent_spp"]["psnr_tm"] is None
    assert "each frame's metered exposure" in printed and f"metered {min(evs):+.1f} to {max(evs):+.1f} EV" in printed
    assert len([line for line in printed.splitlines() if line.startswith(("cornell:", "object /"))]) == 2


@pytest.mark.slow
def test_a_fixed_ev_scores_every_frame_there_and_jobs_give_the_same(one_split):
    root, model = one_split
    ev = EvalFrames(root)
    one = _untimed(evaluate_evalset([model], root, log=quiet, exposure=2.5, jobs=1))
    two = _untimed(evaluate_evalset([model], root, log=quiet, exposure="2.5", jobs=2))
    assert json.dumps(one, sort_keys=True) == json.dumps(two, sort_keys=True)
    assert one["exposure"]["mode"] == "fixed" and one["exposure"]["ev"] == 2.5 and "exposure" not in one["splits"][SPLIT]
    _check_rows(one["splits"][SPLIT], _by_hand(ev, lambda truth: 2.0 ** 2.5))
    # the regions are the scene exposure's pixels in every mode
    scene = evaluate_evalset([model], root, log=quiet)
    for k in ("lit", "shade"):
        assert one["splits"][SPLIT]["methods"]["twice"][f"psnr_tm_{k}"]["frames"] == \
            scene["splits"][SPLIT]["methods"]["twice"][f"psnr_tm_{k}"]["frames"]


@pytest.mark.slow
def test_an_unlit_frame_falls_back_to_the_scenes_exposure_and_is_counted(one_split, monkeypatch):
    root, model = one_split
    ev = EvalFrames(root)
    dark = ev.present(SPLIT, [])[1]
    load = EvalFrames.load

    def load_dark(self, index):  # one frame whose truth holds no light
        f = load(self, index)
        return {**f, "pt": np.zeros_like(f["pt"])} if index == dark else f

    monkeypatch.setattr(EvalFrames, "load", load_dark)
    partial = evaluate_evalset([model], root, log=quiet, exposure="metered", partial=True)
    split = partial["splits"][SPLIT]
    assert split["exposure"]["fell_back"] == 1 and split["exposure"]["frames"] == len(ev.present(SPLIT, []))
    assert split["frames_scored"] == ev.present(SPLIT, [])
    lit = [i for i in ev.present(SPLIT, []) if i != dark]
    evs = [metered_ev(ev.load(i)["pt"], SHOWN) for i in lit] + [math.log2(ev.exposure)]
    assert split["exposure"]["ev_min"] == pytest.approx(min(evs)) and split["exposure"]["ev_max"] == pytest.approx(max(evs))
    # the unlit frame scored against its black truth
    row = split["methods"]["direct"]["per_frame"][1]
    assert row["index"] == dark and row["sum_ref"] == 0.0
    black = FrameExposures("metered", ev.exposure)
    assert black.factor(np.zeros((4, 4, 3), np.float32)) == ev.exposure
    assert black.split_record()["fell_back"] == 1 and black.split_record() is None  # counted once, then reset


def test_a_dataset_split_is_scored_at_each_frames_metered_exposure(tmp_path):
    ds = tiny_capture(tmp_path / "data", frames=3)
    model = direct_times(tmp_path / "m.onnx", 1.2, meta={**base_meta(load_scene("cornell").file_hash, "cornell"),
                                                         "multiple": 2})
    out = tmp_path / "metered.json"
    assert main(["eval", "--model", str(model), "--data", str(ds.root), "--split", "train", "--exposure", "metered",
                 "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    frames = [ds.load(i) for i in ds.indices("train")]
    evs = [metered_ev(f["pt"], SHOWN) for f in frames]
    rows = [score(1.2 * f["direct"], f["pt"], 2.0 ** e) for f, e in zip(frames, evs)]
    assert r["methods"]["neural"]["psnr_tm"]["mean"] == pytest.approx(np.mean([s["psnr_tm"] for s in rows]), rel=1e-4)
    assert r["exposure"]["mode"] == "metered" and r["exposure"]["fell_back"] == 0
    assert r["exposure"]["ev_median"] == pytest.approx(float(np.median(evs)))
    fixed = evaluate(model, ds.root, split="train", log=quiet, exposure=-1.0)
    rows = [score(f["direct"], f["pt"], 0.5) for f in frames]
    assert fixed["methods"]["direct"]["psnr_tm"]["mean"] == pytest.approx(np.mean([s["psnr_tm"] for s in rows]))
    scene = evaluate(model, ds.root, split="train", log=quiet)
    rows = [score(f["direct"], f["pt"], scene["tonemap"]["exposure"]) for f in frames]
    assert scene["methods"]["direct"]["psnr_tm"]["mean"] == pytest.approx(np.mean([s["psnr_tm"] for s in rows]))
    assert scene["exposure"]["mode"] == "scene"


def test_the_regions_of_a_frame_do_not_move_with_the_exposure():
    frame = {"direct": np.array([[[1e-3, 1e-3, 1e-3], [0.0, 0.0, 0.0]]], np.float32)}
    assert regions(frame, 0.5)["shade"].tolist() == [[True, True]]
    assert regions(frame, 2.0)["shade"].tolist() == [[False, True]]


@pytest.mark.extremes
@pytest.mark.parametrize("bad", ["abc", "1e9", "nan", "inf", "-41", ""])
def test_a_bad_exposure_is_refused_before_any_work_naming_the_option(bad, tmp_path, capsys):
    missing = tmp_path / "no_such_model.onnx"  # never read: the value is refused first
    assert main(["eval", "--model", str(missing), "--exposure", bad]) == 2
    err = capsys.readouterr().err
    assert "--exposure" in err and "no_such_model" not in err and len(err.strip().splitlines()) == 1
    if bad not in ("1e9", "-41"):  # out of the options' range only, the API takes any finite number of stops
        with pytest.raises(DiviewerError) as e:
            evaluate_evalset([missing], exposure=bad, log=quiet)
        assert e.value.field == "--exposure"
    assert exposure_mode(" Metered ") == "metered" and exposure_mode("-3") == -3.0
