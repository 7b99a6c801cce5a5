"""Frame and per-stage times the viewer shows (ms), over the last few seconds."""

from __future__ import annotations

import time
from collections import deque

import numpy as np

from diviewer.timing import percentiles

STAGES = ("shadows", "gbuffer", "direct", "readback", "inference", "inference_wait", "upload", "upsample",
          "temporal", "composite")
"""Per-frame stages the stats record, in pipeline order (ms each)."""


class Stats:
    """Frame and per-stage times (ms) over the last ``window_s`` seconds."""

    def __init__(self, window_s: float = 5.0):
        self.window_s = window_s
        self.history: deque[tuple[float, float, dict[str, float]]] = deque()
        self.frames = 0

    def record(self, frame_ms: float, stages: dict[str, float], now: float | None = None) -> None:
        now = time.perf_counter() if now is None else now
        self.history.append((now, float(frame_ms), dict(stages)))
        self.frames += 1
        while self.history and now - self.history[0][0] > self.window_s:
            self.history.popleft()

    def series(self, name: str = "frame") -> np.ndarray:
        """The recorded values of ``frame`` or a stage, oldest first (0 where a frame lacked the stage)."""
        if name == "frame":
            return np.array([f for _, f, _ in self.history], np.float32)
        return np.array([s.get(name, 0.0) for _, _, s in self.history], np.float32)

    def mean(self, name: str = "frame") -> float:
        v = self.series(name)
        return float(v.mean()) if len(v) else 0.0

    def last(self) -> dict[str, float]:
        if not self.history:
            return {}
        _, f, s = self.history[-1]
        return {"frame": f, **s}

    def p95(self, name: str = "frame") -> float:
        """The 95th percentile of ``frame`` or a stage: the slow frames a mean hides."""
        return percentiles(self.series(name), (95.0,))[0]

    @property
    def fps(self) -> float:
        m = self.mean("frame")
        return 1000.0 / m if m > 0 else 0.0
