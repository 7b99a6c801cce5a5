"""The speed/accuracy logic of the benchmark, on plain tables (no GL, no models): equal-time quality of the path
tracer, its time at equal error, the smallest sufficient K, and temporal stability.

The equivalent sample count itself is diviewer.metrics.equivalent_spp (through diviewer.evaluation.evaluate), not repeated here.
"""

from __future__ import annotations

import math

import numpy as np

from diviewer.metrics import equivalent_spp


def _loglog(x0: float, x1: float, y0: float, y1: float, x: float) -> float:
    """y at x on the straight line through (x0, y0), (x1, y1) in log-log."""
    t = (math.log(x) - math.log(x0)) / (math.log(x1) - math.log(x0))
    return math.exp(math.log(y0) + t * (math.log(y1) - math.log(y0)))


def spp_in_time(ladder_spp, ladder_ms, ms: float) -> dict:
    """The sample count the path tracer renders in ``ms``, interpolated in log-log between measured counts.

    Returns ``{"spp", "bound"}``: "=" inside the ladder, "<" when even the smallest count takes longer
    (spp is then the smallest count), ">=" beyond the largest (spp is the largest); never extrapolated.
    """
    spp, t = np.asarray(ladder_spp, float), np.asarray(ladder_ms, float)
    if spp.ndim != 1 or spp.shape != t.shape or not len(spp) or np.any(t <= 0) or np.any(np.diff(spp) <= 0):
        raise ValueError("ladder_spp must increase and ladder_ms be positive, of equal length")
    if not (math.isfinite(ms) and ms > 0):
        raise ValueError(f"time must be positive and finite, got {ms}")
    if ms < t[0]:
        return {"spp": float(spp[0]), "bound": "<"}
    for i in range(len(spp) - 1):
        if t[i] <= ms <= t[i + 1] and t[i + 1] > t[i]:
            return {"spp": _loglog(t[i], t[i + 1], spp[i], spp[i + 1], ms), "bound": "="}
    if ms == t[-1]:
        return {"spp": float(spp[-1]), "bound": "="}
    return {"spp": float(spp[-1]), "bound": ">="}


def error_at_spp(ladder_spp, ladder_error, spp: float) -> float:
    """The path tracer's error at ``spp`` (within the ladder), interpolated in log-log (exact for c / spp^k)."""
    s, e = np.asarray(ladder_spp, float), np.asarray(ladder_error, float)
    if not s[0] <= spp <= s[-1]:
        raise ValueError(f"spp {spp} lies outside the ladder {list(s)}")
    i = min(int(np.searchsorted(s, spp, side="right")) - 1, len(s) - 2)
    if len(s) == 1:
        return float(e[0])
    return _loglog(s[i], s[i + 1], e[i], e[i + 1], spp)


def equal_time(ladder_spp, ladder_ms, ladder_error, ms: float) -> dict:
    """What the path tracer achieves in the time ``ms`` of another method: ``{"spp", "bound", "error"}``.

    "error" is None below the ladder (the path tracer cannot finish one ladder frame in that time) and the
    largest count's error beyond it (an upper bound on the error).
    """
    r = spp_in_time(ladder_spp, ladder_ms, ms)
    r["error"] = None if r["bound"] == "<" else error_at_spp(ladder_spp, ladder_error, r["spp"])
    return r


def time_at_spp(ladder_spp, ladder_ms, spp: float) -> float:
    """The path tracer's frame time at ``spp`` (within the ladder), log-log interpolated."""
    return error_at_spp(ladder_spp, ladder_ms, spp)


def equal_error(ladder_spp, ladder_ms, ladder_error, error: float, ms: float) -> dict:
    """At the error of a method that takes ``ms``: the path tracer's equivalent spp, its time, and the speed-up.

    Returns ``{"spp", "bound", "text", "pt_ms", "speedup"}``; beyond the ladder the time and the speed-up are
    bounds too ("<": the method is worse than 1 spp; ">=": better than the largest count, so the speed-up is
    at least the one reported).
    """
    eq = equivalent_spp(ladder_spp, ladder_error, error)
    pt_ms = time_at_spp(ladder_spp, ladder_ms, eq["spp"])
    return {**eq, "pt_ms": pt_ms, "speedup": pt_ms / ms}


def smallest_sufficient_k(psnr_by_k: dict[int, float], tolerance_db: float = 0.5) -> dict | None:
    """The smallest K whose PSNR is within ``tolerance_db`` of the best K's (what the scene requires)."""
    if not psnr_by_k:
        return None
    best_k = max(psnr_by_k, key=lambda k: psnr_by_k[k])
    best = psnr_by_k[best_k]
    k = min(k for k, v in psnr_by_k.items() if v >= best - tolerance_db)
    return {"K": k, "psnr": psnr_by_k[k], "best_K": best_k, "best_psnr": best, "tolerance_db": tolerance_db}


def temporal_change(frames) -> np.ndarray:
    """Mean absolute change between consecutive frames of a sequence, (T-1,)."""
    f = [np.asarray(x, np.float64) for x in frames]
    return np.array([float(np.mean(np.abs(b - a))) for a, b in zip(f, f[1:])])


def temporal_stability(frames, reference) -> dict:
    """A method's frame-to-frame change against the reference's along the same sequence.

    Returns ``{"change", "reference_change", "ratio", "excess"}``: mean |frame_t+1 - frame_t| of the method
    and of the reference, their ratio (1: as much change as the truth; above 1: flicker the reference does
    not have) and the mean |delta_method - delta_reference| (0 when the method changes exactly as the truth).
    """
    if len(frames) != len(reference) or len(frames) < 2:
        raise ValueError("temporal stability needs two sequences of equal length >= 2")
    dm, dr = temporal_change(frames), temporal_change(reference)
    f = [np.asarray(x, np.float64) for x in frames]
    r = [np.asarray(x, np.float64) for x in reference]
    excess = float(np.mean([np.mean(np.abs((b - a) - (d - c))) for a, b, c, d in zip(f, f[1:], r, r[1:])]))
    change, ref_change = float(dm.mean()), float(dr.mean())
    ratio = change / ref_change if ref_change > 0 else (1.0 if change == 0 else math.inf)
    return {"change": change, "reference_change": ref_change, "ratio": ratio, "excess": excess}
