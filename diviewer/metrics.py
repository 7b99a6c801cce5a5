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
    w = gaussian_window(win_size, sigma)
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    mu_a, mu_b = _filter_valid(a, w), _filter_valid(b, w)
    var_a = _filter_valid(a * a, w) - mu_a * mu_a
    var_b = _filter_valid(b * b, w) - mu_b * mu_b
    cov = _filter_valid(a * b, w) - mu_a * mu_b
    return ((2 * mu_a * mu_b + c1) * (2 * cov + c2)) / ((mu_a ** 2 + mu_b ** 2 + c1) * (var_a + var_b + c2))


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
