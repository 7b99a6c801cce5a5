"""How a build scores a model on its evaluation set: the ladder's rows, its pick, and the model a ship replaces all
read these."""

from __future__ import annotations

from diviewer.errors import DiviewerError

QUALITY = ("psnr", "ssim", "psnr_tm", "ssim_tm")
PICK_MEASURE = "evalset_psnr_tm"
"""What the pick compares: each K's tone-mapped PSNR over every frame of the evaluation set (>= 1024 spp), as
`diviewer bench` does. Not the capture's test split: its truth has the capture's spp (64 for cornell and Sponza),
whose own noise (~36 dB tone-mapped on cornell) caps what it can tell apart; models near that floor read alike."""


def evalset_scores(ev: dict, key: str, qualities: tuple[str, ...] = QUALITY) -> dict[str, dict]:
    """One model's per-split means of ``qualities`` and frame counts in a `diviewer eval --evalset` record ``ev``
    (``key``: the model file's stem), as the ladder's rows hold them."""
    return {s: {**{q: r["methods"][key][q]["mean"] for q in qualities if q in r["methods"][key]},
                "frames": r["frames"]}
            for s, r in ev["splits"].items() if key in r["methods"]}


def means_on_test_split(summary: dict) -> dict[str, dict]:
    """The model's and the direct light's means in a `diviewer eval --data ... --split test` result, as the ladder's
    rows hold them."""
    return {m: {q: summary["methods"][m][q]["mean"] for q in QUALITY} for m in ("neural", "direct")}


def evalset_psnr_tm(splits: dict[str, dict]) -> float:
    """The mean tone-mapped PSNR over every frame of an evaluation set: the splits' means weighted by their frames."""
    scored = [(s["psnr_tm"], s["frames"]) for s in splits.values() if s.get("psnr_tm") is not None]
    if not scored or not sum(n for _, n in scored):
        raise DiviewerError("the evaluation set scored no frames for the ladder's pick")
    return sum(p * n for p, n in scored) / sum(n for _, n in scored)
