"""Auto exposure: an exposure (EV) measured from the shown frame's luminance and smoothed over frames. No GL: the
viewer meters its frames with it, and `diviewer render` the PNGs of a scene that asks for auto exposure.

The meter (shaders/meter.glsl) samples the frame's linear radiance on a fixed grid; ``AutoExposure`` takes
the log-average luminance of the lit samples (the darkest and brightest ``trim`` left out, so a patch of sky
or a blown-out window does not set the exposure), asks for the exposure that maps it to middle grey
(``key``), and moves towards it by a fixed fraction per frame. Per frame, not per second: the exposure is a
function of the frames shown alone, so a scripted run gives the same exposures on any machine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)
"""Rec. 709 luminance weights of linear RGB."""


@dataclass(frozen=True)
class ExposureSettings:
    """How the auto exposure meters and adapts."""

    key: float = 0.18
    """The luminance the frame's log-average is exposed to (middle grey)."""
    trim: float = 0.05
    """Share of the darkest and of the brightest lit samples left out of the average."""
    rate: float = 0.15
    """Fraction of the way to the metered exposure taken each frame (the first frame takes all of it)."""
    limits: tuple[float, float] = (-16.0, 16.0)
    """Range of the exposure (stops), as the panel's slider. Sponza's full evaluation set meters from +3.6 to +13.4
    stops (a gallery no sunlight reaches); at the +-8 of before, 35 of its 72 frames were held at +8, up to 5.4 stops
    darker than metered, and its shade was not shown (docs/accuracy.md). 16 stops still keeps a frame lit only by
    what is barely above ``floor`` from being blown up to middle grey."""
    floor: float = 1e-6
    """Samples darker than this are unlit (the void, the background) and not metered."""


def metered_ev(rgb: np.ndarray, settings: ExposureSettings = ExposureSettings()) -> float | None:
    """The exposure (stops) that maps the trimmed log-average luminance of ``rgb`` (..., 3) to ``key``;
    None when nothing is lit (no finite sample brighter than ``floor``)."""
    lum = np.asarray(rgb, np.float32).reshape(-1, 3) @ LUMA
    lum = np.sort(lum[np.isfinite(lum) & (lum > settings.floor)])
    if len(lum) == 0:
        return None
    k = int(len(lum) * settings.trim)
    kept = lum[k: len(lum) - k] if len(lum) - 2 * k > 0 else lum
    mean_log2 = float(np.mean(np.log2(kept)))
    lo, hi = settings.limits
    return min(max(math.log2(settings.key) - mean_log2, lo), hi)


def still_ev(fixed: float, auto: bool, rgb: np.ndarray) -> tuple[float, bool]:
    """The exposure (stops) to show one still image at, and whether it was metered: a scene file's ``exposure``
    (``fixed``), or where it asks for ``auto_exposure`` the meter's reading of ``rgb`` (rounded to 1e-4 stops, as
    recorded), falling back to ``fixed`` where nothing in the image is lit."""
    ev = metered_ev(rgb) if auto else None
    return (fixed, False) if ev is None else (round(ev, 4), True)


class AutoExposure:
    """The smoothed exposure: ``update(samples)`` once per shown frame, ``ev`` is what to show it at."""

    def __init__(self, settings: ExposureSettings = ExposureSettings()):
        self.settings = settings
        self.ev: float | None = None
        """The current exposure (stops); None before the first lit frame."""
        self.metered: float | None = None
        """The last frame's own metered exposure (before smoothing)."""

    def update(self, rgb: np.ndarray) -> float | None:
        """Meter one frame's samples and move the exposure towards it; returns the exposure to show."""
        self.metered = metered_ev(rgb, self.settings)
        if self.metered is not None:
            if self.ev is None:
                self.ev = self.metered
            else:
                self.ev += self.settings.rate * (self.metered - self.ev)
        return self.ev

    def reset(self) -> None:
        self.ev = self.metered = None
