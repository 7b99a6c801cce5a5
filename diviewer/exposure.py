"""Auto exposure: an exposure (EV) measured from the shown frame's luminance and smoothed over frames. No GL: the
viewer meters its frames with it, and `diviewer render` the PNGs of a scene that asks for auto exposure.

The meter (shaders/meter.glsl) samples the frame's linear radiance on a fixed grid; ``AutoExposure`` takes
the log-average luminance of the lit samples (the darkest and brightest ``trim`` left out, so a patch of sky
or a blown-out window does not set the exposure), asks for the exposure that maps it to middle grey
(``key``), lowers it where more than ``highlights`` of the lit samples would reach the tone curve's white (so a
sunlit floor keeps its texture instead of clipping), and moves towards it by a fixed fraction per frame. Per frame, not per second: the exposure is a
function of the frames shown alone, so a scripted run gives the same exposures on any machine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)
"""Rec. 709 luminance weights of linear RGB."""

WHITE_POINTS: dict[str, float] = {"aces": (0.56 + math.sqrt(0.56 ** 2 + 4 * 0.08 * 0.14)) / 0.16, "clamp": 1.0,
                                  "reinhard": math.inf}
"""Per tone curve (shaders/tonemap.glsl), the exposed radiance from which a channel is shown as full white: Narkowicz's
ACES fit reaches 1 at 7.2417 (the root of 0.08 x^2 - 0.56 x - 0.14), the clamp at 1; Reinhard never does."""


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
    darker than metered, and its shade was not shown (docs/accuracy.md at commit c48f1bc). 16 stops still keeps a frame lit only by
    what is barely above ``floor`` from being blown up to middle grey."""
    floor: float = 1e-6
    """Samples darker than this are unlit (the void, the background) and not metered."""
    highlights: float = 0.0
    """Share of the lit samples allowed to reach the tone curve's white: the exposure is lowered until no more do
    (0: no ceiling, the key alone). The viewer and render's PNGs use ``SHOWN`` (0.5 %)."""


SHOWN = ExposureSettings(highlights=0.005)
"""How the viewer and `diviewer render`'s PNGs meter: the key, with highlights kept (at most 0.5 % of the lit
samples at white). Training's loss weights and the capture's thumbnails meter with the key alone."""


def _lit_max(rgb: np.ndarray, floor: float) -> tuple[np.ndarray, np.ndarray]:
    """The finite samples of ``rgb`` (..., 3) brighter than ``floor``: their luminance and their largest channel."""
    flat = np.asarray(rgb, np.float32).reshape(-1, 3)
    lum = flat @ LUMA
    keep = np.isfinite(lum) & (lum > floor)
    return lum[keep], flat[keep].max(axis=1)


def clipped_share(rgb: np.ndarray, ev: float, white: float) -> float:
    """Share of the pixels of ``rgb`` (..., 3) shown as white in some channel at exposure ``ev`` on a curve whose
    white is ``white`` (`WHITE_POINTS`); non-finite pixels count as clipped."""
    flat = np.asarray(rgb, np.float32).reshape(-1, 3)
    if len(flat) == 0 or not math.isfinite(white):
        return 0.0
    peak = np.max(np.where(np.isfinite(flat), flat, np.inf), axis=1)
    return float(np.mean(peak * np.float32(2.0 ** ev) >= white))


def metered_ev(rgb: np.ndarray, settings: ExposureSettings = ExposureSettings(),
               white: float = WHITE_POINTS["aces"]) -> float | None:
    """The exposure (stops) that maps the trimmed log-average luminance of ``rgb`` (..., 3) to ``key``, lowered
    where ``settings.highlights`` asks so that no more than that share of the lit samples reach ``white`` (the tone
    curve's, `WHITE_POINTS`); None when nothing is lit (no finite sample brighter than ``floor``)."""
    lum, peak = _lit_max(rgb, settings.floor)
    if len(lum) == 0:
        return None
    lum = np.sort(lum)
    k = int(len(lum) * settings.trim)
    kept = lum[k: len(lum) - k] if len(lum) - 2 * k > 0 else lum
    ev = math.log2(settings.key) - float(np.mean(np.log2(kept)))
    if settings.highlights > 0 and math.isfinite(white):
        bright = float(np.quantile(np.minimum(peak, np.float32(3e38)), 1.0 - settings.highlights))
        ev = min(ev, math.log2(white) - math.log2(bright))
    lo, hi = settings.limits
    return min(max(ev, lo), hi)


def still_ev(fixed: float, auto: bool, rgb: np.ndarray, settings: ExposureSettings = ExposureSettings(),
             white: float = WHITE_POINTS["aces"]) -> tuple[float, bool]:
    """The exposure (stops) to show one still image at, and whether it was metered: a scene file's ``exposure``
    (``fixed``), or where it asks for ``auto_exposure`` the meter's reading of ``rgb`` (rounded to 1e-4 stops, as
    recorded), falling back to ``fixed`` where nothing in the image is lit."""
    ev = metered_ev(rgb, settings, white) if auto else None
    return (fixed, False) if ev is None else (round(ev, 4), True)


class AutoExposure:
    """The smoothed exposure: ``update(samples)`` once per shown frame, ``ev`` is what to show it at."""

    def __init__(self, settings: ExposureSettings = ExposureSettings()):
        self.settings = settings
        self.ev: float | None = None
        """The current exposure (stops); None before the first lit frame."""
        self.metered: float | None = None
        """The last frame's own metered exposure (before smoothing)."""
        self.clipped: float | None = None
        """Share of the last frame's samples shown as white at ``ev`` (None before the first lit frame)."""

    def update(self, rgb: np.ndarray, white: float = WHITE_POINTS["aces"]) -> float | None:
        """Meter one frame's samples for a tone curve whose white is ``white`` and move the exposure towards it;
        returns the exposure to show."""
        self.metered = metered_ev(rgb, self.settings, white)
        if self.metered is not None:
            if self.ev is None:
                self.ev = self.metered
            else:
                self.ev += self.settings.rate * (self.metered - self.ev)
            self.clipped = clipped_share(rgb, self.ev, white)
        return self.ev

    def reset(self) -> None:
        self.ev = self.metered = self.clipped = None
