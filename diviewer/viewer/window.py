"""The viewer's GLFW window: opening it, its size and HiDPI scale policy, the letterboxed image rectangle,
and the mapping from window points to image pixels.

Three sizes meet here: the window's (screen units, what the mouse reports), its framebuffer's (pixels;
larger on a HiDPI screen whose system scales the framebuffer) and the image's (the GI resolution).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from diviewer.errors import DiviewerError

if TYPE_CHECKING:
    import numpy as np

GL_MAJOR, GL_MINOR = 4, 3


def letterbox(fb_w: int, fb_h: int, aspect: float) -> tuple[int, int, int, int]:
    """The largest (x, y, w, h) rectangle of aspect ``aspect`` centred in an fb_w x fb_h framebuffer."""
    if fb_w <= 0 or fb_h <= 0:
        return (0, 0, 0, 0)
    if fb_w / fb_h > aspect:
        w, h = max(1, round(fb_h * aspect)), fb_h
    else:
        w, h = fb_w, max(1, round(fb_w / aspect))
    return ((fb_w - w) // 2, (fb_h - h) // 2, w, h)


def window_to_image(x: float, y: float, window_size: tuple[int, int], fb_size: tuple[int, int],
                    rect: tuple[int, int, int, int], image_size: tuple[int, int]) -> tuple[float, float] | None:
    """The image point (pixels, y down) under window point (x, y) (screen units, y down); None outside the image.

    Args:
        rect: where the image is drawn in the framebuffer, (x, y, w, h) with y from the bottom (``letterbox``).
    """
    w, h = window_size
    fb_w, fb_h = fb_size
    if w <= 0 or h <= 0:
        return None
    fx, fy = x * fb_w / w, y * fb_h / h
    rx, ry, rw, rh = rect
    top = fb_h - (ry + rh)
    if not (rx <= fx < rx + rw and top <= fy < top + rh):
        return None
    gw, gh = image_size
    return (fx - rx) / rw * gw, (fy - top) / rh * gh


def ui_scale(content_scale: float, window_w: int, fb_w: int) -> float:
    """How much to enlarge the panel: the monitor's content scale, less what the framebuffer already scales
    (macOS-style HiDPI gives a larger framebuffer; X11 and Windows report the scale and leave it to us)."""
    fb_scale = fb_w / window_w if window_w > 0 else 1.0
    return content_scale / fb_scale if fb_scale > 0 else 1.0


class Window:
    """A resizable GLFW window with an OpenGL 4.3 core, forward-compatible context, made current."""

    def __init__(self, size: tuple[int, int], title: str = "diviewer", vsync: bool = True):
        import glfw

        self.glfw = glfw
        if not glfw.init():
            raise DiviewerError("cannot initialise GLFW: no display? Set DISPLAY, or run under Xvfb "
                                "(Xvfb :99 & export DISPLAY=:99)")
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, GL_MAJOR)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, GL_MINOR)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
        glfw.window_hint(glfw.RESIZABLE, True)
        glfw.window_hint(glfw.SCALE_TO_MONITOR, True)
        w, h = size
        try:
            handle = glfw.create_window(int(w), int(h), title, None, None)
        except glfw.GLFWError as exc:
            handle, why = None, str(exc)
        else:
            why = "the driver offers no OpenGL 4.3 core context"
        if not handle:
            glfw.terminate()
            raise DiviewerError(f"cannot open a {w}x{h} window with OpenGL 4.3: {why}")
        self.handle = handle
        glfw.make_context_current(handle)
        self.vsync = vsync
        self.set_vsync(vsync)
        self._gl = None

    @property
    def size(self) -> tuple[int, int]:
        """Screen units (what mouse positions are in)."""
        return tuple(self.glfw.get_window_size(self.handle))

    @property
    def fb_size(self) -> tuple[int, int]:
        """Framebuffer pixels (what GL draws)."""
        return tuple(self.glfw.get_framebuffer_size(self.handle))

    def ui_scale(self) -> float:
        cx, _ = self.glfw.get_window_content_scale(self.handle)
        return ui_scale(cx, self.size[0], self.fb_size[0])

    def view_rect(self, image_size: tuple[int, int]) -> tuple[int, int, int, int]:
        """Where an image of ``image_size`` is drawn: letterboxed in the framebuffer, (x, y, w, h) from the bottom."""
        fb_w, fb_h = self.fb_size
        return letterbox(fb_w, fb_h, image_size[0] / image_size[1])

    def to_image(self, x: float, y: float, image_size: tuple[int, int]) -> tuple[float, float] | None:
        """The image point under window point (x, y); None outside the letterboxed image."""
        return window_to_image(x, y, self.size, self.fb_size, self.view_rect(image_size), image_size)

    def resize(self, width: int, height: int) -> None:
        """Resize (screen units); the framebuffer follows on the next event poll."""
        self.glfw.set_window_size(self.handle, int(width), int(height))

    def set_vsync(self, on: bool) -> None:
        self.vsync = bool(on)
        self.glfw.swap_interval(1 if self.vsync else 0)

    def should_close(self) -> bool:
        return bool(self.glfw.window_should_close(self.handle))

    def request_close(self) -> None:
        self.glfw.set_window_should_close(self.handle, True)

    def key_down(self, key: int) -> bool:
        return self.glfw.get_key(self.handle, key) == self.glfw.PRESS

    def read_pixels(self) -> np.ndarray:
        """What the window shows: its back buffer as drawn so far, (H, W, 3) uint8, top row first.

        Read with glReadPixels on the default framebuffer's GL_BACK: moderngl's ``ctx.screen.read()`` asks
        for GL_COLOR_ATTACHMENT0 (GL_INVALID_OPERATION on the default framebuffer) and keeps the window's
        first size after a resize, so the call goes through GLFW's own GL entry points.
        """
        import ctypes

        import numpy as np

        if self._gl is None:
            c = ctypes
            fn = lambda name, *args: c.CFUNCTYPE(None, *args)(self.glfw.get_proc_address(name))
            self._gl = (fn("glBindFramebuffer", c.c_uint, c.c_uint), fn("glReadBuffer", c.c_uint),
                        fn("glPixelStorei", c.c_uint, c.c_int),
                        fn("glReadPixels", c.c_int, c.c_int, c.c_int, c.c_int, c.c_uint, c.c_uint, c.c_void_p))
        bind, read_buffer, store, read_pixels = self._gl
        w, h = self.fb_size
        out = np.empty((h, w, 3), np.uint8)
        bind(0x8CA8, 0)  # GL_READ_FRAMEBUFFER
        read_buffer(0x0405)  # GL_BACK
        store(0x0D05, 1)  # GL_PACK_ALIGNMENT: rows of 3-byte pixels are not 4-aligned
        read_pixels(0, 0, w, h, 0x1907, 0x1401, out.ctypes.data)  # GL_RGB, GL_UNSIGNED_BYTE
        return np.ascontiguousarray(out[::-1])

    def swap(self) -> None:
        self.glfw.swap_buffers(self.handle)

    def close(self) -> None:
        self.glfw.destroy_window(self.handle)
        self.glfw.terminate()
