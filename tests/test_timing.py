"""The shared stage timer: wall clock for CPU stages, GPU sync or timer queries for GL stages, percentiles."""

from __future__ import annotations

import time

import pytest

from diviewer.timing import StageTimer, percentiles, summarize


def test_cpu_stages_add_up_and_reset_starts_a_frame():
    t = StageTimer()
    for _ in range(2):
        with t.stage("inference"):
            time.sleep(0.002)
    assert t.times["inference"] >= 4.0
    last = t.reset()
    assert last["inference"] >= 4.0 and t.times == {}


def test_gl_stages_need_a_sync_or_a_query():
    calls = []
    with StageTimer().stage("gbuffer", gpu=True):  # neither: not recorded (it would be submit time only)
        pass
    t = StageTimer(sync=lambda: calls.append("finish"))
    with t.stage("gbuffer", gpu=True):
        calls.append("work")
    assert calls == ["finish", "work", "finish"] and "gbuffer" in t.times

    class Query:  # moderngl's ctx.query(time=True): a context manager with ``elapsed`` in ns
        made = 0

        def __init__(self):
            Query.made += 1
            self.elapsed = 0
            self.released = False

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.elapsed = 2_500_000

        def release(self):
            self.released = True

    t = StageTimer(gpu_query=Query)
    for _ in range(3):
        with t.stage("shadows", gpu=True):
            pass
    assert t.times["shadows"] == pytest.approx(7.5) and Query.made == 1  # one query per stage, reused
    q = t._queries["shadows"]
    t.release()
    assert q.released


def test_percentiles_and_summary():
    assert percentiles([]) == (0.0, 0.0)
    med, p95 = percentiles(range(1, 101))
    assert med == pytest.approx(50.5) and p95 == pytest.approx(95.05)
    s = summarize([{"a": 1.0, "b": 4.0}, {"a": 3.0}])
    assert s["a"] == {"median": 2.0, "p95": pytest.approx(2.9), "mean": 2.0} and s["b"]["mean"] == 4.0
