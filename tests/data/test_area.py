"""The direct light over each pixel's area: the box filter, the renderer's supersampled light, and a dataset
re-rendered with it (its own identity, every other channel as captured, resumable, refusals named)."""

from __future__ import annotations

import numpy as np
import pytest

from diviewer.cli import main
from diviewer.data.area import area_direct, area_manifest, direct_samples
from diviewer.data.capture import CaptureSettings, build_manifest, capture
from diviewer.data.dataset import IDENTITY, Dataset, identity
from diviewer.errors import DiviewerError
from diviewer.gl.area import AreaDirect, box_filter, check_samples
from diviewer.scene import load_scene, sample_config
from diviewer.scene.loader import config_from_dict

TINY = dict(width=32, height=32, spp=4, max_depth=4)
QUIET = dict(log=lambda *_: None)


def test_box_filter_is_each_blocks_mean():
    img = np.arange(4 * 6 * 2, dtype=np.float32).reshape(4, 6, 2)
    out = box_filter(img, 2)
    assert out.shape == (2, 3, 2) and out.dtype == np.float32
    np.testing.assert_allclose(out[1, 2], img[2:4, 4:6].reshape(-1, 2).mean(axis=0))
    np.testing.assert_array_equal(box_filter(img, 1), img)
    with pytest.raises(ValueError, match="multiple"):
        box_filter(img[:3], 2)


@pytest.mark.parametrize("bad", [0, 9, 2.0, True, "4"])
def test_samples_outside_one_to_eight_are_refused_by_name(bad):
    with pytest.raises(DiviewerError, match="samples per axis") as err:
        check_samples(bad, "--samples")
    assert "--samples" in str(err.value)


@pytest.mark.gl
def test_area_light_agrees_with_the_point_light_inside_and_differs_only_at_edges(gl_context):
    """One sample per axis is the renderer's own buffer; 4x4 keeps the frame's light (within 2 %) and the value
    of every pixel whose light is flat, and puts the edge pixels between their neighbours."""
    from diviewer.gl.renderer import Renderer

    scene = load_scene("cornell")
    config = sample_config(scene, 3, "train")
    with gl_context:  # current even if an earlier test made and released a context of its own
        r = Renderer(gl_context, scene, 48, 32)
        r.render(config)
        point = r.read("direct")
        r.release()
        one, four = AreaDirect(gl_context, scene, 48, 32, 1), AreaDirect(gl_context, scene, 48, 32, 4)
        try:
            np.testing.assert_allclose(one(config), point, rtol=1e-6, atol=1e-7)
            area = four(config)
        finally:
            one.release()
            four.release()
    assert area.shape == (32, 48, 3) and np.isfinite(area).all() and area.min() >= 0
    assert abs(area.sum() / point.sum() - 1.0) < 0.02
    lum = point.mean(-1)
    flat = np.ones_like(lum, bool)  # pixels whose 8 neighbours have the same light
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            flat &= np.isclose(np.roll(np.roll(lum, dy, 0), dx, 1), lum, rtol=1e-3, atol=1e-5)
    flat[[0, -1]], flat[:, [0, -1]] = False, False
    assert flat.mean() > 0.3
    np.testing.assert_allclose(area.mean(-1)[flat], lum[flat], rtol=0.05, atol=1e-4)
    assert np.abs(area.mean(-1) - lum)[~flat].max() > 0.01  # and it does change the edges


def test_identity_changes_only_for_a_derived_dataset():
    m = build_manifest(load_scene("cornell"), CaptureSettings(frames=4, **TINY))
    assert identity(m) == {k: m.get(k) for k in IDENTITY} and direct_samples(m) == 1
    assert identity({**m, "direct_area": {"samples": 4}})["direct_area"] == {"samples": 4}


@pytest.mark.mitsuba
def test_derived_dataset_has_the_area_light_and_every_other_channel_as_captured(gl_context, tmp_path, monkeypatch):
    src, out = tmp_path / "src", tmp_path / "area"
    capture("cornell", src, CaptureSettings(frames=3, seed=1, **TINY), **QUIET)
    summary = area_direct(src, out, 2, **QUIET)
    assert summary["present"] == 3 and summary["rendered"] == 3
    a, b = Dataset(src), Dataset(out)
    assert b.check() == [] and direct_samples(b.manifest) == 2 and b.manifest["direct_area"]["from_hash"] == a.hash
    assert b.hash != a.hash and b.manifest["direct_area_from"] == str(src)
    scene = load_scene("cornell")
    with gl_context:  # current again: area_direct made and released its own context
        area = AreaDirect(gl_context, scene, 32, 32, 2)
        expect = {f["index"]: area(config_from_dict(scene, f["config"])).astype(np.float16).astype(np.float32)
                  for f in a.frames}
        area.release()
    for f in a.frames:
        fa, fb = a.load(f["index"]), b.load(f["index"])
        for name in ("depth", "normal", "albedo", "pt", "pt_direct"):
            np.testing.assert_array_equal(fa[name], fb[name])
        np.testing.assert_array_equal(fb["direct"], expect[f["index"]])
    import io

    log = io.StringIO()  # not a terminal: plain lines, and the bar of a resumed run starts at the frames done
    (out / "frames" / f"{a.frames[-1]['index']:06d}.json").unlink()  # one frame lost: the rest are kept
    monkeypatch.setattr("sys.stderr", log)
    assert area_direct(src, out, 2, **QUIET)["rendered"] == 1
    assert "67% 2/3" in log.getvalue() and "100% 3/3" in log.getvalue(), log.getvalue()
    monkeypatch.undo()
    assert area_direct(src, out, 2, **QUIET)["rendered"] == 0  # resumed: nothing left to render
    with pytest.raises(DiviewerError, match="already covers"):
        area_manifest(b, 2)
    with pytest.raises(DiviewerError, match="at least 2"):
        area_manifest(a, 1)
    with pytest.raises(DiviewerError, match="both the source and the output"):
        area_direct(src, src, 2, **QUIET)
    assert main(["data", "area-direct", str(src), "--samples", "2", "--out", str(out)]) == 0
    # eval --data feeds a model the dataset's direct light: it must be the light the model was trained on
    from diviewer.evaluation.evaluate import evaluate
    from onnx_models import base_meta, direct_times

    meta = {**base_meta(load_scene("cornell").file_hash, "cornell"), "multiple": 2}
    point = direct_times(tmp_path / "point.onnx", 1.0, meta=meta)
    area = direct_times(tmp_path / "area.onnx", 1.0, meta={**meta, "direct_samples": 2})
    for model, data in ((point, out), (area, src)):
        with pytest.raises(DiviewerError, match="samples per pixel") as err:
            evaluate(model, data, split="train", log=lambda *_: None)
        assert "direct_area" in str(err.value)
    assert evaluate(area, out, split="train", log=lambda *_: None)["frames"] >= 1


@pytest.mark.gl
def test_render_feeds_a_model_of_the_area_light_its_footprints_mean(gl_context, tmp_path):
    """`diviewer render --model` with direct_samples 2 on the card: the network's input is the direct light of a
    render at 2x2 times the size, averaged (a model returning 1.5 x its direct input shows it)."""
    from onnx_models import base_meta, direct_times

    from diviewer import imageio
    from diviewer.render import render_to_dir

    scene = load_scene("cornell")
    meta = {**base_meta(scene.file_hash, "cornell"), "multiple": 2, "resolution": [24, 16]}
    model = direct_times(tmp_path / "area.onnx", 1.5, meta={**meta, "direct_samples": 2})
    render_to_dir("cornell", tmp_path / "out", res="24x16", seed=5, model=model)
    got = imageio.read_exr(tmp_path / "out" / "neural.exr")
    config = sample_config(scene, 5, "train")
    with gl_context:
        area = AreaDirect(gl_context, scene, 24, 16, 2)
        expect = 1.5 * area(config)
        area.release()
    assert got.shape == (16, 24, 3)
    np.testing.assert_allclose(got, expect, rtol=1e-3, atol=1e-5)


@pytest.mark.mitsuba
def test_a_capture_with_direct_samples_stores_the_area_light_as_area_direct_derives_it(gl_context, tmp_path):
    """`diviewer capture --direct-samples 2` writes what `data area-direct --samples 2` makes of a plain capture,
    frame for frame; its identity carries the record (a plain capture's does not)."""
    plain, captured, derived = tmp_path / "plain", tmp_path / "captured", tmp_path / "derived"
    settings = CaptureSettings(frames=2, seed=4, **TINY)
    capture("cornell", plain, settings, **QUIET)
    capture("cornell", captured, CaptureSettings(frames=2, seed=4, direct_samples=2, **TINY), **QUIET)
    area_direct(plain, derived, 2, **QUIET)
    a, b, c = Dataset(plain), Dataset(captured), Dataset(derived)
    assert direct_samples(b.manifest) == 2 and "direct_area" not in a.manifest and b.hash != a.hash
    for i in a.indices():
        np.testing.assert_array_equal(b.load(i)["direct"], c.load(i)["direct"])
        np.testing.assert_array_equal(b.load(i)["pt"], a.load(i)["pt"])
        for name in ("depth", "normal", "albedo"):  # drawn without the shadow maps nothing stores
            np.testing.assert_array_equal(b.load(i)[name], a.load(i)[name])
    with pytest.raises(DiviewerError, match="samples per axis"):
        capture("cornell", tmp_path / "bad", CaptureSettings(frames=2, direct_samples=0, **TINY), **QUIET)


def test_a_models_recipe_records_the_area_light_as_the_capture_setting_that_makes_it():
    """A checkpoint's (and so a card's) ``recipe.capture`` holds ``direct_samples`` where its dataset's direct light
    covers each pixel's area, so a recipe's [capture] table with that field reads back as the model's recipe."""
    from diviewer.train.checkpoint import CAPTURE_KEYS, capture_record

    cap = {k: getattr(CaptureSettings(), k) for k in CAPTURE_KEYS}
    assert capture_record({"capture": cap, "direct_samples": 1}) == cap
    assert capture_record({"capture": cap}) == cap  # checkpoints from before the area light
    area = capture_record({"capture": cap, "direct_samples": 4})
    assert area == {**cap, "direct_samples": 4} and CaptureSettings(**area).direct_samples == 4
    assert capture_record({}) is None
