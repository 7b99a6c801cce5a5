"""Image error metrics (numpy only, no torch): MSE, PSNR, SSIM.

Conventions, the same everywhere this package reports a number:

- Inputs are (H, W) or (H, W, C) float arrays of the same shape, compared as given: linear radiance
  for renders (no tone mapping, no clipping; HDR values above the peak count in full).
- ``peak`` (PSNR) and ``data_range`` (SSIM) default to 1.0: display white at exposure 0. A caller that
  compares tone-mapped images or other units passes its own and records it.
- SSIM is Wang et al. (2004): an 11x11 Gaussian window (sigma 1.5), K1 = 0.01, K2 = 0.03, computed
  per channel over the windows that lie wholly inside the image ("valid", as in the authors' code),
  and averaged over windows and channels.
"""

from __future__ import annotations

import math

import numpy as np


def _pair(a, b) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"images differ in shape: {a.shape} vs {b.shape}")
    if a.ndim not in (2, 3):
        raise ValueError(f"expected (H, W) or (H, W, C) images, got shape {a.shape}")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise ValueError("images contain NaN or infinite values")
    return a, b


def mse(a, b) -> float:
    """Mean squared error over all pixels and channels."""
    a, b = _pair(a, b)
    return float(np.mean((a - b) ** 2))


def psnr(a, b, peak: float = 1.0) -> float:
    """Peak signal-to-noise ratio in dB, ``10 log10(peak^2 / MSE)``; ``inf`` for identical images.

    Args:
        peak: the signal peak (1.0: display white of linear radiance at exposure 0).
    """
    if peak <= 0:
        raise ValueError(f"peak must be positive, got {peak}")
    e = mse(a, b)
    return math.inf if e == 0.0 else float(10.0 * math.log10(peak * peak / e))


def gaussian_window(size: int = 11, sigma: float = 1.5) -> np.ndarray:
    """Normalised 1D Gaussian taps (the 2D window is their outer product)."""
    x = np.arange(size, dtype=np.float64) - (size - 1) / 2.0
    w = np.exp(-(x * x) / (2.0 * sigma * sigma))
    return w / w.sum()


def _filter_valid(img: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Separable 'valid' correlation of (H, W, C) with the window w (x) w."""
    k = len(w)
    h, wd = img.shape[0] - k + 1, img.shape[1] - k + 1
    rows = sum(w[i] * img[i:i + h] for i in range(k))
    return sum(w[i] * rows[:, i:i + wd] for i in range(k))


def ssim_map(a, b, data_range: float = 1.0, win_size: int = 11, sigma: float = 1.5) -> np.ndarray:
    """The SSIM of every wholly-inside window, (H - 10, W - 10, C) for the default window."""
    a, b = _pair(a, b)
    if a.ndim == 2:
        a, b = a[..., None], b[..., None]
    if min(a.shape[:2]) < win_size:
        raise ValueError(f"SSIM needs images of at least {win_size}x{win_size} pixels, got {a.shape[1]}x{a.shape[0]}")
    if data_range <= 0:
        raise ValueError(f"data_range must be positive, got {data_range}")
    # SSIM(a, b, L) = SSIM(a/s, b/s, L/s): computing at a scale where the largest value is 1
    # keeps squares of huge radiance (1e30) from overflowing float64.
    scale = max(1.0, float(np.abs(a).max()), float(np.abs(b).max()))
    a, b, data_range = a / scale, b / scale, data_range / scale
    w = gaussian_window(win_size, sigma)
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    mu_a, mu_b = _filter_valid(a, w), _filter_valid(b, w)
    # (Co)variances are shift-invariant: computing them about a common per-channel offset avoids the
    # cancellation of E[x^2] - mu^2 when the mean dwarfs the spread (a bright flat region), which
    # otherwise gives negative variances and SSIM outside [-1, 1]. The means keep their true values.
    m = 0.5 * (a.mean(axis=(0, 1)) + b.mean(axis=(0, 1)))
    da, db = a - m, b - m
    mu_da, mu_db = mu_a - m, mu_b - m
    var_a = np.maximum(_filter_valid(da * da, w) - mu_da * mu_da, 0.0)
    var_b = np.maximum(_filter_valid(db * db, w) - mu_db * mu_db, 0.0)
    bound = np.sqrt(var_a * var_b)  # |cov| <= sqrt(var_a var_b) holds exactly; rounding can break it
    cov = np.clip(_filter_valid(da * db, w) - mu_da * mu_db, -bound, bound)
    num_l, den_l = 2 * mu_a * mu_b + c1, mu_a ** 2 + mu_b ** 2 + c1
    num_s, den_s = 2 * cov + c2, var_a + var_b + c2
    # At scales where c1, c2 underflow, two all-zero windows are identical: 0/0 there means 1.
    with np.errstate(invalid="ignore", divide="ignore"):
        lum = np.where(den_l > 0, num_l / den_l, 1.0)
        struct = np.where(den_s > 0, num_s / den_s, 1.0)
    return np.clip(lum * struct, -1.0, 1.0)


def ssim(a, b, data_range: float = 1.0) -> float:
    """Mean structural similarity (1 for identical images); see the module docstring for the conventions."""
    return float(np.mean(ssim_map(a, b, data_range)))


TONEMAP_GAMMA = 2.2
"""Display gamma of the metrics' tone map."""


def tonemap(x: np.ndarray, exposure: float) -> np.ndarray:
    """The fixed tone map of the tone-mapped metrics: y = max(x * exposure, 0), then (y / (1 + y)) ** (1 / 2.2).

    Reinhard's curve at the dataset exposure (which maps the 99th percentile of lit direct light to 1,
    i.e. to 0.5 before gamma), then a display gamma: values in [0, 1), compared with data_range 1.
    It weighs errors as a viewer sees them, where linear metrics are dominated by highlights.
    """
    y = np.maximum(np.asarray(x, dtype=np.float64) * exposure, 0.0)
    return (y / (1.0 + y)) ** (1.0 / TONEMAP_GAMMA)
