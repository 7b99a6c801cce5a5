"""Shared fixtures: one headless EGL context per session, checked for GL errors around each test; the marks
that follow from what a test uses (``gl``: a GL context, ``window``: a display) and the ``mitsuba`` skip."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
REQUIRE_GL = os.environ.get("DIVIEWER_REQUIRE_GL", "") not in ("", "0")
MARK_BY_FIXTURE = {"ctx": "gl", "gl_context": "gl", "display": "window"}
"""A test that asks for one of these fixtures gets the mark: ``pytest -m "not gl"`` runs without any context."""
NO_MITSUBA = importlib.util.find_spec("mitsuba") is None


QUICK_LEFT_OUT = ("tests/train/", "tests/extremes/", "tests/bench/", "tests/builder/test_pipeline.py",
                  "tests/test_faults.py", "tests/viewer/test_recording.py")
"""Folders and files the quick loop leaves out besides what its marks say: training (torch), the extremes suite
(``-m extremes``), the benchmark, and the modules that run whole pipelines or many subprocesses."""
SLOW_MARKS = ("slow", "gl", "window", "mitsuba")


def pytest_collection_modifyitems(items):
    for item in items:
        for mark in sorted({MARK_BY_FIXTURE[f] for f in item.fixturenames if f in MARK_BY_FIXTURE}):
            item.add_marker(mark)
        where = Path(str(item.fspath)).relative_to(ROOT).as_posix()
        if not any(item.get_closest_marker(m) for m in SLOW_MARKS) and not where.startswith(QUICK_LEFT_OUT):
            item.add_marker("quick")
        if NO_MITSUBA and item.get_closest_marker("mitsuba"):
            item.add_marker(pytest.mark.skip(reason="needs mitsuba (pip install 'diviewer[train]')"))


@pytest.fixture(scope="session")
def gl_context():
    """The session's EGL context; a missing context fails the run when DIVIEWER_REQUIRE_GL=1 (CI)."""
    from diviewer.errors import DiviewerError
    from diviewer.gl.context import create_context

    try:
        ctx = create_context("egl")
    except DiviewerError as exc:
        if REQUIRE_GL:
            pytest.fail(f"DIVIEWER_REQUIRE_GL is set and no GL context could be made: {exc}")
        pytest.skip(f"no headless GL context: {exc}")
    yield ctx
    ctx.release()


@pytest.fixture
def ctx(gl_context):
    """The session context, made current, with GL_NO_ERROR required before and after the test.

    `with` makes it current even if code under test created (and released) a context of its own.
    """
    with gl_context:
        assert gl_context.error == "GL_NO_ERROR", "a GL error was left over before this test"
        yield gl_context
        assert gl_context.error == "GL_NO_ERROR", "the test left a GL error"
