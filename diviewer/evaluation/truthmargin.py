"""How far a model's training truth stands above its error, frame by frame on an evaluation set: a path-traced truth
of N spp is noisy, and a network trained on it cannot be checked to an accuracy finer than that noise ("the
ground truth's noise floor must be at least 6 dB above the model's error").

`diviewer eval` scores a model and the set's ladder (``pt_spp64``, ``pt_spp256``, ...) against a truth that has noise
of its own, so both read lower than their error against the converged image, the rungs more (their error is closer to
that noise). The set renders its truth twice (``pt``, and ``pt_b``: the noise floor), so per frame and window shape,
on the tone-mapped images as `diviewer eval` scores them:

- the truth's own noise is half the two renders' squared difference, ``r = mse(pt_b, pt) / 2`` (independent noise);
- a rung's error against the converged image is ``mse(rung, pt) - r``, the model's ``mse(model, pt) - r``; where
  that leaves nothing (an error at or below the truth's own noise: the truth cannot resolve it), the frame's margin
  is unresolved (None), left out of the median, the lowest and the share, and counted (``unresolved``);
- the margin of a truth over the model is ``10 log10(model error / truth error)`` dB; a truth of a count the ladder
  lacks is projected from its top rung (its own error times rung / spp: Monte-Carlo variance goes as 1 / spp; on
  Sponza's full set the 64-spp rung's own error is 4.3-4.5x the 256-spp one's, where 1 / spp says 4).

The subtraction treats the tone map as locally linear (small noise). `tools/experiments/truth_margin.py` reports
every rung and projection of a `diviewer eval` JSON from the frames; `diviewer eval` reports the truth each model
trained on (its card's samples per pixel) for every model it scores.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

MARGIN_DB = 6.0
"""The issue's margin: the truth's noise floor at least this far above the model's error."""
FILTERED_MARGIN = ("the set's ladder is not filtered, so its rungs do not measure that truth: "
                   "tools/experiments/filtered_truth_margin.py does")
"""What `diviewer eval` records in place of the margin of a model whose card says its truth was filtered."""


def margin_db(model_mse: float, rung_mse: float, truth_noise: float) -> float | None:
    """The margin (dB) of a rung over the model, both measured against a truth with noise ``truth_noise`` (its own
    MSE against the converged image), which is taken out of both first; None where either error is at or below that
    noise (the truth cannot resolve it: its margin could read anything)."""
    model, rung = model_mse - truth_noise, rung_mse - truth_noise
    if model <= 0.0 or rung <= 0.0:
        return None
    return float(10.0 * math.log10(model / rung))


def projected_mse(rung_mse: float, truth_noise: float, rung_spp: int, spp: int) -> float | None:
    """A truth of ``spp`` samples projected from a rung of ``rung_spp``: its own error scaled by rung_spp / spp, the
    reference's noise added back (so it reads as a rung measured against the same truth would); None where the
    rung's error is not resolved (at or below the truth's noise)."""
    own = rung_mse - truth_noise
    return own * rung_spp / spp + truth_noise if own > 0.0 else None


def summarize(rows: list[dict], key: str) -> dict:
    """The margins of one rung over a split's frames: median, lowest, and the share at `MARGIN_DB` or more, over the
    frames whose margin the truth resolves; ``unresolved`` counts the others."""
    v = np.array([r[key] for r in rows if r[key] is not None], dtype=np.float64)
    stats = ({"median_db": float(np.median(v)), "lowest_db": float(v.min()),
              "share_at_least_6db": float(np.mean(v >= MARGIN_DB))} if v.size else
             {"median_db": None, "lowest_db": None, "share_at_least_6db": None})
    return {**stats, "frames": int(v.size), "unresolved": len(rows) - int(v.size)}


def model_truth_spp(meta: dict[str, Any]) -> int | None:
    """The samples per pixel of the truth a model trained on, from its card: a refined truth's fewest over its train
    frames (``truth_spp``), else its capture's (``recipe.capture.spp``); None where the card says neither, where
    the truth was not path traced (``gt = "vxgi"``: its error is not noise), or where it was filtered
    (``truth_filter``: the set's ladder is not filtered, so its rungs do not measure that truth;
    tools/experiments/filtered_truth_margin.py does)."""
    cap = (meta.get("recipe") or {}).get("capture") or {}
    if cap.get("gt", "pt") != "pt" or cap.get("truth_filter"):
        return None
    if meta.get("truth_spp"):
        return int(meta["truth_spp"]["min"])
    return int(cap["spp"]) if cap.get("spp") else None


def truth_margin(model: list[dict], noise_floor: list[dict], ladder: dict[int, list[dict]], spp: int) -> dict:
    """The margin of a truth of ``spp`` samples over a model on one split, from its rows of scores frame by frame
    (``mse_tm``, in one order): the model's, the second-seed render's (``noise_floor``: twice the truth's own noise)
    and each ladder rung's (by its spp). The rung of that count where the ladder has it, else its top rung
    projected. Returns `summarize`'s figures with the truth's spp and what it was read from."""
    top = max(ladder)
    rung = spp if spp in ladder else top
    rows = []
    for m, n, t in zip(model, noise_floor, ladder[rung], strict=True):
        noise = n["mse_tm"] / 2.0
        truth = t["mse_tm"] if rung == spp else projected_mse(t["mse_tm"], noise, top, spp)
        rows.append({"margin_db": None if truth is None else margin_db(m["mse_tm"], truth, noise)})
    return {"truth_spp": spp, "from": f"pt_spp{rung}" + ("" if rung == spp else f", projected to {spp} spp"),
            **summarize(rows, "margin_db")}
