"""Dynamic resolution: the shading scale that holds a target frame rate. Pure Python, no GL.

The viewer shades (G-buffer, shadow lookup, direct light, upsample) at ``scale`` times the window's size and
resamples the image to the window. The controller measures frame times at the current scale and moves it
between ``floor`` and ``ceiling`` (1 by default; up to 2, supersampling) under a cost model
``t(s) = a + b s^2`` (a: what does not depend on the pixels, such as the network at its own resolution; b:
per-pixel work):

- It waits ``settle`` frames after a change (the first frames at a new size allocate targets), then decides
  every ``window`` frames on the median of the frames at this scale (the last ``pool`` of them): one slow
  frame moves nothing, and the longer a scale holds, the less noise can move it.
- Inside the dead band ``[low * target, target]`` it holds: the band is wider than one step's effect, so
  noise does not toggle it.
- Outside, it solves the cost model for the scale that lands at ``aim * target``, using an estimate of ``a``
  that errs low (half the secant estimate from the last two measured scales, never above what was
  measured). With ``a`` underestimated the step never crosses the aim: each move lands on the side it
  started from, so the scale converges monotonically and does not oscillate.
- Scales are quantised to ``1 / steps`` (targets are reallocated only when it changes), rounded towards the
  current scale, with at least one step down when the frame is too slow.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from dataclasses import dataclass

MAX_SCALE = 2.0
"""The highest render scale: above 1 the viewer supersamples (it shades more pixels than the window has and
the display filters them down; at 2 each window pixel is the mean of a 2x2 block: its direct light and shadows
anti-aliased). A fixed scale may be set up to it, and dynamic resolution goes up to ``ceiling``."""

DEFAULT_FLOOR = 0.4
"""The default lowest scale: at 768x768 Sponza's still worst-case view holds 15 fps only there on the 2-core
development machine (0.5: 14.0 fps), at 37.3 dB tone-mapped from its full-resolution frame (0.5: 38.4;
docs/speed.md); cornell at 768x768 settles at 0.66 and never reaches it."""


@dataclass(frozen=True)
class ScaleSettings:
    """How the shading scale follows the frame rate."""

    target_fps: float = 30.0
    """Frame rate to hold; 0 turns the controller off (the scale stays at ``start``)."""
    floor: float = DEFAULT_FLOOR
    """Lowest scale (fraction of the window's size per side)."""
    start: float = 1.0
    """Scale of the first frame."""
    ceiling: float = 1.0
    """Highest scale the controller goes to (up to ``MAX_SCALE``: supersampling where the frame rate allows)."""
    low: float = 0.8
    """Lower edge of the dead band, as a fraction of the target frame time: faster frames raise the scale."""
    aim: float = 0.9
    """Where a move aims, as a fraction of the target frame time (inside the band, away from its edges)."""
    settle: int = 2
    """Frames ignored after a change (allocation, shader variants, the pipeline refilling)."""
    window: int = 6
    """Frames between decisions (the first decision at a new scale takes the median of this many)."""
    pool: int = 30
    """Most recent frames at the current scale whose median a decision takes."""
    steps: int = 32
    """Scales are multiples of 1 / steps."""


def moving_map_size(limit: int | None, shaded: tuple[int, int]) -> int | None:
    """A moving sun's shadow-map size for a frame shaded at ``shaded``: the power of two at least twice its larger
    side (two texels a shaded pixel across the view), at most ``limit`` (None: the map is never drawn smaller while
    it moves). At rest the map is drawn at the scene's size, whatever this says."""
    if limit is None:
        return None
    size = 256
    while size < 2 * max(shaded) and size < limit:
        size *= 2
    return min(size, limit)


def render_size(base: tuple[int, int], scale: float) -> tuple[int, int]:
    """The shading resolution at ``scale`` of ``base`` (at least 1x1)."""
    return tuple(max(1, round(s * scale)) for s in base)


class ScaleController:
    """Moves the shading scale to hold ``settings.target_fps``; feed it each frame's time with ``update``."""

    def __init__(self, settings: ScaleSettings = ScaleSettings()):
        if not 0.0 < settings.floor <= 1.0:
            raise ValueError(f"scale floor must be in (0, 1], got {settings.floor}")
        if not 1.0 <= settings.ceiling <= MAX_SCALE:
            raise ValueError(f"scale ceiling must be in [1, {MAX_SCALE:g}], got {settings.ceiling}")
        self.settings = settings
        self.scale = min(max(settings.start, settings.floor), settings.ceiling)
        self._samples: list[float] = []
        """Frame times at the current scale, newest last (at most ``pool``)."""
        self._count = 0
        self._skip = settings.settle
        self._measured: list[tuple[float, float]] = []
        """(scale, median frame ms) of the last measurements at distinct scales, newest last."""
        self.changes = 0
        """How many times the scale moved."""

    def _restart(self, settings: ScaleSettings) -> None:
        self.__init__(settings)

    def fix(self, scale: float) -> float:
        """Hold ``scale`` (the controller turns off; the floor and the ceiling follow a scale beyond them)."""
        s = self.settings
        self._restart(dataclasses.replace(s, target_fps=0.0, start=scale, floor=min(s.floor, scale),
                                          ceiling=min(max(s.ceiling, scale), MAX_SCALE)))
        return self.scale

    def hold(self, fps: float) -> float:
        """Move the scale to hold ``fps`` from the current scale (0: keep the current scale)."""
        s = self.settings
        self._restart(dataclasses.replace(s, target_fps=max(float(fps), 0.0), start=max(self.scale, s.floor)))
        return self.settings.target_fps

    def resume(self) -> None:
        """Go on from the current scale after frames drawn at another (a refined still view): the next
        ``settle`` frames, which reallocate targets, are not measured; the samples at this scale stay."""
        self._skip = self.settings.settle

    @property
    def enabled(self) -> bool:
        return self.settings.target_fps > 0

    @property
    def refined(self) -> float:
        """The scale a still view is refined at: 1, or the ceiling above 1 (supersampled); a fixed scale stays."""
        return max(1.0, self.settings.ceiling) if self.enabled else self.scale

    @property
    def target_ms(self) -> float:
        return 1e3 / self.settings.target_fps if self.enabled else 0.0

    def update(self, frame_ms: float, scale: float | None = None) -> float:
        """Record a frame's time (ms) drawn at ``scale`` (default: the current one); return the next frame's scale."""
        if not self.enabled or not (frame_ms > 0.0 and math.isfinite(frame_ms)):
            return self.scale
        if scale is not None and abs(scale - self.scale) > 1e-9:
            return self.scale  # drawn before the last change: not this scale's time
        if self._skip > 0:
            self._skip -= 1
            return self.scale
        self._samples.append(float(frame_ms))
        self._count += 1
        if self._count < self.settings.window:
            return self.scale
        self._count = 0
        del self._samples[:-self.settings.pool]
        t = statistics.median(self._samples)
        self._record(self.scale, t)
        new = self._next(t)
        if new != self.scale:
            self.scale = new
            self.changes += 1
            self._skip = self.settings.settle
            self._samples.clear()
        return self.scale

    def _record(self, scale: float, t: float) -> None:
        self._measured = [m for m in self._measured if abs(m[0] - scale) > 1e-9][-1:] + [(scale, t)]

    def _fixed_cost(self, t: float) -> float:
        """An estimate of ``a`` that errs low: half the secant through the last two scales, within [0, t/2]."""
        if len(self._measured) < 2:
            return 0.0
        (s1, t1), (s2, t2) = self._measured
        if abs(s1 * s1 - s2 * s2) < 1e-9:
            return 0.0
        b = (t1 - t2) / (s1 * s1 - s2 * s2)
        if b <= 0.0:
            return 0.0
        return min(max(0.5 * (t2 - b * s2 * s2), 0.0), 0.5 * t)

    def _next(self, t: float) -> float:
        s, cfg, target = self.scale, self.settings, self.target_ms
        if cfg.low * target <= t <= target:
            return s
        if t > target and s <= cfg.floor:
            return s
        if t < cfg.low * target and s >= cfg.ceiling:
            return s
        a = self._fixed_cost(t)
        goal = cfg.aim * target
        ratio = max(goal - a, 1e-6) / max(t - a, 1e-6)
        wanted = s * math.sqrt(ratio)
        n = cfg.steps
        if t > target:  # too slow: round up (towards s), but move at least one step
            q = min(math.ceil(wanted * n - 1e-9) / n, s - 1.0 / n)
        else:  # fast: round down (towards s), so the step cannot overshoot
            q = max(math.floor(wanted * n + 1e-9) / n, s)
        return min(max(q, cfg.floor), cfg.ceiling)
