"""Dynamic resolution's scale controller, auto exposure and the GI shape policy: pure Python, no window."""

from __future__ import annotations

import math

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.exposure import AutoExposure, ExposureSettings, metered_ev, still_ev
from diviewer.viewer.models import gi_resolution, runtime_pads
from diviewer.viewer.scale import DEFAULT_FLOOR, ScaleController, ScaleSettings, render_size

# (a, b): frame ms = a + b * scale^2 (a: the network and fixed costs, b: per-pixel work), at 30 fps (33.3 ms).
COSTS = [(5.0, 60.0), (20.0, 40.0), (10.0, 25.0), (2.0, 200.0), (30.0, 10.0), (5.0, 20.0), (15.0, 100.0)]


def _run(a: float, b: float, seed: int, frames: int = 600, noise: float = 0.05, settings=ScaleSettings()):
    """Drive a controller with a noisy synthetic cost model; the scale of every frame."""
    rng = np.random.default_rng(seed)
    c = ScaleController(settings)
    scales = []
    for _ in range(frames):
        s = c.scale
        scales.append(s)
        c.update((a + b * s * s) * (1.0 + noise * rng.standard_normal()), s)
    return c, np.array(scales)


@pytest.mark.parametrize("a,b", COSTS)
def test_scale_converges_stays_in_bounds_and_does_not_oscillate(a, b):
    target, floor = 1e3 / 30.0, ScaleSettings().floor
    cost = lambda s: a + b * s * s
    for seed in range(4):
        c, scales = _run(a, b, seed)
        assert scales.min() >= floor and scales.max() <= 1.0, "left its bounds"
        # Converged: from frame 300 on, the scale is within one step of where it ends (noise at the edge of
        # the dead band may still take one more step, in the same direction) ...
        s = scales[-1]
        assert np.ptp(scales[300:]) <= 1 / 32 + 1e-12, f"still moving: {np.unique(scales[300:])}"
        # ... at a scale that holds the frame rate where the floor allows it, and is not needlessly low: at the
        # window's size, at the floor, or where one step up would leave the dead band's lower edge.
        if cost(floor) <= target:
            assert cost(s) <= target * 1.03, f"scale {s} costs {cost(s):.1f} ms > {target:.1f}"
        else:
            assert s == floor
        assert s == 1.0 or s == floor or cost(s + 2 / 32) >= 0.8 * target
        # No oscillation: the scale moved in one direction only, a handful of times.
        moves = np.sign(np.diff(scales)[np.diff(scales) != 0])
        assert len(set(moves.tolist())) <= 1, f"the scale went both ways: {moves}"
        assert c.changes == len(moves) <= 12


def test_scale_rises_from_the_floor_when_the_frame_is_cheap():
    c, scales = _run(2.0, 8.0, 0, settings=ScaleSettings(start=0.5))
    assert scales[0] == 0.5 and scales[-1] == 1.0
    assert np.all(np.diff(scales) >= 0)


def test_scale_holds_in_the_dead_band_and_ignores_stale_or_broken_times():
    c = ScaleController(ScaleSettings(start=0.75))
    for _ in range(100):  # 30 ms: inside [0.8, 1] of the 33.3 ms target
        c.update(30.0)
    assert c.scale == 0.75 and c.changes == 0
    for bad in (float("nan"), float("inf"), 0.0, -3.0):
        assert c.update(bad) == 0.75
    for _ in range(100):  # times measured at another scale (before a change) are not this scale's
        c.update(500.0, scale=0.6)
    assert c.scale == 0.75
    off = ScaleController(ScaleSettings(target_fps=0.0, start=0.6))
    assert not off.enabled and all(off.update(t) == 0.6 for t in (1.0, 500.0))


def test_fix_and_hold():
    c = ScaleController()
    assert c.fix(0.3) == 0.3 and not c.enabled and c.settings.floor == 0.3
    for _ in range(50):
        c.update(1000.0)
    assert c.scale == 0.3
    assert c.hold(60.0) == 60.0 and c.enabled and c.scale == 0.3
    assert c.fix(2.0) == 2.0 and c.settings.ceiling == 2.0  # a fixed supersampled scale
    with pytest.raises(ValueError):
        ScaleController(ScaleSettings(floor=0.0))


def test_render_size_rounds_and_keeps_a_pixel():
    assert render_size((768, 768), 0.5) == (384, 384)
    assert render_size((1024, 768), 0.71875) == (736, 552)
    assert render_size((1, 3), 0.25) == (1, 1)


def test_render_scale_setting_and_command_line():
    import argparse

    from diviewer.commands.view import add_parser as add_view_parser
    from diviewer.viewer.settings import ViewerSettings, check_render_scale, scale_settings

    assert scale_settings(ViewerSettings()).target_fps == 30.0
    fixed = scale_settings(ViewerSettings(render_scale=0.4))
    assert fixed.target_fps == 0.0 and fixed.start == 0.4 and fixed.floor == 0.4
    for bad in (0.0, -1.0, 2.5, float("nan")):
        with pytest.raises(DiviewerError, match="render scale"):
            check_render_scale(bad)
    supersampled = scale_settings(ViewerSettings(render_scale=2.0))
    assert check_render_scale(2.0) == 2.0 and supersampled.start == supersampled.ceiling == 2.0
    assert ScaleController(supersampled).scale == 2.0
    ap = argparse.ArgumentParser()
    add_view_parser(ap.add_subparsers(dest="command"))
    args = ap.parse_args(["view"])
    assert args.target_fps == 30.0 and args.render_scale is None and not args.auto_exposure
    assert args.scale_floor == DEFAULT_FLOOR == ScaleSettings().floor == 0.4
    args = ap.parse_args(["view", "--target-fps", "0", "--render-scale", "0.5", "--auto-exposure"])
    assert args.target_fps == 0.0 and args.render_scale == 0.5 and args.auto_exposure
    assert ap.parse_args(["view", "--no-auto-exposure"]).auto_exposure is False
    assert ap.parse_args(["view"]).auto_exposure is None  # as the scene file says
    assert args.scale_ceiling == 1.0 == ScaleSettings().ceiling


@pytest.mark.parametrize("flag,value", [("--scale-ceiling", "0.9"), ("--scale-ceiling", "2.5"),
                                        ("--render-scale", "3")])
def test_scales_outside_their_ranges_are_refused_by_flag(flag, value, capsys):
    from diviewer.cli import main

    assert main(["view", "--frames", "1", flag, value]) == 2
    assert flag in capsys.readouterr().err


def test_scale_rises_above_one_up_to_the_ceiling_when_the_frame_is_cheap():
    """With a ceiling of 2 a cheap frame is supersampled: the scale climbs past 1 and stops at the ceiling."""
    c, scales = _run(2.0, 4.0, 0, settings=ScaleSettings(start=1.0, ceiling=2.0))
    assert scales[-1] == 2.0 and np.all(np.diff(scales) >= 0)
    _, plain = _run(2.0, 4.0, 0, settings=ScaleSettings(start=1.0))
    assert max(plain) == 1.0
    with pytest.raises(ValueError, match="ceiling"):
        ScaleController(ScaleSettings(ceiling=0.5))


# --- auto exposure -------------------------------------------------------------------------------------

def test_metered_exposure_maps_the_log_average_to_middle_grey():
    rng = np.random.default_rng(1)
    grey = np.exp(rng.normal(np.log(0.05), 0.5, (64, 64, 1))).repeat(3, axis=-1).astype(np.float32)
    ev = metered_ev(grey)
    s = ExposureSettings()
    lum = np.sort(grey[..., 0].ravel())
    k = int(len(lum) * s.trim)
    assert ev == pytest.approx(math.log2(0.18) - np.log2(lum[k:len(lum) - k]).mean(), abs=1e-5)
    assert metered_ev(grey * 2.0) == pytest.approx(ev - 1.0, abs=1e-5)  # twice the light: one stop less
    # Unlit samples (the void), NaN and infinities are not metered; nothing lit gives no exposure.
    holed = grey.copy()
    holed[:32] = 0.0
    holed[0, 0] = np.nan
    holed[1, 1] = np.inf
    assert metered_ev(holed) == pytest.approx(metered_ev(grey[32:]), abs=1e-5)
    assert metered_ev(np.zeros((8, 8, 3), np.float32)) is None
    assert metered_ev(np.full((8, 8, 3), 1e-9, np.float32)) is None
    assert metered_ev(np.full((4, 4, 3), 2e-6, np.float32)) == ExposureSettings().limits[1]  # clamped
    # Sponza's darkest gallery (median luminance ~2e-5) is metered, not held at the limit: +13.1 stops
    assert metered_ev(np.full((4, 4, 3), 2e-5, np.float32)) == pytest.approx(np.log2(0.18 / 2e-5), abs=1e-3)


def test_auto_exposure_is_smoothed_and_deterministic():
    frames = [np.full((8, 8, 3), v, np.float32) for v in [0.18] * 3 + [0.72] * 40 + [0.0] * 3]
    runs = []
    for _ in range(2):
        auto = AutoExposure()
        runs.append([auto.update(f) for f in frames])
    assert runs[0] == runs[1]  # the same frames give the same exposures
    evs = runs[0]
    assert evs[0] == pytest.approx(0.0, abs=1e-6)  # the first frame snaps to its metered exposure
    assert evs[3] == pytest.approx(-2.0 * ExposureSettings().rate, abs=1e-6)  # then 15 % of the way per frame
    assert all(b < a for a, b in zip(evs[3:42], evs[4:43]))  # monotone towards the new exposure ...
    assert evs[42] == pytest.approx(-2.0, abs=0.01)  # ... which it reaches
    assert evs[-1] == evs[42]  # black frames leave it alone
    auto = AutoExposure()
    auto.update(frames[5])
    auto.reset()
    assert auto.ev is None and auto.update(frames[0]) == pytest.approx(0.0, abs=1e-6)


def test_a_still_is_shown_at_the_fixed_exposure_or_its_own_metered_one():
    """`still_ev` (render's PNGs, capture thumbnails): the scene file's exposure unless it asks for auto exposure;
    then the meter's reading of that image, rounded as recorded; an image with nothing lit keeps the fixed one."""
    rgb = np.full((8, 8, 3), 0.18 / 4, np.float32)  # two stops under middle grey
    assert still_ev(-1.5, False, rgb) == (-1.5, False)
    assert still_ev(-1.5, True, rgb) == (2.0, True) == still_ev(-1.5, True, rgb.copy())
    assert still_ev(-1.5, True, np.zeros((8, 8, 3), np.float32)) == (-1.5, False)


def test_state_auto_exposure_follows_the_meter_only_when_on():
    from diviewer.scene import load_scene
    from diviewer.viewer.state import ViewerState

    st = ViewerState(load_scene("cornell"))
    bright = np.full((4, 4, 3), 0.72, np.float32)
    assert st.meter(bright) == st.exposure == 0.0  # off: the slider's exposure stays
    st.set_auto_exposure(True)
    assert st.meter(bright) == pytest.approx(-2.0, abs=1e-6)
    st.set_auto_exposure(False)
    st.set_exposure(1.5)
    assert st.meter(bright) == 1.5


# --- the GI's shape -------------------------------------------------------------------------------------

def test_gi_resolution_follows_the_window_shape_at_the_model_rows():
    model = (128, 128)
    assert gi_resolution("model", (1024, 768), model, 128, pads=True) == (171, 128)
    assert gi_resolution("model", (768, 1024), model, 128, pads=True) == (96, 128)
    assert gi_resolution("model", (1920, 1080), model, 128, pads=True) == (228, 128)
    assert gi_resolution("model", (768, 768), model, 128, pads=True) == (128, 128)
    # The shape comes from the window, the fraction from the shading size (the render scale's).
    assert gi_resolution("model", (512, 384), model, 128, pads=True, shape=(1024, 768)) == (171, 128)
    assert gi_resolution("1/4", (512, 384), model, 128, pads=True, shape=(1024, 768)) == (128, 96)
    assert gi_resolution("200x120", (512, 384), model, 128, pads=True) == (200, 120)
    # A runtime that cannot pad: snapped to its stride (a wide window squashed into the training width) ...
    assert gi_resolution("model", (1024, 768), model, 128) == (128, 128)
    assert gi_resolution("model", (1920, 1080), model, 128) == (256, 128)
    assert gi_resolution("1/2", (300, 200), (64, 48), 16) == (144, 96)
    # ... and an explicit size off the stride is refused.
    with pytest.raises(DiviewerError, match="multiple of the model's stride 128"):
        gi_resolution("200x120", (512, 384), model, 128)


def test_runtime_pads_asks_the_runtime(ctx):
    class Strict:
        multiple, resolution = 16, (64, 48)

        def check_size(self, w, h):
            if w % 16 or h % 16:
                raise DiviewerError("multiples of 16")

        def shape_note(self, w, h):
            return ""

    class Padding(Strict):
        def check_size(self, w, h):
            return None

    class SquareOnly(Padding):  # trained on square frames only (runtime.NeuralGI.shape_note)
        def shape_note(self, w, h):
            return "" if w == h else f"never trained at {w}x{h}"

    assert not runtime_pads(Strict()) and runtime_pads(Padding())
    # The viewer's GI control: the shape it asks for, and what a runtime without padding runs instead.
    from diviewer.gl.neural import GISettings
    from diviewer.scene import load_scene
    from diviewer.viewer.gi import GIControl
    from diviewer.viewer.state import ViewerState

    class Renderer:
        width, height = 75, 48  # a 150x96 window at render scale 0.5

    gi = GIControl(ctx, Renderer(), ViewerState(load_scene("cornell")), "model", GISettings())  # ctx: the GL size check
    gi.view_size = (150, 96)
    assert gi.sizes(Padding(), "model") == ((75, 48), (75, 48))
    assert gi.sizes(Strict(), "model") == ((80, 48), (75, 48))
    assert gi.sizes(Padding(), "1/3") == ((25, 16), (25, 16))
    assert gi._size_for(Strict(), "model", (75, 48)) == (80, 48) and "instead of 75x48" in gi.note
    assert gi._size_for(Padding(), "model", (75, 48)) == (75, 48) and gi.note == ""
    # A shape the model never saw still runs, and the note (panel, --stats) says so.
    assert gi._size_for(SquareOnly(), "model", (75, 48)) == (75, 48) and gi.note == "never trained at 75x48"


def test_the_linear_filter_at_half_size_is_each_2x2_blocks_mean():
    """What --render-scale 2 shows: GL's linear filter sampling a texture at half its size lands halfway between
    four texels, so each window pixel is the mean of its 2x2 block (the numpy model the viewer tests use)."""
    from oracles import bilinear

    img = np.random.default_rng(3).random((12, 10, 3)).astype(np.float32)
    half = bilinear(img, 5, 6)
    np.testing.assert_allclose(half, img.reshape(6, 2, 5, 2, 3).mean(axis=(1, 3)), rtol=1e-6, atol=1e-7)


def test_a_moving_suns_map_follows_the_shaded_size_within_its_limit():
    from diviewer.viewer.scale import moving_map_size

    assert moving_map_size(2048, (307, 307)) == 1024  # two texels a shaded pixel: 614 -> the next power of two
    assert moving_map_size(2048, (768, 768)) == 2048
    assert moving_map_size(2048, (1536, 864)) == 2048  # never above the limit
    assert moving_map_size(2048, (16, 16)) == 256  # never below 256
    assert moving_map_size(None, (307, 307)) is None  # no moving size: the map keeps the scene's size
