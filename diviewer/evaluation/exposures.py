"""The exposure `diviewer eval` tone-maps each frame at (`eval --exposure`): the scene's one exposure, each frame's
metered exposure, or a fixed number of stops.

``scene`` (the default): every frame at the evaluation set's ``tonemap.exposure`` (on a dataset split, the scene's:
`scene_exposure`). ``metered``: each frame and shape at the exposure the viewer's meter gives the path tracer's frame
of that view (`diviewer.exposure.metered_ev` on the truth, with the viewer's and `diviewer render`'s settings,
`SHOWN`, highlights kept for the viewer's default tone curve, ACES), as a scene shown with ``auto_exposure`` is seen;
a frame in which nothing is lit keeps the scene's exposure and is counted. A number: that many stops for every frame.
Every row of a frame (models, direct light, the noise floor, the ladder) is scored at the frame's one exposure; the
regions (lit, shade, the object's unlit pixels) stay those of the scene's exposure, so each mode scores the same
pixels. The tone map takes a factor: ``2 ** ev`` for an exposure of ``ev`` stops.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.exposure import SHOWN, WHITE_POINTS, metered_ev

MODES = ("scene", "metered")
"""`eval --exposure`'s names; anything else is a number of stops."""
METER = "diviewer.exposure.metered_ev of the frame's truth (path tracer), SHOWN settings, ACES white: the viewer's meter"
"""How ``metered`` meters, as the result records it."""
METERED_TONE_CURVE = "aces"
"""The tone curve whose white the meter keeps highlights below: the viewer's and `diviewer render`'s default."""
COMPACT_LADDER = ("a compact set keeps its ladder's scores at the set's exposure only, not its images: the path "
                  "tracer's rows and the equivalent spp need the full set (--evalset) at this exposure")
"""Why a compact set scored at another exposure than the scene's has no ladder rows."""


def exposure_mode(value: Any) -> str | float:
    """``--exposure``'s value as eval takes it: 'scene', 'metered', or a finite number of stops (float)."""
    if isinstance(value, str) and value.strip().lower() in MODES:
        return value.strip().lower()
    try:
        ev = float(value)
    except (TypeError, ValueError):
        ev = math.nan
    if not math.isfinite(ev):
        raise DiviewerError(f"must be scene, metered or a finite number of stops, got {value}", field="--exposure")
    return ev


def mode_name(mode: str | float) -> str:
    """The mode as the result records it: 'scene', 'metered' or 'fixed'."""
    return mode if isinstance(mode, str) else "fixed"


class FrameExposures:
    """Each frame's tone-map factor under one mode (``exposure_mode``'s), and per split what it used.

    ``factor(truth)`` gives the factor of one frame (``truth``: its path-traced image at the shape scored) and notes
    its exposure in stops; ``split_record()`` returns what the split used and starts the next one."""

    def __init__(self, mode: Any, scene_exposure: float):
        self.mode = exposure_mode(mode)
        self.scene = float(scene_exposure)
        self._evs: list[float] = []
        self._fell_back = 0

    def factor(self, truth: np.ndarray) -> float:
        if self.mode == "scene":
            return self.scene
        if self.mode != "metered":
            return 2.0 ** self.mode
        ev = metered_ev(truth, SHOWN, WHITE_POINTS[METERED_TONE_CURVE])
        if ev is None:  # nothing lit to meter: the scene's exposure, counted
            self._fell_back += 1
            self._evs.append(math.log2(self.scene))
            return self.scene
        self._evs.append(ev)
        return 2.0 ** ev

    def split_record(self) -> dict | None:
        """For ``metered``: the split's lowest, median and highest exposure used (stops; a fallen-back frame at the
        scene's) and how many frames fell back; None in the other modes."""
        evs, fell_back = self._evs, self._fell_back
        self._evs, self._fell_back = [], 0
        if self.mode != "metered" or not evs:
            return None
        return {"ev_min": float(min(evs)), "ev_median": float(np.median(evs)), "ev_max": float(max(evs)),
                "frames": len(evs), "fell_back": fell_back}

    def record(self) -> dict:
        """The result's account of the mode: its name, the scene's factor, and the fixed stops or the meter."""
        out: dict = {"mode": mode_name(self.mode), "scene_exposure": self.scene}
        if self.mode == "metered":
            out.update(meter=METER, fallback="the scene's exposure where nothing in the truth is lit",
                       regions="lit, shade and the object's unlit pixels at the scene's exposure")
        elif self.mode != "scene":
            out.update(ev=self.mode, factor=2.0 ** self.mode,
                       regions="lit, shade and the object's unlit pixels at the scene's exposure")
        return out


def legend(result: dict) -> str:
    """The table legend's words on the tone map's exposure: what every tm column of ``result`` was scored at."""
    exp = result.get("exposure") or {"mode": "scene"}
    scene = f"{result['tonemap_exposure']:.3g}"
    if exp["mode"] == "fixed":
        return f"tm = tone-mapped at {exp['ev']:+g} EV (exposure {exp['factor']:.4g}, --exposure; the scene's is {scene})"
    if exp["mode"] == "metered":
        splits = [s["exposure"] for s in result["splits"].values() if s.get("exposure")]
        span = (f" {min(s['ev_min'] for s in splits):+.1f} to {max(s['ev_max'] for s in splits):+.1f} EV,"
                if splits else "")
        fell = sum(s["fell_back"] for s in splits)
        return (f"tm = tone-mapped at each frame's metered exposure (the viewer's meter on the truth:{span} "
                f"{fell} unlit frame(s) at the scene's {scene})")
    return f"tm = tone-mapped at exposure {scene} (the scene's)"


def split_legend(split: dict) -> str:
    """The words a split's heading adds on its metered exposures (none in the other modes)."""
    e = split.get("exposure")
    return "" if not e else (f"; metered {e['ev_min']:+.1f} to {e['ev_max']:+.1f} EV (median {e['ev_median']:+.1f}), "
                             f"{e['fell_back']} unlit")


def data_legend(exp: dict) -> str:
    """What `eval --data`'s first line adds on an exposure other than the scene's."""
    if exp["mode"] == "fixed":
        return f"; scored at {exp['ev']:+g} EV instead (--exposure)"
    if exp["mode"] == "metered" and "ev_min" in exp:
        return (f"; scored at each frame's metered exposure instead ({exp['ev_min']:+.1f} to {exp['ev_max']:+.1f} EV, "
                f"{exp['fell_back']} unlit frame(s) at the scene's)")
    return ""


def scene_exposure(scene_name: str, scene_hash: str, direct_frames) -> tuple[float, str]:
    """The scene's tone-map exposure: the shipped evaluation set's (same scene file), else fitted on the
    given GL direct-light frames (deterministic); never a model's."""
    from diviewer.contract.encoding import fit_exposure
    from diviewer.data.dataset import read_manifest
    from diviewer.evaluation.frames import default_evalset

    path = default_evalset(scene_name)
    if (path / "manifest.json").is_file():
        m = read_manifest(path)
        if m.get("scene_hash") == scene_hash:
            return float(m["evalset"]["tonemap"]["exposure"]), f"the scene's evaluation set ({path})"
    return float(fit_exposure(list(direct_frames))), ("fitted on the dataset's train split GL direct light, as "
                                                      "training fits it (no shipped evaluation set of this scene)")
