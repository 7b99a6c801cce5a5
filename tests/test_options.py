"""The numeric options' table: the values each takes, a subcommand's narrower rule, and the GL limits hook."""

from __future__ import annotations

import pytest
from hypothesis import given, strategies as st

from diviewer.cli import build_parser
from diviewer.errors import DiviewerError
from diviewer.options import GL_GUARANTEED, OPTIONS, check_options, option_spec
from diviewer.train.config import TRAIN_FIELDS
from diviewer.train.recipe_fields import TRUTH_FILTER

AP = build_parser()


def _check(argv, gl_info=None):
    check_options(AP, AP.parse_args(argv), gl_info)


@pytest.mark.parametrize("argv", [
    ["view", "--size", "1024x768", "--gi-res", "1/4", "--target-fps", "0", "--scale-floor", "0.25"],
    ["view", "--gi-res", "model"], ["view", "--gi-res", "256x128"], ["view", "--gi-res", "2/4"],
    ["render", "--out", "o", "--res", "8192", "--exposure", "-12.5", "--seed", "4294967295"],
    ["capture", "--out", "o", "--splits", "8,1,1", "--shard", "2/3", "--thumbs", "0"],
    ["evalset", "--out", "o", "--ladder", "1,4,16", "--window-widths", "170,228", "--res", "16"],
    ["bench", "--res", "16", "8192", "--vxgi-grids", "32", "256", "--gi-steps", "1", "2"],
    ["train", "--data", "d", "--out", "o", "--aspect-crops", "9/16:16/9", "--lr", "1e-9", "--d-lr", "1"],
    ["train", "--data", "d", "--out", "o", "--aspect-crops", "off"],
    ["data", "filter-truth", "d", "--out", "o", "--normal-power", "1024", "--range-sigma", "0"],
    ["build", "--scene", "cornell", "--budget", "0.5", "--ks", "8", "16"],
    ["eval", "--model", "m.onnx", "--exposure", "metered"], ["eval", "--model", "m.onnx", "--exposure", "Scene"],
    ["eval", "--model", "m.onnx", "--exposure", "-12.5"],
])
def test_values_in_range_pass(argv):
    _check(argv)


@pytest.mark.parametrize("argv,option", [
    (["evalset", "--out", "o", "--res", "15"], "--res"),  # an evaluation set's SSIM window needs 16
    (["render", "--out", "o", "--res", "15"], None),  # render takes it
    (["bench", "--res", "100000"], "--res"),
    (["bench", "--res", "16", "0"], "--res"),  # each value of a list
    (["view", "--gi-res", "1/32"], "--gi-res"),
    (["evalset", "--out", "o", "--ladder", "4,1"], "--ladder"),
    (["evalset", "--out", "o", "--window-widths", "170,170"], "--window-widths"),
    (["capture", "--out", "o", "--shard", "0/3"], "--shard"),
    (["train", "--data", "d", "--out", "o", "--aspect-crops", "2:1"], "--aspect-crops"),
    (["eval", "--model", "m.onnx", "--exposure", "abc"], "--exposure"),  # scene, metered or render's stops
    (["eval", "--model", "m.onnx", "--exposure", "41"], "--exposure"),
])
def test_a_subcommands_own_rule_and_values_in_strings(argv, option):
    if option is None:
        _check(argv)
        return
    with pytest.raises(DiviewerError, match=option):
        _check(argv)


def test_options_that_fill_a_settings_field_take_its_spec():
    """One rule: `train --k` is TrainConfig.K's, `data filter-truth --levels` the recipe's truth_filter.levels."""
    assert OPTIONS["K"] is TRAIN_FIELDS["K"] and OPTIONS["lr"] is TRAIN_FIELDS["lr"]
    assert OPTIONS["max_steps"] is TRAIN_FIELDS["max_steps"].spec
    assert all(OPTIONS[name] is spec for name, spec in TRUTH_FILTER.items())
    assert option_spec("bench", "res") is not option_spec("render", "res")


def test_gl_limits_hook_bounds_sizes_by_a_contexts_limits():
    """Without a context the GL 4.3 guarantees apply (above every static cap); a caller holding one passes
    ``ctx.info`` and a size beyond its limits is refused naming the limit."""
    _check(["view", "--size", "4096x2048", "--gi-res", "2048x1024"])
    small = {"GL_MAX_TEXTURE_SIZE": 2048, "GL_MAX_RENDERBUFFER_SIZE": 4096, "GL_MAX_3D_TEXTURE_SIZE": 128}
    with pytest.raises(DiviewerError, match="--size.*GL_MAX_TEXTURE_SIZE 2048"):
        _check(["view", "--size", "4096x2048"], small)
    with pytest.raises(DiviewerError, match="--gi-res.*GL_MAX_TEXTURE_SIZE"):
        _check(["view", "--gi-res", "4096x64"], small)
    _check(["view", "--gi-res", "1/4"], small)  # a fraction of a window already within them
    with pytest.raises(DiviewerError, match="--vxgi-res.*GL_MAX_3D_TEXTURE_SIZE 128"):
        _check(["render", "--out", "o", "--vxgi-res", "256"], small)
    with pytest.raises(DiviewerError, match="--vxgi-grids"):
        _check(["bench", "--vxgi-grids", "64", "256"], small)
    assert GL_GUARANTEED["GL_MAX_TEXTURE_SIZE"] > OPTIONS["size"].hi


@given(st.one_of(st.floats(-40.0, 40.0).map(repr), st.sampled_from(["scene", "metered", "METERED", " scene "])))
def test_eval_exposure_takes_a_mode_or_renders_stops(value):
    _check(["eval", "--model", "m.onnx", f"--exposure={value}"])


@given(st.one_of(st.floats(max_value=-40.0, exclude_max=True), st.floats(min_value=40.0, exclude_min=True),
                 st.sampled_from(["nan", "inf", "-inf", "", "auto", "1/2", "5EV"])).map(str))
def test_eval_exposure_refuses_anything_else_naming_the_option(value):
    with pytest.raises(DiviewerError, match="--exposure"):
        _check(["eval", "--model", "m.onnx", f"--exposure={value}"])
