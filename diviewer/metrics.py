"""Image error metrics (numpy only, no torch): MSE, PSNR, SSIM (whole frame and over a region), FLIP, a
checkerboard measure, the pattern a decoder's stride locks to the pixel grid, and the equivalent sample count.

Conventions, the same everywhere this package reports a number:

- Inputs are (H, W) or (H, W, C) float arrays of the same shape, compared as given: linear radiance
  for renders (no tone mapping, no clipping; HDR values above the peak count in full).
- ``peak`` (PSNR) and ``data_range`` (SSIM) default to 1.0: display white at exposure 0. A caller that
  compares tone-mapped images or other units passes its own and records it.
- SSIM is Wang et al. (2004): an 11x11 Gaussian window (sigma 1.5), K1 = 0.01, K2 = 0.03, computed
  per channel over the windows that lie wholly inside the image ("valid", as in the authors' code),
  and averaged over windows and channels. It is computed on images scaled by their common peak (SSIM is
  unchanged when images and data range scale together), so huge values neither overflow nor lose the
  variance to cancellation; it always lies in [-1, 1].
- Region metrics (``masked_psnr``, ``masked_ssim``) take an (H, W) mask: PSNR over the masked pixels
  squared error; SSIM averaged over the windows centred on masked pixels. An empty region gives None.
- FLIP is NVIDIA's perceptual difference (the ``flip-evaluator`` package): HDR-FLIP on linear radiance,
  LDR-FLIP on display-encoded images in [0, 1]; 0 is identical, 1 the largest difference.
"""

from __future__ import annotations

import math

import numpy as np

LUMA = np.array([0.2126, 0.7152, 0.0722])
"""Rec. 709 luminance weights of linear RGB."""


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
    if not (data_range > 0 and math.isfinite(data_range)):
        raise ValueError(f"data_range must be positive and finite, got {data_range}")
    # Scale by the common peak: SSIM(a, b, L) == SSIM(a / s, b / s, L / s) exactly, and values of
    # order 1 keep E[x^2] - E[x]^2 from overflowing or cancelling to nonsense.
    s = max(float(np.max(np.abs(a))), float(np.max(np.abs(b))), data_range)
    a, b, data_range = a / s, b / s, data_range / s
    w = gaussian_window(win_size, sigma)
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    mu_a, mu_b = _filter_valid(a, w), _filter_valid(b, w)
    var_a = np.maximum(_filter_valid(a * a, w) - mu_a * mu_a, 0.0)  # >= 0; rounding can make it -1e-17
    var_b = np.maximum(_filter_valid(b * b, w) - mu_b * mu_b, 0.0)
    cov = _filter_valid(a * b, w) - mu_a * mu_b
    num = (2 * mu_a * mu_b + c1) * (2 * cov + c2)
    den = (mu_a ** 2 + mu_b ** 2 + c1) * (var_a + var_b + c2)
    # den underflows to 0 only for windows that are 0 in both images (c1, c2 below 1e-308): identical.
    out = np.divide(num, den, out=np.ones_like(num), where=den > 0)
    return np.clip(out, -1.0, 1.0)  # the bound holds exactly; rounding may step over it by 1e-16


def ssim(a, b, data_range: float = 1.0) -> float:
    """Mean structural similarity (1 for identical images); see the module docstring for the conventions."""
    return float(np.mean(ssim_map(a, b, data_range)))


def _mask(mask, shape) -> np.ndarray:
    m = np.asarray(mask)
    m = m[..., 0] if m.ndim == 3 else m
    if m.shape != tuple(shape[:2]):
        raise ValueError(f"mask of shape {m.shape} for images of shape {tuple(shape)}")
    return m > 0.5 if m.dtype != bool else m


def masked_mse(a, b, mask) -> float | None:
    """Mean squared error over the masked pixels (all channels); None for an empty mask."""
    a, b = _pair(a, b)
    m = _mask(mask, a.shape)
    if not m.any():
        return None
    return float(np.mean((a[m] - b[m]) ** 2))


def masked_psnr(a, b, mask, peak: float = 1.0) -> float | None:
    """PSNR (dB) over the masked pixels only, ``10 log10(peak^2 / masked MSE)``; inf when they agree, None
    for an empty mask: a region's error is not diluted by the rest of the frame."""
    if peak <= 0:
        raise ValueError(f"peak must be positive, got {peak}")
    e = masked_mse(a, b, mask)
    if e is None:
        return None
    return math.inf if e == 0.0 else float(10.0 * math.log10(peak * peak / e))


def masked_ssim(a, b, mask, data_range: float = 1.0) -> float | None:
    """Mean SSIM of the windows centred on masked pixels (the windows of ``ssim_map``, each wholly inside
    the image, so a region's structure is judged with its surroundings as SSIM always does); None when
    no window is centred on the mask (an empty mask, or one only within 5 pixels of the border)."""
    a, b = _pair(a, b)
    m = _mask(mask, a.shape)
    r = 11 // 2
    centres = m[r:m.shape[0] - r, r:m.shape[1] - r]
    if not centres.any():
        return None
    return float(np.mean(ssim_map(a, b, data_range)[centres]))


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


# --- FLIP ---------------------------------------------------------------------------------------------------------

FLIP_MODES = ("HDR", "LDR")


def flip(reference, test, mode: str = "HDR") -> float:
    """Mean FLIP error of ``test`` against ``reference`` (``flip-evaluator``), 0 for identical images.

    Args:
        mode: "HDR" for linear radiance (HDR-FLIP: the ACES tone map at the exposures FLIP picks from the
            reference), "LDR" for display-encoded (sRGB-like) images in [0, 1].

    Negative radiance (noise in a prediction) is clamped to 0 and LDR values to [0, 1], the inputs FLIP
    defines. Both images are divided by their common maximum first: HDR-FLIP picks its exposures from
    the reference, so the result does not change, and neither overflow nor underflow can occur. A black
    reference gives FLIP no exposure to start from; the exposures are then picked from the test image.
    """
    import flip_evaluator

    mode = mode.upper()
    if mode not in FLIP_MODES:
        raise ValueError(f"FLIP mode must be one of {FLIP_MODES}, got {mode!r}")
    ref, tst = _pair(reference, test)
    if ref.ndim == 2:
        ref, tst = np.repeat(ref[..., None], 3, -1), np.repeat(tst[..., None], 3, -1)
    if ref.shape[-1] != 3:
        raise ValueError(f"FLIP compares RGB images, got {ref.shape[-1]} channels")
    hi = np.inf if mode == "HDR" else 1.0
    ref, tst = np.clip(ref, 0.0, hi), np.clip(tst, 0.0, hi)
    if np.array_equal(ref, tst):
        return 0.0
    params: dict = {}
    if mode == "HDR":
        peak = max(float(ref.max()), float(tst.max()))
        ref, tst = ref / peak, tst / peak  # peak > 0: the images differ and are non-negative
        if float(ref.max()) == 0.0:
            # The C++ code exits the process when the reference has no light (start exposure = inf).
            _, _, auto = flip_evaluator.evaluate(tst.astype(np.float32), ref.astype(np.float32), "HDR",
                                                 applyMagma=False, computeMeanError=False)
            params = {k: auto[k] for k in ("startExposure", "stopExposure", "numExposures")}
    _, mean, _ = flip_evaluator.evaluate(np.ascontiguousarray(ref, np.float32), np.ascontiguousarray(tst, np.float32),
                                         mode, inputsRGB=True, applyMagma=False, parameters=params)
    return float(mean)


# --- checkerboard -------------------------------------------------------------------------------------------------

def flat_mask(depth, normal, albedo, direct=None, *, depth_tol: float = 1e-4, normal_tol: float = 1e-4,
              albedo_tol: float = 1e-3, direct_tol: float = 0.05) -> np.ndarray:
    """(H, W) bool: pixels whose 3x3 neighbourhood lies on one plane of one albedo (walls, floor).

    A plane's inverse view depth is affine in screen space, so its second differences vanish: they
    must stay below ``depth_tol`` times 1/z. Normals must agree with the centre's within ``normal_tol``
    (1 - cos), albedo within ``albedo_tol``; background (depth 0) and the image border are excluded.
    With ``direct`` (the GL direct light) the neighbourhood must also be free of shadow edges: its
    direct light may vary by at most ``direct_tol`` of its largest value. Shadow edges are aliased in
    the GL pass and box-filtered in the path tracer, so without this the measure would count them.
    """
    z = np.asarray(depth, dtype=np.float64)
    z = z[..., 0] if z.ndim == 3 else z
    n, al = np.asarray(normal, dtype=np.float64), np.asarray(albedo, dtype=np.float64)
    h, w = z.shape
    valid = np.isfinite(z) & (z > 0)
    inv = np.where(valid, 1.0 / np.where(valid, z, 1.0), 0.0)
    ok = np.zeros((h, w), dtype=bool)
    if h < 3 or w < 3:
        return ok
    c = (slice(1, -1), slice(1, -1))
    core = valid[c].copy()
    d2x = np.abs(inv[1:-1, :-2] - 2 * inv[c] + inv[1:-1, 2:])
    d2y = np.abs(inv[:-2, 1:-1] - 2 * inv[c] + inv[2:, 1:-1])
    core &= (d2x <= depth_tol * inv[c]) & (d2y <= depth_tol * inv[c])
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            nb = (slice(1 + dy, h - 1 + dy), slice(1 + dx, w - 1 + dx))
            core &= valid[nb]
            core &= np.sum(n[nb] * n[c], axis=-1) >= 1.0 - normal_tol
            core &= np.max(np.abs(al[nb] - al[c]), axis=-1) <= albedo_tol
    if direct is not None:
        lum = np.asarray(direct, dtype=np.float64) @ np.array([0.2126, 0.7152, 0.0722])
        nbs = [lum[1 + dy:h - 1 + dy, 1 + dx:w - 1 + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
        hi, lo = np.maximum.reduce(nbs), np.minimum.reduce(nbs)
        core &= hi - lo <= direct_tol * hi
    ok[c] = core
    return ok


def highpass_power(image, mask) -> float:
    """Mean power of the second differences in x and y (kernel [1, -2, 1] / 4) over the masked pixels.

    The kernel's gain is sin^2(w / 2): 1 at the Nyquist frequency (a 2-pixel checkerboard or stripes),
    0.5 at half of it, 0 for constants and linear ramps (smooth shading), so it measures the highest
    spatial-frequency band. Averaged over channels; 0 when the mask is empty.
    """
    x = np.asarray(image, dtype=np.float64)
    x = x[..., None] if x.ndim == 2 else x
    m = np.asarray(mask, dtype=bool)[1:-1, 1:-1]
    if not m.any():
        return 0.0
    hx = (x[1:-1, :-2] - 2 * x[1:-1, 1:-1] + x[1:-1, 2:]) / 4.0
    hy = (x[:-2, 1:-1] - 2 * x[1:-1, 1:-1] + x[2:, 1:-1]) / 4.0
    return float(np.mean((hx[m] ** 2 + hy[m] ** 2) / 2.0))


STRIDE_PERIOD = 8
"""The period (pixels) `stride_pattern` analyses: a U-Net decoder's transposed convolutions of stride 2 leave
patterns of period 2, 4 and 8 at its three finest levels, all periodic in 8."""


def _box_mean(x: np.ndarray, weight: np.ndarray, size: int) -> np.ndarray:
    """The ``weight``-weighted mean of ``x`` (H, W) over each pixel's size x size box (clamped at the border)."""
    def box(a):
        h, w = a.shape
        c = np.zeros((h + 1, w + 1))
        c[1:, 1:] = np.cumsum(np.cumsum(a, axis=0), axis=1)
        y0 = np.clip(np.arange(h) - size // 2, 0, h)
        y1 = np.clip(np.arange(h) - size // 2 + size, 0, h)
        x0 = np.clip(np.arange(w) - size // 2, 0, w)
        x1 = np.clip(np.arange(w) - size // 2 + size, 0, w)
        return c[y1][:, x1] - c[y0][:, x1] - c[y1][:, x0] + c[y0][:, x0]
    return box(x * weight) / np.maximum(box(weight), 1e-12)


def stride_pattern(image, albedo, depth, mask=None, period: int = STRIDE_PERIOD,
                   min_albedo: float = 0.03) -> float | None:
    """The RMS amplitude of the part of an image that repeats on the pixel grid with ``period``, relative to the
    image: 0.1 is a pattern of +-10 % on every surface, the grid-locked pattern of a network's decoder stride.

    The flat-region checkerboard ratio cannot see it on a textured scene (Sponza has few flat pixels) nor in shade,
    where the reference's own noise swamps its high frequencies. Here the irradiance (luminance over the albedo's,
    which takes the textures out) is divided by its local mean over period x period pixels (which removes every
    component of that period, so the quotient keeps them whole), and the quotient is averaged per phase of the grid
    (y and x modulo ``period``: `stride_phases`). Nothing grid-locked averages out over a frame; a decoder's pattern
    adds up. The phase means' power is corrected for the noise each mean keeps (the quotient's variance over the
    pixels of a phase), so a noisy path-traced reference scores about 0 rather than its noise. None where
    `stride_phases` reads nothing.
    """
    read = stride_phases(image, albedo, depth, mask, period, min_albedo)
    if read is None:
        return None
    means, counts, noise = read
    return math.sqrt(max(float(np.average(means ** 2, weights=counts)) - noise, 0.0))


def stride_phases(image, albedo, depth, mask=None, period: int = STRIDE_PERIOD, min_albedo: float = 0.03):
    """`stride_pattern`'s reading: the (period, period) mean relative deviation of the irradiance per phase of the
    grid (centred), each phase's pixel count, and the power of the noise the means keep (the quotient's variance x
    period^2 / pixels). Pixels read: the geometry's (depth > 0, albedo luminance >= ``min_albedo``), within the
    (H, W) ``mask`` if one is given (the frame's shade, where no rasterized direct light adds its own). Deviations
    are clipped at +-4 (a firefly weighs no more than that). None with too few pixels (fewer than 16 a phase), or
    where the image is black over half of them or more (direct light alone in the shade: a few soft shadow edges
    are not a pattern of the image)."""
    lum = np.asarray(image, dtype=np.float64)
    alb = np.asarray(albedo, dtype=np.float64)
    lum = lum @ LUMA if lum.ndim == 3 else lum
    alb = alb @ LUMA if alb.ndim == 3 else alb
    z = np.asarray(depth, dtype=np.float64)
    z = z[..., 0] if z.ndim == 3 else z
    valid = np.isfinite(z) & (z > 0) & (alb >= min_albedo) & np.isfinite(lum)
    if mask is not None:
        valid &= np.asarray(mask, dtype=bool)
    if valid.sum() < 16 * period * period:
        return None
    q = np.where(valid, np.maximum(lum, 0.0) / np.maximum(alb, min_albedo), 0.0)
    local = _box_mean(q, valid.astype(np.float64), period)
    read = valid & (local > 0)
    if read.sum() < max(16 * period * period, valid.sum() / 2):  # black over half the pixels: nothing to read
        return None
    u = np.clip(q[read] / local[read] - 1.0, -4.0, 4.0)
    ys, xs = np.nonzero(read)
    phase = (ys % period) * period + xs % period
    counts = np.bincount(phase, minlength=period * period).astype(np.float64)
    if counts.min() < 1:
        return None
    means = np.bincount(phase, weights=u, minlength=period * period) / counts
    means -= np.average(means, weights=counts)
    noise = float(np.var(u)) * period * period / len(u)
    return means.reshape(period, period), counts.reshape(period, period), noise


def checkerboard_ratio(image, reference, mask) -> float:
    """The image's high-frequency power over flat regions divided by the reference's (1: as much as the
    reference; a checkerboard makes it large). ``inf`` when only the reference is perfectly smooth."""
    return power_ratio(highpass_power(image, mask), highpass_power(reference, mask))


def power_ratio(p: float, q: float) -> float:
    """p / q for powers (pooled over frames by the caller); 1 when both are 0, inf when only q is."""
    if q == 0.0:
        return 1.0 if p == 0.0 else math.inf
    return p / q


# --- equivalent sample count --------------------------------------------------------------------------------------

def equivalent_spp(ladder_spp, ladder_error, error: float) -> dict:
    """The sample count at which the path tracer's error equals ``error``: interpolated in log-log.

    Args:
        ladder_spp: increasing sample counts the path tracer was scored at (e.g. 1, 4, 16, 64, 256).
        ladder_error: its error at each (lower is better, positive: MSE, FLIP, or 10^(-PSNR/10)).
        error: the method's error on the same frames.

    Returns:
        ``{"spp": float, "bound": "=" | ">=" | "<", "text": str}``: beyond the ladder the answer is a bound
        (">= 256": at least as good as the largest count; "< 1": worse than the smallest), never an
        extrapolation. Monte-Carlo error falls as a power of spp, a straight line in log-log, so
        interpolation is exact for error = c / spp^k. With a non-monotone ladder the smallest
        count that reaches ``error`` is returned.
    """
    spp = np.asarray(ladder_spp, dtype=np.float64)
    err = np.asarray(ladder_error, dtype=np.float64)
    if spp.ndim != 1 or spp.shape != err.shape or len(spp) < 1:
        raise ValueError("ladder_spp and ladder_error must be 1D and of equal length")
    if np.any(np.diff(spp) <= 0) or spp[0] <= 0:
        raise ValueError(f"ladder_spp must be positive and increasing, got {list(spp)}")
    if not (np.all(np.isfinite(err)) and np.all(err > 0) and math.isfinite(error) and error > 0):
        raise ValueError("errors must be positive and finite")

    def fmt(v: float) -> str:
        return f"{v:.0f}" if v >= 10 else f"{v:.2g}"

    if error > err[0]:
        return {"spp": float(spp[0]), "bound": "<", "text": f"< {fmt(spp[0])}"}
    for i in range(len(spp) - 1):
        lo, hi = err[i], err[i + 1]
        if min(lo, hi) <= error <= max(lo, hi) and hi < lo:
            t = (math.log(error) - math.log(lo)) / (math.log(hi) - math.log(lo))
            v = float(math.exp(math.log(spp[i]) + t * (math.log(spp[i + 1]) - math.log(spp[i]))))
            return {"spp": v, "bound": "=", "text": fmt(v)}
        if error == lo:
            return {"spp": float(spp[i]), "bound": "=", "text": fmt(spp[i])}
    if error == err[-1]:
        return {"spp": float(spp[-1]), "bound": "=", "text": fmt(spp[-1])}
    return {"spp": float(spp[-1]), "bound": ">=", "text": f">= {fmt(spp[-1])}"}


def psnr_error(value: float) -> float:
    """PSNR (dB) as the error equivalent_spp takes: 10^(-PSNR/10), the MSE at peak 1."""
    return 10.0 ** (-value / 10.0)
