"""sRGB transfer functions (IEC 61966-2-1), defined once: texture decoding and 8-bit previews use these.

The GL side applies the same curve in shaders/tonemap.glsl (``linear_to_srgb``); a test compares the two.
"""

from __future__ import annotations

import numpy as np


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] to linear (float64), e.g. an 8-bit texture divided by 255."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    """Linear values to sRGB-encoded [0, 1] (float64); clamped to [0, 1] first, as a display does."""
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * np.power(c, 1 / 2.4) - 0.055)


def srgb8(linear: np.ndarray) -> np.ndarray:
    """A linear [0, 1] image (e.g. albedo) as uint8 sRGB, rounded; NaN shows as black."""
    return (linear_to_srgb(np.nan_to_num(linear)) * 255 + 0.5).astype(np.uint8)


LUMINANCE_WEIGHTS: tuple[float, float, float] = (0.2126, 0.7152, 0.0722)
"""Rec. 709 / sRGB primaries: relative luminance of linear RGB."""


def luminance(rgb) -> float:
    """Relative luminance of one linear RGB triple."""
    return float(sum(w * float(c) for w, c in zip(LUMINANCE_WEIGHTS, rgb)))
