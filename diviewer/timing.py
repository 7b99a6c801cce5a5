"""Per-stage timing shared by every stage of the program: renderer passes, the neural pass, the runtime, the viewer.

One ``StageTimer`` collects a frame's milliseconds per named stage (``with timer.stage("shadows", gpu=True):``).
GL work runs asynchronously, so a GL stage is timed either by waiting for the GPU before and after it
(``sync``: honest, but the frame gets slower) or by a GL timer query (``gpu_query``: the GPU's own clock,
where the driver has ARB_timer_query); with neither it is not recorded, since its wall time would only
be the time taken to submit it. No GL here: the GL side hands in ``ctx.finish`` and ``ctx.query``
(``diviewer.gl.context.stage_timer``).

Reading a timer query's result waits for its stage to finish on the GPU, so read at the stage's end it is a sync
too: the driver cannot rasterize one stage while the CPU submits the next. ``deferred`` queries are read only when
the frame's times are collected (``collect``, which ``reset`` calls first): the viewer collects after the buffer
swap, which has waited for the frame anyway, so timing no longer stalls its frame.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np


class StageTimer:
    """Milliseconds per named stage of the current frame; a stage entered twice adds up."""

    def __init__(self, sync: Callable[[], None] | None = None, gpu_query: Callable[[], Any] | None = None,
                 deferred: bool = False):
        """
        Args:
            sync: waits for the GPU (``ctx.finish``); given, GL stages are timed by the wall clock around it.
            gpu_query: makes a timer query (``ctx.query(time=True)``: a context manager with ``elapsed`` in ns);
                used for GL stages when ``sync`` is not given. Queries are kept per stage name and reused.
            deferred: read the queries when the frame's times are collected (``collect``), not at each stage's end.
        """
        self.sync = sync
        self.gpu_query = gpu_query
        self.deferred = deferred
        self.times: dict[str, float] = {}
        self._queries: dict[str, list[Any]] = {}
        self._pending: list[tuple[str, Any]] = []
        """Deferred queries of this frame not read yet: (stage name, query), in order."""

    @property
    def enabled(self) -> bool:
        """Whether GL stages are timed at all."""
        return self.sync is not None or self.gpu_query is not None

    @property
    def method(self) -> str:
        """How GL stages are timed, in words (the panel's and the stats JSON's)."""
        if self.sync is not None:
            return "wall clock around a GPU sync"
        if self.gpu_query is None:
            return "off"
        return "GPU timer queries, read after the frame" if self.deferred else "GPU timer queries"

    def collect(self) -> dict[str, float]:
        """Read this frame's deferred queries into ``times`` (waiting for their stages where they are still running);
        returns ``times``."""
        pending, self._pending = self._pending, []
        for name, query in pending:
            self.add(name, query.elapsed / 1e6)
        return self.times

    def reset(self) -> dict[str, float]:
        """Start a new frame; returns the last frame's times (its deferred queries read first)."""
        self.collect()
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
            pool = self._queries.setdefault(name, [])
            in_flight = sum(1 for n, _ in self._pending if n == name)  # a query is reused once it has been read
            if in_flight == len(pool):
                pool.append(self.gpu_query())
            query = pool[in_flight]
            with query:
                yield
            if self.deferred:
                self._pending.append((name, query))
            else:
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
        as the context, which is why they are kept per stage name rather than made per frame); deferred queries not
        read yet are dropped."""
        for pool in self._queries.values():
            for q in pool:
                if hasattr(q, "release"):
                    q.release()
        self._queries.clear()
        self._pending.clear()


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
