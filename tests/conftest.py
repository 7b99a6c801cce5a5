"""Shared fixtures: one headless EGL context per session, checked for GL errors around each test."""

from __future__ import annotations

import os

import pytest

REQUIRE_GL = os.environ.get("DIVIEWER_REQUIRE_GL", "") not in ("", "0")


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
