"""The evaluation set (splits, shapes, object mask, resumable, apart from training data), its compact form, and
`diviewer eval` on both: every row and region, strict JSON, refusals of what cannot be scored honestly."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil

import numpy as np
import pytest

from diviewer.cli import main
from diviewer.data.capture import CaptureSettings, plan_frames
from diviewer.data.dataset import Dataset
from diviewer.errors import DiviewerError
from diviewer.evaluation.frames import EvalFrames, crop, default_evalset, write_compact
from diviewer.evaluation.scoring import Scorer
from diviewer.evaluation.evaluate import evaluate_evalset
from diviewer.evaluation.evalset import (EVAL_SPLITS, EvalSetSettings, build_evalset, configs_apart, plan_evalset,
                              plan_splits)
from diviewer.scene import load_scene, sample_config
from diviewer.scene.sampler import in_test_stretch, path_parameter

from onnx_models import base_meta, direct_times

TINY = EvalSetSettings(frames_per_split=2, width=16, height=16, spp=16, ladder=(1, 4), max_depth=4, thumbs=1)
WINDOW_KEYS = ("window_shapes_22x16", "window_shapes_28x16")
SPLIT_KEYS = ("unseen_configs", "unseen_objects", "moved_camera", *WINDOW_KEYS)


def quiet(*_):
    pass


def _center_mesh(f: dict) -> str:
    return next(o["mesh"] for o in f["config"]["objects"] if o["name"] == "center")


@pytest.mark.slow
def test_plan_splits_cameras_meshes_and_seeds():
    scene = load_scene("cornell")
    plan = plan_evalset(scene, EvalSetSettings(frames_per_split=24))
    assert plan == plan_evalset(scene, EvalSetSettings(frames_per_split=24))
    assert [f["index"] for f in plan] == list(range(96))
    r, region = scene.ranges.objects["center"], scene.ranges.camera_region
    by = {s: [f for f in plan if f["split"] == s] for s in EVAL_SPLITS}
    assert all(len(v) == 24 for v in by.values())
    for split, meshes in (("unseen_configs", r.train_meshes), ("unseen_objects", r.test_meshes),
                          ("moved_camera", r.train_meshes), ("window_shapes", r.train_meshes)):
        assert all(_center_mesh(f) in meshes for f in by[split]), split
    scene_camera = dataclasses.asdict(scene.default.camera)
    for split in ("unseen_configs", "unseen_objects", "window_shapes"):  # the paper's fixed camera
        assert all(tuple(f["config"]["camera"]["position"]) == tuple(scene_camera["position"]) for f in by[split])
    for f in by["moved_camera"]:  # every moved camera in a held-out box, none at the scene's camera
        assert region.in_test_region(f["config"]["camera"]["position"])
    # The scene-camera splits keep the lights and objects of the sampler's draw (the camera has a stream
    # of its own): the frames of the evaluation sets before the camera region, comparable with them.
    for f in by["unseen_configs"][:4] + by["unseen_objects"][:4]:
        drawn = sample_config(scene, f["seed"], f["sampler_split"], camera="sampled").to_dict()
        assert f["config"]["lights"] == drawn["lights"] and f["config"]["objects"] == drawn["objects"]
    assert [f["widths"] for f in by["window_shapes"]][0] == [170, 228]
    assert {tuple(f["widths"]) for f in plan if f["split"] != "window_shapes"} == {(128,)}
    seeds = [s for f in plan for s in (f["pt_seeds"]["reference"], f["pt_seeds"]["second"], *f["pt_seeds"]["ladder"])]
    assert len(set(seeds)) == len(seeds), "every render of the set has a seed of its own"
    for seed in (0, 1):  # a capture with the same base seed draws other configurations (its own seed stream)
        assert configs_apart(plan, plan_frames(scene, CaptureSettings(frames=500, seed=seed)))
    assert plan_evalset(scene, EvalSetSettings(frames_per_split=24, seed=1)) != plan


def test_a_path_scene_leaves_out_what_it_cannot_have_and_says_why():
    scene = load_scene("atrium")
    splits, left_out = plan_splits(scene, TINY)
    assert "unseen_objects" not in splits and "no test_meshes" in left_out["unseen_objects"]
    assert splits["moved_camera"]["stream"] == 1  # the frames its unseen_objects split had
    plan = plan_evalset(scene, TINY)
    for f in plan:
        s = path_parameter(scene, f["seed"], f["sampler_split"])
        assert in_test_stretch(scene.ranges.camera, s) == (f["split"] == "moved_camera")
    still = dataclasses.replace(scene, ranges=dataclasses.replace(scene.ranges, camera=None, camera_region=None))
    splits, left_out = plan_splits(still, TINY)
    assert "moved_camera" not in splits and "no camera ranges" in left_out["moved_camera"]
    assert list(splits) == ["unseen_configs", "window_shapes"]


def test_bad_settings_are_refused():
    with pytest.raises(DiviewerError, match="ladder"):
        EvalSetSettings(spp=64, ladder=(1, 256)).check()
    with pytest.raises(DiviewerError, match="16x16"):
        EvalSetSettings(width=8).check()
    with pytest.raises(DiviewerError, match="odd number"):
        EvalSetSettings(window_widths=(171, 228)).check()
    assert EvalSetSettings().windows == (170, 228) and EvalSetSettings().render_width == 228


def test_a_centred_crop_of_a_wider_render_is_the_narrower_frame(ctx):
    from diviewer.gl.renderer import Renderer

    scene = load_scene("cornell")
    config = plan_evalset(scene, TINY)[0]["config"]
    from diviewer.scene.loader import config_from_dict

    config = config_from_dict(scene, config)
    wide, narrow = Renderer(ctx, scene, 56, 32), Renderer(ctx, scene, 32, 32)
    try:
        a, b = wide.frame(config), narrow.frame(config)
    finally:
        wide.release()
        narrow.release()
    # The same pixel centres: equal up to rounding, except where a centre lies on the edge between two
    # surfaces (a wall's corner), where rasterisation's tie can go either way (here < 1 % of pixels).
    differ = np.zeros((32, 32), bool)
    for name in ("depth", "normal", "albedo", "direct"):
        x, y = crop(a[name], 32), b[name]
        close = np.isclose(x, y, rtol=1e-4, atol=1e-5)
        differ |= ~(close if close.ndim == 2 else close.all(axis=-1))
    np.testing.assert_allclose(crop(a["depth"], 32), b["depth"], rtol=1e-4)  # the same surfaces, where they tie
    assert differ.mean() < 0.02, differ.mean()
    with pytest.raises(ValueError):
        crop(a["depth"], 31)


@pytest.fixture(scope="module")
def evalset(tmp_path_factory, gl_context):
    pytest.importorskip("mitsuba")
    out = tmp_path_factory.mktemp("evalset") / "cornell"
    summary = build_evalset("cornell", out, TINY, log=quiet)
    return out, summary


@pytest.mark.slow
def test_build_writes_a_sound_set_with_its_noise_floor_and_object_mask(evalset):
    out, summary = evalset
    ds = Dataset(out)
    assert summary["present"] == 8 and ds.check() == [] and (ds.width, ds.height) == (28, 16)
    names = [n for n, _ in ds.channels]
    assert names[-4:] == ["pt_b", "pt_spp1", "pt_spp4", "object"]
    f = ds.load(0)
    assert not np.array_equal(f["pt"], f["pt_b"]), "the second render has a seed of its own"
    m = json.loads((out / "manifest.json").read_text())
    assert m["kind"] == "evalset" and m["evalset"]["ladder_spp"] == [1, 4] and m["evalset"]["tonemap"]["exposure"] > 0
    assert m["evalset"]["left_out"] == {}
    seen = 0
    for i in ds.indices():  # the object's material (albedo 0.8) is exactly where the mask says
        f = ds.load(i)
        obj = f["object"][..., 0] > 0.5
        grey = np.all(np.abs(f["albedo"] - 0.8) < 1e-3, axis=-1)
        assert np.array_equal(obj, grey), i
        seen += int(obj.sum())
    assert seen > 0
    s = json.loads((out / "summary.json").read_text())
    assert set(s["splits"]) == set(SPLIT_KEYS)
    for key in SPLIT_KEYS:
        floor = s["splits"][key]["methods"]["noise_floor"]
        assert math.isfinite(floor["psnr_tm"]["mean"]) and 0 < floor["flip_ldr"]["mean"] < 1
        assert summary["noise_floor"][key]["psnr"]["mean"] == floor["psnr"]["mean"]


@pytest.mark.slow
def test_build_resumes_a_lost_frame_to_the_same_bytes(evalset, tmp_path):
    out, _ = evalset
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    (copy / "frames" / "000003.json").unlink()  # as if killed before the sidecar was written
    summary = build_evalset("cornell", copy, TINY, log=quiet)
    assert summary["present"] == 8
    assert (copy / "frames" / "000003.npy").read_bytes() == (out / "frames" / "000003.npy").read_bytes()
    with pytest.raises(DiviewerError, match="differs in"):
        build_evalset("cornell", copy, EvalSetSettings(**{**TINY.__dict__, "spp": 64}), log=quiet)


@pytest.mark.slow
def test_a_complete_set_run_again_keeps_its_scores_until_a_frame_is_newer(evalset, tmp_path):
    """Nothing to render: the scores written after the last frame are read back, not computed again (a chain
    resumes it at every start); a frame written after them (or a deleted summary.json) is scored again."""
    out, first = evalset
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)  # modification times kept
    before = (copy / "summary.json").read_bytes()
    lines = []
    again = build_evalset("cornell", copy, TINY, log=lines.append)
    assert any("written after its last frame" in line for line in lines)
    assert (copy / "summary.json").read_bytes() == before and again["noise_floor"] == first["noise_floor"]
    later = (copy / "summary.json").stat().st_mtime + 10
    os.utime(copy / "frames" / "000001.npy", (later, later))
    lines.clear()
    rescored = build_evalset("cornell", copy, TINY, log=lines.append)
    assert not any("written after its last frame" in line for line in lines)
    assert rescored["noise_floor"] == first["noise_floor"]


@pytest.mark.slow
def test_shards_render_their_own_frames_into_one_set_and_the_last_scores_it(evalset, tmp_path):
    out, _ = evalset
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    (copy / "summary.json").unlink()
    for i in (2, 3, 5):  # shard 1/2 owns the even indices, shard 2/2 the odd ones
        (copy / "frames" / f"{i:06d}.json").unlink()
    first = build_evalset("cornell", copy, TINY, log=quiet, shard=(1, 2))
    assert first["present"] == 6 and (copy / "frames" / "000002.json").is_file()
    assert not (copy / "frames" / "000003.json").is_file() and not (copy / "summary.json").exists()
    last = build_evalset("cornell", copy, TINY, log=quiet, shard=(2, 2))
    assert last["present"] == 8 and (copy / "summary.json").is_file()
    for i in (2, 3, 5):  # each frame's seeds come from its index, not from the shard that rendered it
        assert (copy / "frames" / f"{i:06d}.npy").read_bytes() == (out / "frames" / f"{i:06d}.npy").read_bytes()
    a, b = (json.loads((d / "summary.json").read_text()) for d in (copy, out))
    assert (a.pop("evalset"), b.pop("evalset")) == (str(copy), str(out))  # each names its own folder
    assert a == b

def _models(tmp_path):
    scene = load_scene("cornell")
    # cards of a model trained on a 4-spp capture (a rung of the ladder) and on a truth refined to 8 (projected)
    any_shape = direct_times(tmp_path / "twice.onnx", 1.5, meta={**base_meta(scene.file_hash, "cornell"),
                                                                 "multiple": 2, "checkpoint_sha256": "c" * 64,
                                                                 "recipe": {"capture": {"spp": 4}}})
    square = direct_times(tmp_path / "square.onnx", 1.5, meta={**base_meta(scene.file_hash, "cornell"),  # multiple 16
                                                               "truth_spp": {"min": 8, "max": 9}})
    return any_shape, square


@pytest.mark.slow
def test_eval_scores_every_split_shape_and_region_as_strict_json(evalset, tmp_path):
    out, _ = evalset
    model, square = _models(tmp_path)
    res = tmp_path / "eval.json"
    args = ["eval", "--model", str(model), "--model", str(model), "--model", str(square), "--evalset", str(out)]
    assert main(args + ["--out", str(res)]) == 0
    text = res.read_text()
    assert "NaN" not in text and "Infinity" not in text
    r = json.loads(text)
    assert set(r["splits"]) == set(SPLIT_KEYS) and r["left_out"] == {} and r["not_scored"] == {}
    for key in SPLIT_KEYS:
        split = r["splits"][key]
        methods = split["methods"]
        # the model of stride 16 runs 22 and 28 columns too: the runtime pads to its stride and crops back
        expected = {"twice", "twice_1", "square", "direct", "noise_floor", "pt_spp1", "pt_spp4"}
        assert not split.get("refused") and set(methods) == expected
        for m in methods.values():
            for k in ("psnr", "ssim", "psnr_tm", "ssim_tm", "flip_hdr", "flip_ldr"):
                assert math.isfinite(m[k]["mean"]), k
            assert m["equivalent_spp"]["psnr_tm"]["text"]
            assert m["psnr_tm_object"] is not None and m["psnr_tm_object"]["frames"] >= 1
        assert methods["pt_spp1"]["equivalent_spp"]["psnr_tm"]["text"] == "1"
        assert methods["twice"]["psnr"] == methods["twice_1"]["psnr"]
        # which weights each row scored (`diviewer ship eval` checks it): the card's checkpoint, None without one
        assert methods["twice"]["checkpoint_sha256"] == "c" * 64 and methods["square"]["checkpoint_sha256"] is None
        assert methods["twice"]["edge_guard"] == 0  # the padding it ran with: no aspect crops recorded, no guard
        below = methods["twice"]["below_direct"]
        assert below["frame"]["frames"] == 2 and 0 <= below["frame"]["share"] <= 1
        # Pooled bias: the model returns 1.5 x direct light, so its summed radiance is 1.5 x the direct light's.
        ev = EvalFrames(out)
        frames = [{k: crop(v, split["shape"][0]) for k, v in ev.load(i).items()}
                  for i in ev.present(split["split"], [])]
        d, pt = (sum(float(np.sum(f[c], dtype=np.float64)) for f in frames) for c in ("direct", "pt"))
        assert methods["twice"]["bias"] == pytest.approx(1.5 * d / pt - 1, rel=1e-4)
        assert methods["direct"]["bias_indirect"] == pytest.approx(-1.0)
        # frame by frame, in the split's order: the pooled figures and the below-direct share can be read per frame
        rows = methods["twice"]["per_frame"]
        assert [r["index"] for r in rows] == list(ev.present(split["split"], []))
        assert sum(r["sum"] for r in rows) / sum(r["sum_ref"] for r in rows) - 1 == pytest.approx(methods["twice"]["bias"])
        assert np.mean([r["psnr_tm"] for r in rows]) == pytest.approx(methods["twice"]["psnr_tm"]["mean"])
        assert len(methods["direct"]["per_frame"]) == len(rows) and "per_frame" not in methods["pt_spp1"]
    # each model's training truth over its error (diviewer.evaluation.truthmargin): a rung of the ladder, or projected
    for key in SPLIT_KEYS:
        methods = r["splits"][key]["methods"]
        for name, spp, rung in (("twice", 4, "pt_spp4"), ("square", 8, "pt_spp4, projected to 8 spp")):
            got = methods[name]["truth_margin"]
            assert (got["truth_spp"], got["from"]) == (spp, rung) and got["frames"] + got["unresolved"] == 2
        assert "truth_margin" not in methods["direct"]


@pytest.mark.slow
def test_scoring_in_worker_processes_gives_the_same_numbers_in_the_same_order(evalset, tmp_path):
    out, _ = evalset
    model, _ = _models(tmp_path)

    def untimed(r):  # the models' inference times are the one thing that differs between runs
        for split in r["splits"].values():
            split["methods"]["twice"].pop("inference_ms")
        return r

    one, two = (untimed(evaluate_evalset([model], out, log=quiet, jobs=j)) for j in (1, 2))
    assert json.dumps(one, sort_keys=True) == json.dumps(two, sort_keys=True)
    for j in (1, 2):
        write_compact(out, tmp_path / f"compact{j}", frames_per_split=2, log=quiet, jobs=j)
    a, b = (json.loads((tmp_path / f"compact{j}" / "manifest.json").read_text()) for j in (1, 2))
    assert a["frame_list"] == b["frame_list"] and a["frame_list"][0]["ladder_scores"]
    with pytest.raises(ValueError, match="at least 1"):
        Scorer(0)
    assert main(["eval", "--model", str(model), "--evalset", str(out), "--jobs", "0"]) == 2


@pytest.mark.slow
def test_a_model_of_the_area_direct_light_is_fed_it_and_scored_against_the_same_truth(evalset, tmp_path, gl_context):
    """direct_samples 2 on the card: eval renders each frame's direct light over 2x2 samples (`diviewer.gl.area`)
    and feeds it in place of the stored buffer; the truth and the regions stay the set's."""
    from diviewer.gl.area import AreaDirect
    from diviewer.scene.loader import config_from_dict

    out, _ = evalset
    scene = load_scene("cornell")
    meta = {**base_meta(scene.file_hash, "cornell"), "multiple": 2}
    point = direct_times(tmp_path / "point.onnx", 1.5, meta=meta)
    area = direct_times(tmp_path / "area.onnx", 1.5, meta={**meta, "direct_samples": 2})
    r = evaluate_evalset([point, area], out, log=quiet)
    ev = EvalFrames(out)
    with gl_context:  # current again: eval made and released its own context
        light = AreaDirect(gl_context, scene, ev.manifest["resolution"][0], ev.manifest["resolution"][1], 2)
        lit = {f["index"]: light(config_from_dict(scene, f["config"])) for f in ev.frames}
        light.release()
    for key, split in r["splits"].items():
        frames = ev.present(split["split"], [])
        w = split["shape"][0]
        a = sum(float(np.sum(crop(lit[i], w), dtype=np.float64)) for i in frames)
        pt = sum(float(np.sum(crop(ev.load(i)["pt"], w), dtype=np.float64)) for i in frames)
        assert split["methods"]["area"]["bias"] == pytest.approx(1.5 * a / pt - 1, rel=1e-4), key
        assert split["methods"]["area"]["psnr"] != split["methods"]["point"]["psnr"]


def test_eval_refuses_corrupt_and_incomplete_sets_unless_partial(evalset, tmp_path, capsys):
    out, _ = evalset
    model, _ = _models(tmp_path)
    corrupt = tmp_path / "corrupt"
    shutil.copytree(out, corrupt)
    npy = corrupt / "frames" / "000002.npy"
    data = bytearray(npy.read_bytes())
    data[-7] ^= 0x5A  # one byte of one pixel
    npy.write_bytes(bytes(data))
    assert main(["eval", "--model", str(model), "--evalset", str(corrupt)]) == 2
    assert "checksum" in capsys.readouterr().err
    assert main(["eval", "--model", str(model), "--evalset", str(corrupt), "--partial"]) == 2

    part = tmp_path / "part"
    shutil.copytree(out, part)
    for i in (2, 3):  # the whole unseen_objects split, and nothing else
        (part / "frames" / f"{i:06d}.json").unlink()
    (part / "frames" / "000000.npy").unlink()
    assert main(["eval", "--model", str(model), "--evalset", str(part)]) == 2
    assert "incomplete" in capsys.readouterr().err
    res = tmp_path / "p.json"
    assert main(["eval", "--model", str(model), "--evalset", str(part), "--partial", "--out", str(res)]) == 0
    printed = capsys.readouterr().out
    r = json.loads(res.read_text())
    assert "unseen_objects" not in r["splits"] and "no frame" in r["not_scored"]["unseen_objects"]
    assert "unseen_objects: not scored" in printed
    assert r["splits"]["unseen_configs"]["frames_scored"] == [1] and "frames scored: 1" in printed
    # the whole result names what it scored and what it did not, never "every frame"
    assert "every frame" not in r["frames"] and r["frames"].startswith("a partial set: ")
    assert 0 not in r["frames_scored"] and 1 in r["frames_scored"] and len(r["frames_scored"]) == len(
        Dataset(part).frames) - 3
    assert [(x["index"], x["split"]) for x in r["frames_not_scored"]] == [(0, "unseen_configs"), (2, "unseen_objects"),
                                                                         (3, "unseen_objects")]
    assert "frames: a partial set" in printed and "not scored: 0, 2, 3" in printed


def test_compact_set_scores_as_the_full_one_and_is_checked(evalset, tmp_path, monkeypatch, capsys):
    out, _ = evalset
    model, _ = _models(tmp_path)
    compact = tmp_path / "evalsets" / "cornell"
    assert main(["evalset", "--compact", str(out), "--out", str(compact), "--frames-per-split", "1"]) == 0
    ev = EvalFrames(compact)
    assert ev.compact and len(ev.frames) == 4 and ev.problems() == []
    assert {f["stored_width"] for f in ev.frames} == {16, 28}  # square splits stored cropped
    # Each distinct object list is stored once; read back, every frame's configuration is the full set's.
    raw = json.loads((compact / "manifest.json").read_text())
    assert all(set(f["config"]["objects"]) == {"list"} for f in raw["frame_list"]) and raw["object_lists"]
    configs = {f["index"]: f["config"] for f in EvalFrames(out).frames}
    assert all(f["config"] == configs[f["index"]] for f in ev.frames)
    assert not (compact / "frames").exists() and main(["data", "check", str(compact)]) == 0
    monkeypatch.setattr("diviewer.evaluation.frames.DEFAULT_EVALSETS", tmp_path / "evalsets")
    assert default_evalset("cornell") == compact
    res = tmp_path / "c.json"
    assert main(["eval", "--model", str(model), "--out", str(res)]) == 0  # no --evalset: the compact set
    r = json.loads(res.read_text())
    assert r["compact"] and set(r["splits"]) == set(SPLIT_KEYS)
    full = len(EvalFrames(out).frames)  # the JSON says how much of the rendered set it scored, not only its storage
    assert full > 4 and r["frames"] == f"a subset: 4 of the full set's {full} (1 per split at most)"
    assert EvalFrames(out).subset == f"every frame rendered ({full})"
    whole = tmp_path / "whole"  # stored compact, every frame kept (as the device-rendered Sponza set)
    assert main(["evalset", "--compact", str(out), "--out", str(whole), "--frames-per-split", "2"]) == 0
    assert EvalFrames(whole).subset == f"every frame: {full} of the full set's {full} (2 per split at most)"
    # One frame per split: the compact set holds each split's first frame; scores match the full set's on it.
    single = tmp_path / "first"
    shutil.copytree(out, single)
    for f in Dataset(out).frames:
        if f["index"] % 2:
            (single / "frames" / f"{f['index']:06d}.json").unlink()
    full = evaluate_evalset([model], single, log=quiet, partial=True)
    for key in SPLIT_KEYS:
        for m in ("twice", "direct", "noise_floor", "pt_spp1", "pt_spp4"):
            a, b = r["splits"][key]["methods"][m], full["splits"][key]["methods"][m]
            assert a["psnr_tm"]["mean"] == pytest.approx(b["psnr_tm"]["mean"], abs=0.05), (key, m)
            assert a["ssim_tm"]["mean"] == pytest.approx(b["ssim_tm"]["mean"], abs=2e-3), (key, m)
    # A changed byte in the compact set is refused, naming the frame.
    m = json.loads((compact / "manifest.json").read_text())
    m["frame_list"][1]["sha256"] = "0" * 64
    (compact / "manifest.json").write_text(json.dumps(m))
    capsys.readouterr()
    assert main(["eval", "--model", str(model)]) == 2
    assert "frame 2: checksum" in capsys.readouterr().err
    assert main(["data", "check", str(compact)]) == 1
    # eval --data of this scene takes the scene's tone map from its evaluation set, never from a model
    from diviewer.evaluation.evaluate import scene_exposure

    frames = [np.full((4, 4, 3), 2.0)]
    assert scene_exposure("cornell", ev.manifest["scene_hash"], frames)[0] == ev.exposure
    from diviewer.contract.encoding import fit_exposure

    assert scene_exposure("cornell", "another", frames)[0] == fit_exposure(frames)
    with pytest.raises(DiviewerError, match="already a compact"):
        write_compact(compact, tmp_path / "again", log=quiet)
    with pytest.raises(DiviewerError, match="not ready"):
        write_compact(single, tmp_path / "two", frames_per_split=2, log=quiet)


def test_a_compact_set_is_never_written_over_and_holds_the_count_it_took(evalset, tmp_path, capsys):
    out, _ = evalset
    compact = tmp_path / "compact"
    assert main(["evalset", "--compact", str(out), "--out", str(compact), "--frames-per-split", "1"]) == 0
    before = {p.name: p.read_bytes() for p in compact.iterdir()}
    shipped = tmp_path / "shipped"  # a copy of the shipped set, written over as the folder it is
    shutil.copytree(default_evalset("cornell"), shipped)
    shipped_before = {p.name: p.read_bytes() for p in shipped.iterdir()}
    capsys.readouterr()
    for target in (compact, shipped, out):  # a compact set, the shipped one, the full set itself
        assert main(["evalset", "--compact", str(out), "--out", str(target), "--frames-per-split", "2"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(target) in err[0], err
    assert {p.name: p.read_bytes() for p in compact.iterdir()} == before
    assert {p.name: p.read_bytes() for p in shipped.iterdir()} == shipped_before
    # more frames per split than the full set's splits have: refused up front, nothing written
    assert main(["evalset", "--compact", str(out), "--out", str(tmp_path / "more"), "--frames-per-split", "3"]) == 2
    assert "at most 2" in capsys.readouterr().err and not (tmp_path / "more").exists()
    assert EvalFrames(compact).manifest["compact"]["frames_per_split"] == 1
    # asked for nothing: the default, capped at what each split has, and the manifest says the count taken
    write_compact(out, tmp_path / "default", log=quiet)
    m = EvalFrames(tmp_path / "default").manifest["compact"]
    assert m["frames_per_split"] == 2 and set(m["per_split"].values()) == {2}


def test_a_derived_evaluation_set_is_neither_a_source_nor_scored(evalset, tmp_path, capsys):
    out, _ = evalset
    model, _ = _models(tmp_path)
    for command, extra in (("filter-truth", []), ("refine", ["--spp", "32"]), ("area-direct", ["--samples", "2"])):
        assert main(["data", command, str(out), "--out", str(tmp_path / command), *extra]) == 2
        assert "evaluation set" in capsys.readouterr().err and not (tmp_path / command).exists()
    derived = tmp_path / "derived"  # as an older diviewer wrote a filtered copy of a set: the record, no lineage
    shutil.copytree(out, derived)
    m = json.loads((derived / "manifest.json").read_text())
    m["truth_filter"], m["truth_filter_from"] = {"levels": 1, "from_hash": "a"}, str(out)
    (derived / "manifest.json").write_text(json.dumps(m))
    assert main(["eval", "--model", str(model), "--evalset", str(derived), "--out", str(tmp_path / "r.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "lineage" in err[0] and "filtered" in err[0] and not (tmp_path / "r.json").exists()
    with pytest.raises(DiviewerError, match="lineage"):
        write_compact(derived, tmp_path / "compact", log=quiet)


def test_eval_refuses_a_capture_as_evalset_and_models_of_other_scenes(evalset, tmp_path):
    out, _ = evalset
    other = direct_times(tmp_path / "other.onnx", meta=base_meta("f" * 64, "elsewhere"))
    assert main(["eval", "--model", str(other), "--evalset", str(out)]) == 2
    assert main(["eval", "--model", str(other)]) == 2  # no --evalset, and no set ships for scene 'elsewhere'
    capture_like = tmp_path / "cap"
    capture_like.mkdir()
    m = json.loads((out / "manifest.json").read_text())
    m.pop("kind")
    (capture_like / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(DiviewerError, match="not an evaluation set"):
        evaluate_evalset([], capture_like, log=quiet)


SHIPPED = {name: default_evalset(name) for name in ("cornell", "sponza")}


@pytest.mark.parametrize("name", [n for n, d in SHIPPED.items() if (d / "manifest.json").is_file()])
def test_the_shipped_compact_set_is_sound_small_and_of_todays_scene(name):
    ev = EvalFrames(SHIPPED[name])
    assert ev.compact and ev.problems() == []
    assert ev.manifest["scene_hash"] == load_scene(name).file_hash
    left_out = set(ev.left_out())
    assert ev.manifest["spp"] >= 1024 and set(ev.splits()) == set(EVAL_SPLITS) - left_out
    size = sum(p.stat().st_size for p in SHIPPED[name].iterdir())
    assert size < 6 * 2**20, size  # cornell 6 frames a split: 3.4 MB; sponza 5 (its textures compress less): 5.3 MB


def test_the_shipped_compact_sets_fit_the_repository_budget():
    """cornell and sponza together <= 10 MB (the device carries the whole tracked tree)."""
    total = sum(p.stat().st_size for d in SHIPPED.values() if d.is_dir() for p in d.iterdir())
    assert (SHIPPED["cornell"] / "manifest.json").is_file() and total <= 10 * 2**20, total
