"""The exposure meter's highlight ceiling: a sunlit patch keeps its texture, the key alone is unchanged."""

import math

import numpy as np
import pytest

from diviewer.exposure import SHOWN, WHITE_POINTS, AutoExposure, ExposureSettings, clipped_share, metered_ev


def _sunlit(share: float, ratio: float = 300.0, size: int = 100) -> np.ndarray:
    """A grey frame (0.01) whose first ``share`` of pixels are ``ratio`` times brighter, with a little texture."""
    rng = np.random.default_rng(0)
    rgb = np.full((size * size, 3), 0.01, np.float32) * rng.uniform(0.8, 1.2, (size * size, 1)).astype(np.float32)
    n = int(share * size * size)
    rgb[:n] *= ratio
    return rgb.reshape(size, size, 3)


def test_aces_white_point_is_where_the_curve_reaches_one():
    x = WHITE_POINTS["aces"]
    aces = (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)
    assert aces == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("share", [0.02, 0.05, 0.2])
def test_the_ceiling_keeps_all_but_the_allowed_share_of_highlights(share):
    rgb = _sunlit(share)
    key_only = metered_ev(rgb)
    kept = metered_ev(rgb, SHOWN)
    assert clipped_share(rgb, key_only, WHITE_POINTS["aces"]) >= share * 0.99  # the key alone blows the patch
    assert kept < key_only
    assert clipped_share(rgb, kept, WHITE_POINTS["aces"]) <= SHOWN.highlights + 1e-4


def test_no_ceiling_where_nothing_is_bright_or_the_curve_has_no_white():
    rgb = _sunlit(0.0)
    assert metered_ev(rgb, SHOWN) == metered_ev(rgb)  # a frame without highlights is metered by its key
    bright = _sunlit(0.2)
    assert metered_ev(bright, SHOWN, WHITE_POINTS["reinhard"]) == metered_ev(bright)
    assert clipped_share(bright, 30.0, WHITE_POINTS["reinhard"]) == 0.0


def test_defaults_meter_by_the_key_alone():
    """Training's loss weights and the capture's thumbnails meter with the defaults: the key, no ceiling."""
    assert ExposureSettings().highlights == 0.0
    rgb = _sunlit(0.05)
    lum = rgb.reshape(-1, 3) @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    lum = np.sort(lum)
    k = int(len(lum) * 0.05)
    expect = math.log2(0.18) - float(np.mean(np.log2(lum[k:len(lum) - k])))
    assert metered_ev(rgb) == pytest.approx(expect, abs=1e-6)


@pytest.mark.extremes
def test_clipped_share_counts_non_finite_pixels_and_survives_huge_values():
    rgb = np.full((4, 4, 3), 0.1, np.float32)
    rgb[0, 0] = np.nan
    rgb[0, 1] = np.inf
    rgb[0, 2] = 3e38
    assert clipped_share(rgb, 0.0, WHITE_POINTS["aces"]) == pytest.approx(3 / 16)
    ev = metered_ev(rgb, SHOWN)
    assert ev is not None and math.isfinite(ev) and SHOWN.limits[0] <= ev <= SHOWN.limits[1]


def test_auto_exposure_reports_the_clipped_share_at_the_shown_exposure():
    auto = AutoExposure(SHOWN)
    assert auto.clipped is None
    rgb = _sunlit(0.05)
    ev = auto.update(rgb)
    assert auto.clipped == clipped_share(rgb, ev, WHITE_POINTS["aces"]) <= SHOWN.highlights + 1e-4
    auto.reset()
    assert auto.clipped is None
