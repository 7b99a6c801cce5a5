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
    q = t._queries["shadows"][0]
    t.release()
    assert q.released


def test_deferred_queries_are_read_when_the_frame_is_collected():
    """A deferred query is not read at its stage's end (reading waits for the GPU): ``collect`` reads the frame's
    queries, ``reset`` collects first, a stage entered twice in one frame gets a second query, and the queries are
    reused frame after frame."""
    reads = []

    class Query:
        made = 0

        def __init__(self):
            Query.made += 1
            self.n = Query.made

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            pass

        @property
        def elapsed(self):
            reads.append(self.n)
            return 1_000_000 * self.n

    t = StageTimer(gpu_query=Query, deferred=True)
    assert "read after the frame" in t.method
    for frame in range(3):
        with t.stage("gbuffer", gpu=True):
            pass
        with t.stage("shadows", gpu=True):
            pass
        with t.stage("shadows", gpu=True):  # a second light's map
            pass
        with t.stage("panel"):
            pass
        assert reads == [] and "gbuffer" not in t.times and "panel" in t.times
        if frame < 2:
            times = t.collect()
            assert reads == [1, 2, 3] and times is t.times
            assert times["gbuffer"] == pytest.approx(1.0) and times["shadows"] == pytest.approx(5.0)
            assert t.collect()["shadows"] == pytest.approx(5.0)  # read once
            t.reset()
        else:
            last = t.reset()  # not collected: reset reads them into the frame it closes
            assert reads == [1, 2, 3] and last["shadows"] == pytest.approx(5.0) and t.times == {}
        reads.clear()
    assert Query.made == 3
    with t.stage("gbuffer", gpu=True):
        pass
    t.release()  # a query in flight is dropped with the rest
    assert t.collect() == {} and reads == []


def test_percentiles_and_summary():
    assert percentiles([]) == (0.0, 0.0)
    med, p95 = percentiles(range(1, 101))
    assert med == pytest.approx(50.5) and p95 == pytest.approx(95.05)
    s = summarize([{"a": 1.0, "b": 4.0}, {"a": 3.0}])
    assert s["a"] == {"median": 2.0, "p95": pytest.approx(2.9), "mean": 2.0} and s["b"]["mean"] == 4.0
