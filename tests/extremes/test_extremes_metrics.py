"""Metrics at the extremes (constant, black, huge images), strict JSON, the indirect target's division
by albedo, and `eval` on a black reference (warns; its JSON stays strict)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from diviewer.metrics import mse, psnr, ssim
from diviewer.outputs import dumps

SIZE = (12, 13, 3)


@pytest.mark.parametrize("value", [0.0, 1e-30, 0.5, 1.0, 1e8, 1e30, 1e300])
def test_constant_images(value):
    a = np.full(SIZE, value)
    assert ssim(a, a) == 1.0 and psnr(a, a) == math.inf and mse(a, a) == 0.0


@pytest.mark.parametrize("scale", [1.0, 1e4, 1e8, 1e15, 1e30, 1e150, 1e300])
def test_ssim_stays_in_range_for_huge_values(scale):
    rng = np.random.default_rng(1)
    a = scale * (1 + 1e-3 * rng.random(SIZE))  # a bright, nearly flat region: E[x^2] - mu^2 cancels
    b = scale * (1 + 1e-3 * rng.random(SIZE))
    s = ssim(a, b)
    assert -1.0 <= s <= 1.0 and math.isfinite(s)
    assert ssim(a, a) == pytest.approx(1.0)


@pytest.mark.parametrize("scale", [1e-300, 1e-30, 1.0, 1e30])
def test_black_against_anything(scale):
    black = np.zeros(SIZE)
    other = scale * np.random.default_rng(2).random(SIZE)
    s = ssim(black, other)
    assert -1.0 <= s <= 1.0
    assert psnr(black, other) > 0 or scale >= 1.0


IMAGES = hnp.arrays(np.float64, SIZE, elements=st.floats(0.0, 1.0))


@given(a=IMAGES, b=IMAGES, scale=st.sampled_from([1e-200, 1e-8, 1.0, 1e8, 1e38, 1e200]),
       offset=st.sampled_from([0.0, 1.0, 1e6]))
def test_ssim_is_bounded_and_symmetric(a, b, scale, offset):
    x, y = (a + offset) * scale, (b + offset) * scale
    s = ssim(x, y)
    assert -1.0 <= s <= 1.0
    assert s == pytest.approx(ssim(y, x), abs=1e-9)


@given(a=IMAGES, b=IMAGES)
def test_psnr_of_unit_images_is_positive_or_inf(a, b):
    p = psnr(a, b)
    assert p > 0 and (math.isfinite(p) or np.array_equal(a, b))


@pytest.mark.slow
@given(st.recursive(st.one_of(st.floats(), st.integers(), st.text(max_size=3), st.none()),
                    lambda c: st.one_of(st.lists(c, max_size=3), st.dictionaries(st.text(max_size=3), c, max_size=3)),
                    max_leaves=8))
def test_written_json_is_always_strict(obj):
    text = dumps(obj)
    json.loads(text, parse_constant=lambda c: pytest.fail(f"non-strict JSON constant {c}"))


def test_metric_values_in_json_are_strict():
    text = dumps({"psnr": psnr(np.zeros(SIZE), np.zeros(SIZE)), "x": np.float32("nan"), "y": [-math.inf]})
    assert json.loads(text) == {"psnr": None, "x": None, "y": [None]}


# --- the indirect target's division by albedo -----------------------------------------------------
@pytest.mark.parametrize("albedo", [0.0, 1e-30, 1e-3, 1.0])
def test_division_by_albedo_is_finite_and_invertible_where_it_can_be(albedo):
    from diviewer.train.targets import ALBEDO_FLOOR, compose_radiance, target_radiance

    rng = np.random.default_rng(3)
    pt_direct = rng.random((4, 4, 3)).astype(np.float32)
    pt = pt_direct + rng.random((4, 4, 3)).astype(np.float32)
    alb = np.full((4, 4, 3), albedo, np.float32)
    t = target_radiance(pt, pt_direct, alb, "indirect", True)
    assert np.all(np.isfinite(t)) and np.all(np.abs(t) <= np.abs(pt - pt_direct) / ALBEDO_FLOOR * 1.0001)
    back = compose_radiance(t, pt_direct, alb, "indirect", True)
    np.testing.assert_allclose(back, pt, rtol=1e-5)


# --- eval on a black reference -----------------------------------------------------------------
def test_eval_warns_on_black_reference_and_writes_strict_json(tmp_path, capsys):
    from diviewer.cli import main
    from diviewer.data.dataset import Dataset, write_frame
    from onnx_models import base_meta, direct_times
    from test_extremes_files import make_dataset

    ds = make_dataset(tmp_path / "data", frames=4, width=16, height=16)
    for f in ds.frames:  # all black, and a model that outputs exactly black: PSNR is infinite
        write_frame(ds, f["index"], np.zeros((ds.height, ds.width, ds.num_channels), ds.dtype),
                    {"index": f["index"], "split": f["split"]})
    meta = {**base_meta(scene_hash=ds.manifest["scene_hash"], scene="cornell"), "multiple": 4}
    meta["encoding"] = {"version": 1, "exposure": 1.0}
    model = direct_times(tmp_path / "m.onnx", factor=0.0, meta=meta)
    out = tmp_path / "eval.json"
    assert main(["eval", "--model", str(model), "--data", str(ds.root), "--split", "train", "--out", str(out)]) == 0
    assert "all-black reference" in capsys.readouterr().out
    summary = json.loads(out.read_text(), parse_constant=lambda c: pytest.fail(f"non-strict JSON {c}"))
    assert summary["black_reference_frames"] == Dataset(ds.root).indices("train")
    assert summary["methods"]["neural"]["psnr"]["mean"] is None  # infinite: null, not Infinity


def test_eval_refuses_frames_smaller_than_the_ssim_window(tmp_path, capsys):
    from diviewer.cli import main
    from onnx_models import base_meta, direct_times
    from test_extremes_files import make_dataset

    ds = make_dataset(tmp_path / "data", frames=4)  # 8x4
    model = direct_times(tmp_path / "m.onnx", meta=base_meta(scene_hash=ds.manifest["scene_hash"]))
    assert main(["eval", "--model", str(model), "--data", str(ds.root), "--split", "train"]) == 2
    err = capsys.readouterr().err
    assert "resolution" in err and "11x11" in err and err.count("\n") == 1
