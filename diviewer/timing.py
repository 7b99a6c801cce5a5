"""Per-stage timing shared by every stage of the program: renderer passes, the neural pass, the runtime, the viewer.

One ``StageTimer`` collects a frame's milliseconds per named stage (``with timer.stage("shadows", gpu=True):``).
GL work runs asynchronously, so a GL stage is timed either by waiting for the GPU before and after it
(``sync``: honest, but the frame gets slower) or by a GL timer query (``gpu_query``: the GPU's own clock,
where the driver has ARB_timer_query); with neither it is not recorded, since its wall time would only
be the time taken to submit it. No GL here: the GL side hands in ``ctx.finish`` and ``ctx.query``
(``diviewer.gl.context.stage_timer``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np


class StageTimer:
    """Milliseconds per named stage of the current frame; a stage entered twice adds up."""

    def __init__(self, sync: Callable[[], None] | None = None, gpu_query: Callable[[], Any] | None = None):
        """
        Args:
            sync: waits for the GPU (``ctx.finish``); given, GL stages are timed by the wall clock around it.
            gpu_query: makes a timer query (``ctx.query(time=True)``: a context manager with ``elapsed`` in ns);
                used for GL stages when ``sync`` is not given. One query is kept per stage name.
        """
        self.sync = sync
        self.gpu_query = gpu_query
        self.times: dict[str, float] = {}
        self._queries: dict[str, Any] = {}

    @property
    def enabled(self) -> bool:
        """Whether GL stages are timed at all."""
        return self.sync is not None or self.gpu_query is not None

    @property
    def method(self) -> str:
        """How GL stages are timed, in words (the panel's and the stats JSON's)."""
        if self.sync is not None:
            return "wall clock around a GPU sync"
        return "GPU timer queries" if self.gpu_query is not None else "off"

    def reset(self) -> dict[str, float]:
        """Start a new frame; returns the last frame's times."""
        last, self.times = self.times, {}
        return last

    def add(self, name: str, ms: float) -> None:
        self.times[name] = self.times.get(name, 0.0) + float(ms)

    @contextmanager
    def stage(self, name: str, gpu: bool = False) -> Iterator[None]:
        """Time the block as stage ``name``; ``gpu``: the block issues GL work (see the module's docstring)."""
        if gpu and self.sync is None:
            if self.gpu_query is None:
                yield
                return
            query = self._queries.get(name)
            if query is None:
                query = self._queries[name] = self.gpu_query()
            with query:
                yield
            self.add(name, query.elapsed / 1e6)  # waits for this stage's result only
            return
        if gpu:
            self.sync()
        t0 = time.perf_counter()
        yield
        if gpu:
            self.sync()
        self.add(name, (time.perf_counter() - t0) * 1e3)

    def release(self) -> None:
        """Release the timer queries where they can be (moderngl 5's Query cannot: its GL query lives as long
        as the context, which is why one is kept per stage name rather than made per frame)."""
        for q in self._queries.values():
            if hasattr(q, "release"):
                q.release()
        self._queries.clear()


def percentiles(values: Iterable[float], qs: tuple[float, ...] = (50.0, 95.0)) -> tuple[float, ...]:
    """The ``qs`` percentiles of ``values`` (median and p95 by default); zeros when there are none."""
    v = np.asarray(list(values), np.float64)
    if not len(v):
        return tuple(0.0 for _ in qs)
    return tuple(float(x) for x in np.percentile(v, qs))


def summarize(frames: Iterable[dict[str, float]]) -> dict[str, dict[str, float]]:
    """Per stage over frames (dicts of ms): median, p95 and mean, counting only the frames that had the stage."""
    by_stage: dict[str, list[float]] = {}
    for f in frames:
        for k, ms in f.items():
            by_stage.setdefault(k, []).append(ms)
    out = {}
    for k, v in by_stage.items():
        med, p95 = percentiles(v)
        out[k] = {"median": med, "p95": p95, "mean": float(np.mean(v))}
    return out
