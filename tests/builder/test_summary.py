"""The build's last lines and the rules of what they suggest (diviewer.builder.summary), on synthetic records."""

from __future__ import annotations

from diviewer.builder.summary import larger_k_helps, still_improving, suggestions, summary_lines, weakest


def _method(psnr, lit=None, shade=None, obj=None, stride=None, eq=None):
    m = {"psnr_tm": {"mean": psnr}}
    for key, v in (("psnr_tm_lit", lit), ("psnr_tm_shade", shade), ("psnr_tm_object", obj)):
        if v is not None:
            m[key] = {"mean": v}
    if stride is not None:
        m["stride_shade"] = {"mean": stride, "max": stride, "frames": 4}
    if eq is not None:
        m["equivalent_spp"] = {"psnr_tm": {"text": eq}}
    return m


def _ev(moved=36.0, moved_shade=27.1, stride=0.10):
    return {"splits": {
        "unseen_configs": {"frames": 4, "methods": {"s_k8": _method(39.0, 40.0, 35.0, eq="180"),
                                                     "direct": _method(14.0)}},
        "moved_camera": {"frames": 4, "methods": {"s_k8": _method(moved, 38.0, moved_shade, stride=stride, eq="60"),
                                                   "direct": _method(14.2)}}}}


LEVEL = [{"val_psnr_tm": v} for v in (30.0, 33.0, 34.0, 34.1, 34.1, 34.1, 34.1, 34.1)]
RISING = [{"val_psnr_tm": v} for v in (30.0, 31.0, 32.0, 33.0, 34.0, 35.0, 36.0, 37.0)]
LADDER_FLAT = [{"K": 8, "evalset_psnr_tm": 37.0}, {"K": 16, "evalset_psnr_tm": 37.2}]
LADDER_CLIMBING = [{"K": 8, "evalset_psnr_tm": 36.0}, {"K": 16, "evalset_psnr_tm": 37.5}]


def test_the_summary_names_direct_light_the_equivalent_spp_and_the_weakest_split_and_region():
    lines = summary_lines(_ev(), "s_k8", LADDER_FLAT, 0.5, LEVEL)
    assert "37.50 dB" in lines[0] and "direct light alone 14.10 dB" in lines[0]
    assert "unseen_configs 180" in lines[0] and "moved_camera 60" in lines[0]
    assert lines[1].startswith("weakest: moved_camera, shade: 27.10 dB") and "stride pattern of 10%" in lines[1]
    assert weakest(_ev(), "s_k8") == ("moved_camera", "shade", 27.1)
    assert "stride" not in summary_lines(_ev(stride=0.02), "s_k8", LADDER_FLAT, 0.5, LEVEL)[1]


def test_a_lagging_held_out_camera_asks_for_ranges_that_cover_it():
    s = suggestions(_ev(moved=36.0), "s_k8", LADDER_FLAT, 0.5, LEVEL)
    assert len(s) == 1 and s[0].startswith("ranges that cover the held-out camera") and "3.0 dB" in s[0]


def test_a_training_still_rising_asks_for_more_steps_and_a_climbing_ladder_for_a_larger_k():
    assert still_improving(RISING) and not still_improving(LEVEL) and still_improving(LEVEL[:3]) is None
    assert larger_k_helps(LADDER_CLIMBING, 0.5) and not larger_k_helps(LADDER_FLAT, 0.5)
    assert not larger_k_helps(LADDER_FLAT[:1], 0.5)
    s = suggestions(_ev(moved=38.5), "s_k8", LADDER_CLIMBING, 0.5, RISING)
    assert s[0].startswith("more steps") and s[1].startswith("a larger K: K=16") and "--ks 16 32" in s[1]


def test_with_nothing_else_lagging_it_asks_for_more_frames():
    s = suggestions(_ev(moved=38.5), "s_k8", LADDER_FLAT, 0.5, LEVEL)
    assert s == [s[0]] and s[0].startswith("more frames")


def test_a_curve_too_short_to_read_is_not_called_levelled_off():
    s = suggestions(_ev(moved=38.5), "s_k8", LADDER_FLAT, 0.5, LEVEL[:2])
    assert s[0].startswith("more frames: the training had too few validations to tell")
    assert "levelled off" in suggestions(_ev(moved=38.5), "s_k8", LADDER_FLAT, 0.5, LEVEL)[0]
