"""Per-frame scores of one method against the path-traced truth, and their aggregates (numpy only).

What ``eval`` and ``bench`` report for every split of an evaluation set: MSE, PSNR and SSIM on linear
radiance and tone-mapped (diviewer.metrics.tonemap at the scene's exposure), HDR- and LDR-FLIP, the sums
behind the pooled checkerboard ratio and bias, and the region metrics: tone-mapped PSNR and SSIM over the
movable object's pixels (``object``), over those of them that receive no direct light (``object_unlit``: the GL
direct light's luminance, exposed by the scene's exposure, below ``UNLIT``), and over the whole frame's pixels
that receive direct light (``lit``) and those that do not (``shade``: lit by bounced light alone, where a
network's indirect light is the whole image). A region a frame does not have (the object off screen, a frame
wholly lit or wholly in shade) scores None for that frame and the aggregate counts the frames that had it. In the
shade also the pattern locked to the pixel grid a decoder's stride leaves (``stride_shade``), which the
checkerboard ratio's flat regions miss on a textured scene.
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import Future, ProcessPoolExecutor

import numpy as np

from diviewer.metrics import (LUMA, equivalent_spp, flip, highpass_power, masked_psnr, masked_ssim, mse,
                              power_ratio, psnr, psnr_error, ssim, stride_pattern, tonemap)

KEYS = ("mse", "psnr", "ssim", "mse_tm", "psnr_tm", "ssim_tm")
EVAL_KEYS = KEYS + ("flip_hdr", "flip_ldr")
EQUIVALENT_BY = ("psnr_tm", "psnr", "flip_ldr", "ssim_tm")
"""Metrics the equivalent sample count is read from; the first is the headline (tables, targets). SSIM's error is
1 - SSIM, which falls with the path tracer's samples about as a power too (Sponza's full set: 0.73 at 1 spp, 0.07 at
256)."""
REGIONS = ("object", "object_unlit", "lit", "shade")
REGION_KEYS = tuple(f"{k}_{r}" for r in REGIONS for k in ("psnr_tm", "ssim_tm"))
UNLIT = 1e-3
"""A pixel receives no direct light when its GL direct luminance times the exposure is below this (the
tone map's white is at 1): shadowed or facing away from every light."""
LUMINANCE = LUMA


def score(image: np.ndarray, truth: np.ndarray, exposure: float) -> dict[str, float]:
    a, b = tonemap(image, exposure), tonemap(truth, exposure)
    return {"mse": mse(image, truth), "psnr": psnr(image, truth), "ssim": ssim(image, truth),
            "mse_tm": mse(a, b), "psnr_tm": psnr(a, b), "ssim_tm": ssim(a, b)}


def score_frame(image: np.ndarray, truth: np.ndarray, exposure: float, mask: np.ndarray,
                direct: np.ndarray | None = None) -> dict[str, float]:
    """Every evaluation-set metric of one frame, plus the sums behind the pooled checkerboard ratio and
    the pooled bias (given the frame's GL ``direct`` light, also the bias of the indirect light alone)."""
    a, b = tonemap(image, exposure), tonemap(truth, exposure)
    s = score(image, truth, exposure)
    s["flip_hdr"] = flip(truth, image, "HDR")
    s["flip_ldr"] = flip(b, a, "LDR")
    s["hf_power"], s["hf_power_ref"] = highpass_power(a, mask), highpass_power(b, mask)
    s["sum"], s["sum_ref"] = float(np.sum(image, dtype=np.float64)), float(np.sum(truth, dtype=np.float64))
    if direct is not None:
        d = float(np.sum(direct, dtype=np.float64))
        s["sum_indirect"], s["sum_indirect_ref"] = s["sum"] - d, s["sum_ref"] - d
    return s


def regions(frame: dict[str, np.ndarray], exposure: float) -> dict[str, np.ndarray]:
    """The frame's region masks (H, W) bool: ``lit`` and ``shade`` always, the object's two where the evaluation
    set has an object mask."""
    lum = np.asarray(frame["direct"], dtype=np.float64) @ LUMINANCE
    dark = lum * exposure < UNLIT
    out = {}
    if "object" in frame:
        obj = np.asarray(frame["object"])
        obj = (obj[..., 0] if obj.ndim == 3 else obj) > 0.5
        out = {"object": obj, "object_unlit": obj & dark}
    return {**out, "lit": ~dark, "shade": dark}


def score_frame_regions(image: np.ndarray, frame: dict[str, np.ndarray], exposure: float,
                        mask: np.ndarray, region_exposure: float | None = None) -> dict:
    """``score_frame`` against ``frame["pt"]``, plus the region metrics and each region's pixel count, and, where the
    frame has its G-buffer's albedo and depth, the grid-locked pattern in its shade (``stride_shade``:
    `diviewer.metrics.stride_pattern`, None with too little shade to read). ``region_exposure``: the exposure the
    regions are drawn at where it is not the tone map's (`eval --exposure`: the scene's, in every mode)."""
    s = score_frame(image, frame["pt"], exposure, mask, frame["direct"])
    a, b = tonemap(image, exposure), tonemap(frame["pt"], exposure)
    parts = regions(frame, exposure if region_exposure is None else region_exposure)
    for name, m in parts.items():
        s[f"psnr_tm_{name}"], s[f"ssim_tm_{name}"] = masked_psnr(a, b, m), masked_ssim(a, b, m)
        s[f"pixels_{name}"] = int(m.sum())
    if "albedo" in frame and "depth" in frame:
        s["stride_shade"] = stride_pattern(image, frame["albedo"], frame["depth"], parts["shade"])
    return s


SCORED_CHANNELS = ("pt", "direct", "object", "albedo", "depth")
"""What ``score_frame_regions`` reads of a frame (all that is sent to a worker process)."""


def default_jobs() -> int:
    """Worker processes for scoring by default: the cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def done(value) -> Future:
    """A future already holding ``value`` (a score computed or read elsewhere, beside submitted ones)."""
    f = Future()
    f.set_result(value)
    return f


def _one_thread_each() -> None:
    """Worker set-up: FLIP's OpenMP runs one thread in each worker (the workers are the parallelism; OpenMP's own
    threads on top of them oversubscribe the cores). Runs before the first task imports ``flip_evaluator``."""
    os.environ["OMP_NUM_THREADS"] = "1"


class Scorer:
    """``score_frame_regions`` of many images, over ``jobs`` worker processes (inline for 1).

    Scoring dominates ``eval`` and ``evalset`` on a set of any size: HDR-FLIP takes ~0.4 s an image at 128x128 on
    one core, and an evaluation set scores seven images a frame and shape. FLIP's own OpenMP threads scale poorly on
    images this small, so the images are spread over processes of one thread each instead; the results are the same
    numbers as inline, in the order they were submitted. Workers are spawned, not forked: the caller may hold GL
    contexts and onnxruntime threads (a script that asks for jobs > 1 therefore needs Python's ``if __name__ ==
    "__main__":`` guard; the ``diviewer`` command has it). On a machine another job keeps busy the workers also
    avoid OpenMP's spinning threads (a 4-frame set at 16x16 rows scored in 6.1 s inline and 2.5 s over two
    workers beside a capture on the 2-core AMD machine, 2026-11-27). Use as a context manager.
    """

    def __init__(self, jobs: int = 1):
        if jobs < 1:
            raise ValueError(f"jobs must be at least 1, got {jobs}")
        self.jobs, self._pool = jobs, None

    def __enter__(self) -> "Scorer":
        if self.jobs > 1:
            self._pool = ProcessPoolExecutor(self.jobs, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_one_thread_each)
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def submit(self, image: np.ndarray, frame: dict[str, np.ndarray], exposure: float, mask: np.ndarray,
               region_exposure: float | None = None) -> Future:
        """``score_frame_regions(image, frame, exposure, mask, region_exposure)``, now or in a worker; its future."""
        frame = {k: frame[k] for k in SCORED_CHANNELS if k in frame}
        if self._pool is None:
            return done(score_frame_regions(image, frame, exposure, mask, region_exposure))
        return self._pool.submit(score_frame_regions, np.asarray(image), frame, float(exposure), mask,
                                 None if region_exposure is None else float(region_exposure))


def pooled_bias(rows: list[dict], key: str = "sum") -> float | None:
    """Signed relative error of the summed radiance over all frames, (sum image / sum truth) - 1: negative
    where a method is darker than the truth on the whole. An unbiased estimator (the path tracer at any
    sample count) scores ~0; L1 training on noisy targets converges to the per-pixel median, which is
    darker than the mean where fireflies are. None without the sums or with a black truth."""
    if not rows or any(key not in r for r in rows):
        return None
    ref = sum(r[f"{key}_ref"] for r in rows)
    return sum(r[key] for r in rows) / ref - 1.0 if ref > 0 else None


def aggregate(rows: list[dict]) -> dict:
    """Per-frame scores (``score_frame``) of one method as mean and std per key, plus the pooled checkerboard
    ratio; what evaluate and the bench report per method. Region keys: over the frames that have the region
    (``frames``), None where none has."""
    out = {k: {"mean": float(np.mean([r[k] for r in rows])), "std": float(np.std([r[k] for r in rows]))}
           for k in EVAL_KEYS}
    # Pooled over frames (each frame's flat pixels weigh alike), not a mean of per-frame ratios.
    out["checkerboard"] = power_ratio(sum(r["hf_power"] for r in rows), sum(r["hf_power_ref"] for r in rows))
    out["bias"] = pooled_bias(rows)
    out["bias_indirect"] = pooled_bias(rows, "sum_indirect")
    # The decoder-stride pattern in the shade, over the frames with shade enough to read: its mean and its worst
    # frame (a pattern is seen where it is strongest). None where no row has it (a compact set's stored ladder rows).
    v = [r["stride_shade"] for r in rows if r.get("stride_shade") is not None]
    out["stride_shade"] = {"mean": float(np.mean(v)), "max": float(np.max(v)), "frames": len(v)} if v else None
    if any(k in r for r in rows for k in REGION_KEYS):
        for k in REGION_KEYS:
            v = [r[k] for r in rows if r.get(k) is not None]
            out[k] = {"mean": float(np.mean(v)), "std": float(np.std(v)), "frames": len(v)} if v else None
    return out


PER_FRAME_KEYS = ("psnr_tm", "ssim_tm", "flip_ldr", "sum", "sum_ref", "sum_indirect", "sum_indirect_ref",
                  "stride_shade")
"""What `per_frame` keeps of each frame's scores: enough to read a split frame by frame (which frames fall below
direct light, which carry a pooled bias)."""


def per_frame(indices: list[int], rows: list[dict]) -> list[dict] | None:
    """One method's scores frame by frame (``PER_FRAME_KEYS`` with the frame's index), or None when the rows do
    not pair with the frames one to one (a model refused part-way)."""
    if len(indices) != len(rows):
        return None
    return [{"index": int(i), **{k: r[k] for k in PER_FRAME_KEYS if k in r}} for i, r in zip(indices, rows)]


def below_direct(rows: list[dict], direct: list[dict]) -> dict:
    """Share of frames in which a method's tone-mapped PSNR is below direct light alone's, over the whole
    frame and over each region (frames that have it); ``frames`` counts the frames compared."""
    out = {}
    for name, key in (("frame", "psnr_tm"), *((r, f"psnr_tm_{r}") for r in REGIONS)):
        pairs = [(a[key], d[key]) for a, d in zip(rows, direct) if a.get(key) is not None and d.get(key) is not None]
        if pairs:
            out[name] = {"share": sum(a < d for a, d in pairs) / len(pairs), "frames": len(pairs)}
    return out


def _error(summary: dict, key: str) -> float:
    v = summary[key]["mean"]
    if key.startswith("psnr"):
        return psnr_error(v)
    return 1.0 - v if key.startswith("ssim") else v


def equivalent(summary: dict, ladder_spp: list[int], ladder: list[dict]) -> dict:
    """The path-traced sample count whose error matches ``summary``'s (an ``aggregate``), per key of
    ``EQUIVALENT_BY``, read off the ladder (``ladder[i]`` aggregated at ``ladder_spp[i]``); None where none can be."""
    out = {}
    for key in EQUIVALENT_BY:
        try:
            out[key] = equivalent_spp(ladder_spp, [_error(r, key) for r in ladder], _error(summary, key))
        except ValueError:  # a perfect score (error 0) or a ladder with one: no sample count to read
            out[key] = None
    return out


def ladder_methods(ev) -> dict[str, str]:
    """The path tracer's rows an evaluation set (diviewer.evaluation.frames.EvalFrames) holds: method -> channel."""
    info = ev.info
    return {f"pt_spp{int(n)}": ch for n, ch in zip(info["ladder_spp"], info["ladder_channels"])}
