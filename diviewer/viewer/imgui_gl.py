"""imgui-bundle drawn through moderngl, and GLFW input forwarded to imgui (no PyOpenGL needed).

``ImguiRenderer`` implements imgui's renderer backend: it owns imgui's textures (the font atlas,
created and updated incrementally as imgui 1.92 asks: ``BackendFlags_.renderer_has_textures``), one
vertex and one index buffer refilled per draw list, and draws each command with its texture and
scissor rectangle under premultiplied-style alpha blending. ``GlfwImgui`` is the platform side:
display size, framebuffer scale (HiDPI), time, mouse, wheel, keys and characters; it calls the
app's own handlers after imgui has seen each event.
"""

from __future__ import annotations

import ctypes
import time

import glfw
import moderngl
import numpy as np
from imgui_bundle import imgui

from diviewer.gl.resources import set_uniform
from diviewer.gl.shaders import ShaderCache


def _ortho(x: float, y: float, w: float, h: float) -> np.ndarray:
    """Display rectangle (origin top left, y down) to clip space."""
    l, r, t, b = x, x + w, y, y + h
    m = np.identity(4)
    m[0, 0], m[1, 1] = 2.0 / (r - l), 2.0 / (t - b)
    m[0, 3], m[1, 3] = (r + l) / (l - r), (t + b) / (b - t)
    m[2, 2] = -1.0
    return m


def _bytes_at(address: int, size: int) -> memoryview:
    """A read-only view of ``size`` bytes of imgui's memory (vertex or index data) without copying."""
    return memoryview((ctypes.c_char * size).from_address(address)).cast("B")


class ImguiRenderer:
    """Draws imgui's draw data into the bound (default) framebuffer through moderngl."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderCache):
        if imgui.get_current_context() is None:
            raise RuntimeError("create an imgui context (imgui.create_context()) before the renderer")
        self.ctx = ctx
        self.program = shaders.program("imgui.glsl")
        self.textures: dict[int, moderngl.Texture] = {}
        """imgui texture id -> texture (the id is the GL name)."""
        self._vbo: moderngl.Buffer | None = None
        self._ibo: moderngl.Buffer | None = None
        self._vao: moderngl.VertexArray | None = None
        self._capacity = (0, 0)
        io = imgui.get_io()
        io.backend_flags |= imgui.BackendFlags_.renderer_has_textures
        pio = imgui.get_platform_io()
        max_size = int(ctx.info["GL_MAX_TEXTURE_SIZE"])
        pio.renderer_texture_max_width = pio.renderer_texture_max_height = max_size

    # --- textures ---------------------------------------------------------------------------------
    def _update_texture(self, tex) -> None:
        status = tex.status
        if status == imgui.ImTextureStatus.want_create:
            if tex.format != imgui.ImTextureFormat.rgba32:
                raise RuntimeError(f"imgui asked for texture format {tex.format}; this renderer uploads rgba32")
            pixels = np.ascontiguousarray(tex.get_pixels_array(), dtype=np.uint8)
            t = self.ctx.texture((tex.width, tex.height), 4, pixels.tobytes())
            # Bilinear: imgui's anti-aliased lines sample the atlas between texels.
            t.filter = (moderngl.LINEAR, moderngl.LINEAR)
            t.repeat_x = t.repeat_y = False
            self.textures[t.glo] = t
            tex.set_tex_id(t.glo)
            tex.status = imgui.ImTextureStatus.ok
        elif status == imgui.ImTextureStatus.want_updates:
            t = self.textures[tex.tex_id]
            full = np.asarray(tex.get_pixels_array(), dtype=np.uint8).reshape(tex.height, tex.width, 4)
            for r in tex.updates:
                block = np.ascontiguousarray(full[r.y:r.y + r.h, r.x:r.x + r.w])
                t.write(block.tobytes(), viewport=(r.x, r.y, r.w, r.h))
            tex.status = imgui.ImTextureStatus.ok
        elif status == imgui.ImTextureStatus.want_destroy:
            t = self.textures.pop(tex.tex_id, None)
            if t is not None:
                t.release()
            tex.set_tex_id(0)
            tex.status = imgui.ImTextureStatus.destroyed

    def _update_textures(self) -> None:
        for tex in imgui.get_platform_io().textures:
            if tex.status != imgui.ImTextureStatus.ok:
                self._update_texture(tex)

    # --- buffers ----------------------------------------------------------------------------------
    def _ensure_capacity(self, vtx_bytes: int, idx_bytes: int) -> None:
        cv, ci = self._capacity
        if vtx_bytes <= cv and idx_bytes <= ci and self._vao is not None:
            return
        cv, ci = max(vtx_bytes, cv * 2, 1 << 16), max(idx_bytes, ci * 2, 1 << 15)
        self._release_buffers()
        self._vbo = self.ctx.buffer(reserve=cv, dynamic=True)
        self._ibo = self.ctx.buffer(reserve=ci, dynamic=True)
        # imgui's ImDrawVert: pos (2 float), uv (2 float), colour (4 normalised bytes) = 20 bytes.
        assert imgui.VERTEX_SIZE == 20 and imgui.VERTEX_BUFFER_COL_OFFSET == 16, "unexpected ImDrawVert layout"
        self._vao = self.ctx.vertex_array(self.program, [(self._vbo, "2f 2f 4f1", "in_position", "in_uv", "in_color")],
                                          self._ibo, index_element_size=imgui.INDEX_SIZE)
        self._capacity = (cv, ci)

    def _release_buffers(self) -> None:
        for r in (self._vao, self._vbo, self._ibo):
            if r is not None:
                r.release()
        self._vao = self._vbo = self._ibo = None

    # --- drawing ----------------------------------------------------------------------------------
    def render(self, draw_data=None) -> None:
        """Draw ``draw_data`` (default: ``imgui.get_draw_data()`` after ``imgui.render()``) into the bound
        framebuffer."""
        draw_data = draw_data if draw_data is not None else imgui.get_draw_data()
        self._update_textures()
        dw, dh = draw_data.display_size.x, draw_data.display_size.y
        sx, sy = draw_data.framebuffer_scale.x, draw_data.framebuffer_scale.y
        fb_w, fb_h = int(dw * sx), int(dh * sy)
        if fb_w <= 0 or fb_h <= 0 or draw_data.total_vtx_count == 0:
            return
        ctx = self.ctx
        ctx.viewport = (0, 0, fb_w, fb_h)
        ctx.enable_only(moderngl.BLEND)
        ctx.blend_equation = moderngl.FUNC_ADD
        ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        px, py = draw_data.display_pos.x, draw_data.display_pos.y
        set_uniform(self.program, "m_proj", _ortho(px, py, dw, dh))
        set_uniform(self.program, "u_texture", 0)
        try:
            for cmd_list in draw_data.cmd_lists:
                vtx_bytes = cmd_list.vtx_buffer.size() * imgui.VERTEX_SIZE
                idx_bytes = cmd_list.idx_buffer.size() * imgui.INDEX_SIZE
                if vtx_bytes == 0 or idx_bytes == 0:
                    continue
                self._ensure_capacity(vtx_bytes, idx_bytes)
                self._vbo.orphan(self._capacity[0])
                self._ibo.orphan(self._capacity[1])
                self._vbo.write(_bytes_at(cmd_list.vtx_buffer.data_address(), vtx_bytes))
                self._ibo.write(_bytes_at(cmd_list.idx_buffer.data_address(), idx_bytes))
                for cmd in cmd_list.cmd_buffer:
                    if cmd.elem_count == 0:
                        continue
                    cx0 = (cmd.clip_rect.x - px) * sx
                    cy0 = (cmd.clip_rect.y - py) * sy
                    cx1 = (cmd.clip_rect.z - px) * sx
                    cy1 = (cmd.clip_rect.w - py) * sy
                    cx0, cy0 = max(cx0, 0.0), max(cy0, 0.0)
                    cx1, cy1 = min(cx1, fb_w), min(cy1, fb_h)
                    if cx1 <= cx0 or cy1 <= cy0:
                        continue
                    # GL's scissor origin is the bottom-left corner.
                    ctx.scissor = (int(cx0), int(fb_h - cy1), int(cx1 - cx0), int(cy1 - cy0))
                    tex = self.textures.get(cmd.tex_ref.get_tex_id())
                    if tex is None:
                        continue
                    tex.use(location=0)
                    if cmd.vtx_offset:
                        raise RuntimeError("imgui draw command with a vertex offset, but renderer_has_vtx_offset "
                                           "is not set")
                    self._vao.render(moderngl.TRIANGLES, vertices=cmd.elem_count, first=cmd.idx_offset)
        finally:
            ctx.scissor = None
            ctx.disable(moderngl.BLEND)

    def release(self) -> None:
        """Free the GL objects and tell imgui its textures are gone."""
        for tex in imgui.get_platform_io().textures:
            if tex.tex_id in self.textures:
                tex.status = imgui.ImTextureStatus.want_destroy
                self._update_texture(tex)
        for t in self.textures.values():
            t.release()
        self.textures.clear()
        self._release_buffers()
        io = imgui.get_io()
        io.backend_flags &= ~imgui.BackendFlags_.renderer_has_textures


def _glfw_key_map() -> dict[int, "imgui.Key"]:
    k = imgui.Key
    m = {
        glfw.KEY_TAB: k.tab, glfw.KEY_LEFT: k.left_arrow, glfw.KEY_RIGHT: k.right_arrow, glfw.KEY_UP: k.up_arrow,
        glfw.KEY_DOWN: k.down_arrow, glfw.KEY_PAGE_UP: k.page_up, glfw.KEY_PAGE_DOWN: k.page_down,
        glfw.KEY_HOME: k.home, glfw.KEY_END: k.end, glfw.KEY_INSERT: k.insert, glfw.KEY_DELETE: k.delete,
        glfw.KEY_BACKSPACE: k.backspace, glfw.KEY_SPACE: k.space, glfw.KEY_ENTER: k.enter,
        glfw.KEY_ESCAPE: k.escape, glfw.KEY_KP_ENTER: k.keypad_enter,
        glfw.KEY_LEFT_CONTROL: k.left_ctrl, glfw.KEY_RIGHT_CONTROL: k.right_ctrl,
        glfw.KEY_LEFT_SHIFT: k.left_shift, glfw.KEY_RIGHT_SHIFT: k.right_shift,
        glfw.KEY_LEFT_ALT: k.left_alt, glfw.KEY_RIGHT_ALT: k.right_alt,
        glfw.KEY_LEFT_SUPER: k.left_super, glfw.KEY_RIGHT_SUPER: k.right_super,
        glfw.KEY_APOSTROPHE: k.apostrophe, glfw.KEY_COMMA: k.comma, glfw.KEY_MINUS: k.minus,
        glfw.KEY_PERIOD: k.period, glfw.KEY_SLASH: k.slash, glfw.KEY_SEMICOLON: k.semicolon,
        glfw.KEY_EQUAL: k.equal, glfw.KEY_LEFT_BRACKET: k.left_bracket, glfw.KEY_BACKSLASH: k.backslash,
        glfw.KEY_RIGHT_BRACKET: k.right_bracket, glfw.KEY_GRAVE_ACCENT: k.grave_accent,
        glfw.KEY_CAPS_LOCK: k.caps_lock, glfw.KEY_SCROLL_LOCK: k.scroll_lock, glfw.KEY_NUM_LOCK: k.num_lock,
        glfw.KEY_PRINT_SCREEN: k.print_screen, glfw.KEY_PAUSE: k.pause, glfw.KEY_MENU: k.menu,
        glfw.KEY_KP_DECIMAL: k.keypad_decimal, glfw.KEY_KP_DIVIDE: k.keypad_divide,
        glfw.KEY_KP_MULTIPLY: k.keypad_multiply, glfw.KEY_KP_SUBTRACT: k.keypad_subtract,
        glfw.KEY_KP_ADD: k.keypad_add, glfw.KEY_KP_EQUAL: k.keypad_equal,
    }
    for c in "ABCDEFGHIJKLMNOPQRSTUVWXYZ":
        m[getattr(glfw, f"KEY_{c}")] = getattr(k, c.lower())
    for d in range(10):
        m[getattr(glfw, f"KEY_{d}")] = getattr(k, f"_{d}")
        m[getattr(glfw, f"KEY_KP_{d}")] = getattr(k, f"keypad{d}")
    for f in range(1, 13):
        m[getattr(glfw, f"KEY_F{f}")] = getattr(k, f"f{f}")
    return m


class GlfwImgui:
    """GLFW events to imgui, then to the app's handler (``on_key``, ``on_char``, ``on_mouse_button``,
    ``on_cursor``, ``on_scroll``, each optional); the app decides with ``wants_mouse``/``wants_keyboard``
    whether imgui took the event."""

    def __init__(self, window, handler=None):
        self.window = window
        self.handler = handler
        self.io = imgui.get_io()
        self.key_map = _glfw_key_map()
        self._last_time: float | None = None
        glfw.set_key_callback(window, self._on_key)
        glfw.set_char_callback(window, self._on_char)
        glfw.set_mouse_button_callback(window, self._on_mouse_button)
        glfw.set_cursor_pos_callback(window, self._on_cursor)
        glfw.set_cursor_enter_callback(window, self._on_cursor_enter)
        glfw.set_scroll_callback(window, self._on_scroll)
        glfw.set_window_focus_callback(window, self._on_focus)
        pio = imgui.get_platform_io()
        pio.platform_get_clipboard_text_fn = lambda _ctx: (glfw.get_clipboard_string(window) or b"").decode()
        pio.platform_set_clipboard_text_fn = lambda _ctx, text: glfw.set_clipboard_string(window, text)

    def _call(self, name: str, *args) -> None:
        fn = getattr(self.handler, name, None)
        if fn is not None:
            fn(*args)

    # --- callbacks --------------------------------------------------------------------------------
    def _mods(self, mods: int) -> None:
        io, k = self.io, imgui.Key
        io.add_key_event(k.mod_ctrl, bool(mods & glfw.MOD_CONTROL))
        io.add_key_event(k.mod_shift, bool(mods & glfw.MOD_SHIFT))
        io.add_key_event(k.mod_alt, bool(mods & glfw.MOD_ALT))
        io.add_key_event(k.mod_super, bool(mods & glfw.MOD_SUPER))

    def _on_key(self, window, key, scancode, action, mods) -> None:
        if action in (glfw.PRESS, glfw.RELEASE):
            self._mods(mods)
            if key in self.key_map:
                self.io.add_key_event(self.key_map[key], action == glfw.PRESS)
        self._call("on_key", key, action, mods)

    def _on_char(self, window, codepoint) -> None:
        if 0 < codepoint < 0x110000:
            self.io.add_input_character(codepoint)
        self._call("on_char", codepoint)

    def _on_mouse_button(self, window, button, action, mods) -> None:
        self._mods(mods)
        if 0 <= button < 5:
            self.io.add_mouse_button_event(button, action == glfw.PRESS)
        self._call("on_mouse_button", button, action, mods)

    def _on_cursor(self, window, x, y) -> None:
        self.io.add_mouse_pos_event(float(x), float(y))  # window coordinates; imgui scales for the framebuffer
        self._call("on_cursor", x, y)

    def _on_cursor_enter(self, window, entered) -> None:
        if not entered:
            self.io.add_mouse_pos_event(-imgui.FLT_MAX, -imgui.FLT_MAX)

    def _on_scroll(self, window, dx, dy) -> None:
        self.io.add_mouse_wheel_event(float(dx), float(dy))
        self._call("on_scroll", dx, dy)

    def _on_focus(self, window, focused) -> None:
        self.io.add_focus_event(bool(focused))

    # --- per frame --------------------------------------------------------------------------------
    @property
    def wants_mouse(self) -> bool:
        return bool(self.io.want_capture_mouse)

    @property
    def wants_keyboard(self) -> bool:
        return bool(self.io.want_capture_keyboard or self.io.want_text_input)

    def new_frame(self) -> None:
        """Display size (window units), framebuffer scale (HiDPI) and time step; then ``imgui.new_frame()``."""
        w, h = glfw.get_window_size(self.window)
        fw, fh = glfw.get_framebuffer_size(self.window)
        self.io.display_size = imgui.ImVec2(float(w), float(h))
        self.io.display_framebuffer_scale = imgui.ImVec2(fw / w if w > 0 else 1.0, fh / h if h > 0 else 1.0)
        now = time.perf_counter()
        self.io.delta_time = max(now - self._last_time, 1e-4) if self._last_time is not None else 1.0 / 60.0
        self._last_time = now
        imgui.new_frame()

    def release(self) -> None:
        for setter in (glfw.set_key_callback, glfw.set_char_callback, glfw.set_mouse_button_callback,
                       glfw.set_cursor_pos_callback, glfw.set_cursor_enter_callback, glfw.set_scroll_callback,
                       glfw.set_window_focus_callback):
            setter(self.window, None)
