"""The one place GL contexts are created: EGL standalone (headless) or a GLFW window's."""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import moderngl

from diviewer.errors import DiviewerError
from diviewer.timing import StageTimer

GL_VERSION = 430


def create_context(backend: str = "egl") -> moderngl.Context:
    """A moderngl context of at least OpenGL 4.3 core.

    Args:
        backend: ``"egl"`` for a headless standalone context, ``"window"`` to wrap the context
            current on this thread (a GLFW window's).
    """
    try:
        if backend == "window":
            ctx = moderngl.create_context(require=GL_VERSION)
        elif backend == "egl":
            ctx = moderngl.create_context(standalone=True, backend="egl", require=GL_VERSION)
        else:
            raise ValueError(f"unknown GL backend {backend!r}")
    except DiviewerError:
        raise
    except Exception as exc:
        raise DiviewerError(
            f"cannot create an OpenGL {GL_VERSION // 100}.{GL_VERSION // 10 % 10} context ({backend}): {exc}. "
            "Headless rendering needs EGL with Mesa (Debian: apt-get install libegl1 libgl1-mesa-dri)"
        ) from exc
    return ctx


@contextmanager
def headless_context() -> Iterator[moderngl.Context]:
    """A standalone EGL context, current inside the block and released after it.

    Creating it makes it current, replacing whatever context was current on this thread, and that one is not
    current again afterwards (the block restores what was current when it began: the new context itself). So a
    caller that holds a context of its own renders in it rather than opening another (``area_direct_of``'s
    ``ctx``), or makes it current again (``with ctx:``).
    """
    ctx = create_context("egl")
    try:
        with ctx:
            yield ctx
    finally:
        ctx.release()


def describe(ctx: moderngl.Context) -> str:
    return f"{ctx.info['GL_RENDERER']} / OpenGL {ctx.info['GL_VERSION']}"


def unbind_framebuffer(ctx: moderngl.Context) -> None:
    """Bind the default framebuffer (0), so releasing ours leaves no dead binding behind.

    moderngl restores the previously bound framebuffer after creating a new one; if that one was
    released while bound, the restore raises GL_INVALID_OPERATION.
    """
    ctx.detect_framebuffer(0).use()


def max_render_size(ctx: moderngl.Context) -> tuple[int, int]:
    """The largest width and height this context can render to: texture, renderbuffer and viewport limits."""
    info = ctx.info
    tex = int(info.get("GL_MAX_TEXTURE_SIZE", 0)) or 1 << 30
    rbo = int(info.get("GL_MAX_RENDERBUFFER_SIZE", 0)) or 1 << 30
    vp = info.get("GL_MAX_VIEWPORT_DIMS") or (1 << 30, 1 << 30)
    return min(tex, rbo, int(vp[0])), min(tex, rbo, int(vp[1]))


def check_render_size(ctx: moderngl.Context, width: int, height: int, option: str = "--res") -> None:
    """Refuse a render size this context cannot hold, before any pass allocates: its limits, then a probe.

    The probe allocates the largest target the renderer uses (an RGBA float32 texture with a depth
    renderbuffer) and checks that the framebuffer is complete: drivers refuse large targets below
    GL_MAX_TEXTURE_SIZE (Mesa llvmpipe: no texture of 2 GiB or more, i.e. above 11584x11584 RGBA32F).
    """
    mw, mh = max_render_size(ctx)
    if width > mw or height > mh:
        raise DiviewerError(f"{width}x{height} is larger than this GL context allows ({mw}x{mh}: "
                            f"GL_MAX_TEXTURE_SIZE, GL_MAX_RENDERBUFFER_SIZE, GL_MAX_VIEWPORT_DIMS of {describe(ctx)})",
                            field=option)
    tex = rbo = fbo = None
    try:
        tex = ctx.texture((width, height), 4, dtype="f4")
        rbo = ctx.depth_renderbuffer((width, height))
        fbo = ctx.framebuffer([tex], rbo)
    except moderngl.Error as exc:
        raise DiviewerError(f"{width}x{height} is too large for {describe(ctx)}: a float RGBA target of that "
                            f"size cannot be allocated ({exc}); use a smaller size", field=option) from None
    finally:
        unbind_framebuffer(ctx)
        for r in (fbo, rbo, tex):
            if r is not None:
                r.release()
        ctx.error  # a failed allocation leaves GL_OUT_OF_MEMORY behind: read (and clear) it


def stage_timer(ctx: moderngl.Context, sync: bool = False, queries: bool = False, deferred: bool = False) -> StageTimer:
    """The program's stage timer for GL work on ``ctx``: waits for the GPU around each GL stage (``sync``), or
    reads GL timer queries (``queries``; ARB_timer_query, which llvmpipe has), or leaves GL stages untimed;
    ``deferred``: its queries are read when the frame's times are collected (`StageTimer.collect`)."""
    return StageTimer(sync=ctx.finish if sync else None,
                      gpu_query=(lambda: ctx.query(time=True)) if queries else None, deferred=deferred)


def set_stage_timing(timer: StageTimer, ctx: moderngl.Context, on: bool) -> None:
    """Time ``timer``'s GL stages by timer queries (ARB_timer_query, core since GL 3.3), or by waiting for the
    GPU around them where the driver lacks queries (``on``); or leave them untimed."""
    timer.release()
    timer.sync = timer.gpu_query = None
    if on:
        try:
            with ctx.query(time=True) as probe:
                pass
            probe.elapsed  # noqa: B018 (raises where the driver has no timer queries)
            timer.gpu_query = lambda: ctx.query(time=True)
        except Exception:  # noqa: BLE001
            timer.sync = ctx.finish


@functools.lru_cache(maxsize=1)
def gl_flush() -> Callable[[], None] | None:
    """``glFlush`` for the context current on this thread, or None where it cannot be had. moderngl 5 has no flush of
    its own; its loader (glcontext) calls GL through the library ``find_library("GL")`` names, for a GLFW window's
    context and an EGL one alike (GLVND dispatches to the current context), so this takes glFlush from the same."""
    name = ctypes.util.find_library("GL")
    try:
        fn = ctypes.CDLL(name).glFlush if name else None
    except (OSError, AttributeError):
        return None
    if fn is not None:
        fn.restype, fn.argtypes = None, []
    return fn
