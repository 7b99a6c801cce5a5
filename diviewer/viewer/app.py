"""`diviewer view`: a GLFW window that renders a scene with neural GI every frame, with an imgui panel.

Usage::

    diviewer view --scene cornell                      # interactive, the scene's model if one is shipped
    diviewer view --frames 60 --screenshot shot.png    # scripted: 60 frames, save the last, exit

Each frame: the GL renderer draws the G-buffer and direct light at the GI resolution (the model's
training resolution when a model is loaded, else the window's framebuffer), the neural pass turns
them into the final image, the view mode's image is drawn into the window (letterboxed to the GI
aspect ratio), and the panel goes on top. Nothing here imports torch.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.gl.renderer import RenderSettings
from diviewer.scene.model import Scene
from diviewer.viewer.reference import ReferenceSettings
from diviewer.viewer.state import (
    STAGES, TONEMAPS, VIEW_MODES, Unavailable, ViewerState, ViewMode, single_modes, view_mode,
)

DISPLAY_KINDS = {"radiance": 0, "raw": 1, "depth": 2, "normal": 3, "albedo": 4}
LAYOUTS = {"single": 0, "split": 1, "difference": 2}
BACKGROUND = (0.08, 0.08, 0.09)
WARN = (1.0, 0.75, 0.3, 1.0)
DIM = (0.6, 0.6, 0.6, 1.0)
"""Colour of the bars around the GI image when the window's aspect ratio differs."""

SHORTCUTS: tuple[tuple[str, str], ...] = (
    ("W A S D", "fly forward / left / back / right (orbit: pan the centre)"),
    ("Q / E", "down / up"),
    ("Shift", "move 4x faster"),
    ("right mouse drag", "look around"),
    ("left mouse drag", "orbit (orbit camera) / look (fly camera)"),
    ("left click", "select the object under the cursor"),
    ("mouse wheel", "flying speed (fly) / zoom (orbit)"),
    ("C", "switch fly / orbit camera"),
    ("R", "reset the camera"),
    ("Shift+R", "reset the whole frame (lights, objects, camera)"),
    ("arrow keys", "light azimuth (left/right) and elevation (up/down)"),
    ("L", "animate the light"),
    ("P", "play the scene's camera path"),
    ("Tab", "select the next object"),
    ("1 ... 0", "view modes: " + ", ".join(f"{m.key} {m.name}" for m in VIEW_MODES if m.key)),
    ("+ / -", "exposure up / down half a stop"),
    ("F12 or Ctrl+S", "screenshot (PNG + frame JSON)"),
    ("V", "vsync on / off"),
    ("H or F1", "show / hide the panel"),
    ("Esc", "quit"),
)
"""The keyboard and mouse controls (the panel and the README list them)."""


@dataclass(frozen=True)
class ViewerSettings:
    """Settings of one viewer session."""

    size: tuple[int, int] = (768, 768)
    """Window size in screen units (the framebuffer may be larger on HiDPI screens)."""
    vsync: bool = True
    model: str = "auto"
    """A model file, ``auto`` (the first compatible assets/models/<scene>*.onnx) or ``none``."""
    provider: str | None = None
    """onnxruntime execution provider (cpu, cuda, tensorrt); None picks the fastest available."""
    controller: str = "fly"
    """Camera controller at start: fly or orbit."""
    timing: bool = True
    """Time each stage (waits for the GPU between stages: the frame is a little slower, the numbers are honest)."""
    panel: bool = True
    render: RenderSettings = field(default_factory=RenderSettings)
    reference: ReferenceSettings = field(default_factory=ReferenceSettings)
    reference_max_size: int = 512
    """Longest side of the path-traced reference (it is scaled to the view)."""
    title: str = "diviewer"


# --- models ---------------------------------------------------------------------------------------

def model_candidates(scene: Scene) -> list[Path]:
    """The shipped models named for this scene: assets/models/<scene>*.onnx."""
    from diviewer.paths import models_dir

    try:
        folder = models_dir()
    except FileNotFoundError:
        return []
    return sorted(folder.glob(f"{scene.name}*.onnx")) if folder.is_dir() else []


def open_model(spec: str | Path | None, scene: Scene, provider: str | None = None):
    """Load the model ``spec`` asks for (a path, ``auto`` or ``none``) for ``scene``.

    Returns:
        (NeuralGI or None, message): the message says why there is no model, or which was chosen.
    """
    from diviewer.runtime import NeuralGI, choose_providers

    spec = "auto" if spec is None else str(spec)
    if spec.lower() == "none":
        return None, "neural GI is off (no model requested)"
    if provider:
        import onnxruntime as ort

        # A missing provider is the user's error, not the model's.
        choose_providers(ort.get_available_providers(), provider)
    if spec.lower() != "auto":
        try:
            return NeuralGI(spec, scene=scene, provider=provider), ""
        except DiviewerError as exc:
            return None, f"model refused: {exc}"
    candidates = model_candidates(scene)
    if not candidates:
        from diviewer.paths import models_dir

        try:
            where = models_dir()
        except FileNotFoundError:
            where = "assets/models"
        return None, (f"no model for scene '{scene.name}' in {where} (train and export one: diviewer train, "
                      f"diviewer export); showing direct light only")
    refusals = []
    for path in candidates:
        try:
            return NeuralGI(path, scene=scene, provider=provider), ""
        except DiviewerError as exc:
            refusals.append(str(exc))
    return None, "no compatible model for this scene: " + "; ".join(refusals)


def meta_lines(meta: dict) -> list[tuple[str, str]]:
    """The model card as (key, value) rows for the panel."""
    rows = []
    for key in ("scene", "K", "levels", "resolution", "multiple", "target", "precision", "epoch", "dataset_hash"):
        if key in meta:
            v = meta[key]
            rows.append((key, f"{v[:12]}..." if key.endswith("hash") and isinstance(v, str) else str(v)))
    for key, v in meta.items():
        if isinstance(v, dict) and any(w in key for w in ("val", "metric")):
            for k2, v2 in v.items():
                rows.append((f"{key}.{k2}", f"{v2:.4g}" if isinstance(v2, float) else str(v2)))
        elif key.startswith("val") and not isinstance(v, (dict, list)):
            rows.append((key, f"{v:.4g}" if isinstance(v, float) else str(v)))
    return rows


def letterbox(fb_w: int, fb_h: int, aspect: float) -> tuple[int, int, int, int]:
    """The largest (x, y, w, h) rectangle of aspect ``aspect`` centred in an fb_w x fb_h framebuffer."""
    if fb_w <= 0 or fb_h <= 0:
        return (0, 0, 0, 0)
    if fb_w / fb_h > aspect:
        w, h = max(1, round(fb_h * aspect)), fb_h
    else:
        w, h = fb_w, max(1, round(fb_w / aspect))
    return ((fb_w - w) // 2, (fb_h - h) // 2, w, h)


# --- the window -----------------------------------------------------------------------------------

@dataclass
class _Image:
    texture: Any
    flip: bool
    """Rows top first (neural output, reference): sampled upside down."""


class _Sources:
    """One frame's images for the view modes (state.FrameSources); the neural pass runs at most once."""

    def __init__(self, viewer: "Viewer"):
        self.v = viewer
        self.has_model = viewer.neural is not None
        self._neural: _Image | None = None

    def buffer(self, name: str) -> _Image:
        return _Image(self.v.renderer.textures[name], False)

    def network_output(self) -> _Image:
        v = self.v
        if v.neural is None:
            raise Unavailable(v.state.model_message or "no model loaded")
        if self._neural is None:
            tex = v.neural.run()
            v.stage_times.update(v.neural.timings)
            self._neural = _Image(tex, True)
        return self._neural

    def reference(self) -> _Image:
        return self.v.reference_image()


class Viewer:
    """The window, its GL resources and the frame loop. ``run_viewer`` is the usual entry point."""

    def __init__(self, scene: Scene, settings: ViewerSettings = ViewerSettings()):
        import glfw
        import moderngl
        from imgui_bundle import imgui

        from diviewer.viewer.reference import ProgressiveReference

        self.glfw, self.imgui, self.moderngl = glfw, imgui, moderngl
        self.settings = settings
        self._closed = False
        self.window = _open_window(glfw, settings)
        self.imgui_ctx = None
        self.reference = ProgressiveReference(settings.reference)
        try:
            self._setup(scene)
        except BaseException:
            # GL objects die with the window's context; the rest is released here.
            self.reference.close()
            if self.imgui_ctx is not None:
                imgui.destroy_context(self.imgui_ctx)
            glfw.destroy_window(self.window)
            glfw.terminate()
            raise

    def _setup(self, scene: Scene) -> None:
        """Everything that needs the window's GL context: renderer, display passes, imgui, the model."""
        from diviewer.gl.context import create_context, describe
        from diviewer.gl.renderer import Compositor, Renderer
        from diviewer.gl.shaders import ShaderCache
        from diviewer.viewer.imgui_gl import GlfwImgui, ImguiRenderer

        glfw, imgui, settings = self.glfw, self.imgui, self.settings
        self.ctx = create_context("window")
        self.gl_renderer = describe(self.ctx)
        self.vsync = settings.vsync
        self.state = ViewerState(scene, controller=settings.controller)
        self.state.show_panel = settings.panel
        self.shaders = ShaderCache(self.ctx)
        fb_w, fb_h = (max(1, s) for s in glfw.get_framebuffer_size(self.window))
        self.renderer = Renderer(self.ctx, scene, fb_w, fb_h, settings.render, self.shaders)
        self.compositor = Compositor(self.ctx, self.shaders)
        self.view_program = self.shaders.program("view.glsl")
        self.view_vao = self.ctx.vertex_array(self.view_program, [])
        self.black = self.ctx.texture((1, 1), 3, np.zeros(3, np.float32).tobytes(), dtype="f4")
        self._scene_revision = 0
        self._uploaded: dict[str, object] = {}
        """Meshes and materials uploaded after the start (loaded files), to spot replacements."""
        self.model = None
        self.neural = None
        self._ref_texture = None
        self._ref_serial = -1
        self._shot_fbo: tuple | None = None
        self.imgui_ctx = imgui.create_context()
        io = imgui.get_io()
        io.set_ini_filename(None)  # no imgui.ini in the user's working folder
        self.gui = GlfwImgui(self.window, handler=self)
        self.imgui_renderer = ImguiRenderer(self.ctx, self.shaders)
        self._apply_ui_scale()
        self.stage_times: dict[str, float] = {}
        self.frame_index = 0
        self._last_frame_start: float | None = None
        self._mouse = {"left": False, "right": False, "x": 0.0, "y": 0.0, "dragged": 0.0}
        self.shot_path = f"diviewer_{scene.name}.png"
        self.screenshots: list[Path] = []
        self._pending_shots: list[Path] = []
        self._pending_window_shots: list[Path] = []
        self._pending_model: str | None = None
        self.unavailable: dict[str, str] = {}
        self.modes_drawn: set[str] = set()
        self.candidates = model_candidates(scene)
        self.set_model(settings.model)

    # --- setup helpers -----------------------------------------------------------------------------
    def _apply_ui_scale(self) -> None:
        """Scale the panel on HiDPI screens whose framebuffer is not already larger than the window."""
        glfw, imgui = self.glfw, self.imgui
        cx, _ = glfw.get_window_content_scale(self.window)
        w, _ = glfw.get_window_size(self.window)
        fw, _ = glfw.get_framebuffer_size(self.window)
        fb_scale = fw / w if w > 0 else 1.0
        s = cx / fb_scale if fb_scale > 0 else 1.0
        if s > 1.05:
            style = imgui.get_style()
            style.scale_all_sizes(s)
            style.font_scale_dpi = s

    @property
    def gi_size(self) -> tuple[int, int]:
        return self.renderer.width, self.renderer.height

    def set_model(self, spec: str | Path | None) -> None:
        """Load a model (path, ``auto`` or ``none``); without one the viewer shows direct light and says why."""
        from diviewer.gl.neural import NeuralPass

        self._drop_model()
        model, message = open_model(spec, self.state.scene, self.settings.provider)
        st = self.state
        st.model_message, st.model_meta, st.provider = message, None, ""
        st.model_name = None
        if model is not None:
            w, h = model.resolution
            try:
                model.check_size(w, h)
                self.renderer.resize(w, h)
                self.neural = NeuralPass(self.ctx, self.renderer, model)
            except DiviewerError as exc:
                st.model_message = f"model refused: {exc}"
                self._fit_renderer_to_window()
                return
            self.model = model
            st.model_name = model.path.name
            st.model_meta = dict(model.meta)
            st.provider = model.provider
        else:
            self._fit_renderer_to_window()
        if message and spec not in (None, "auto", "none"):
            print(f"diviewer view: {message}", file=sys.stderr)

    def _drop_model(self) -> None:
        if self.neural is not None:
            self.neural.release()
        self.neural = None
        self.model = None  # drops the onnxruntime session

    def _fit_renderer_to_window(self) -> None:
        fb_w, fb_h = self.glfw.get_framebuffer_size(self.window)
        if fb_w > 0 and fb_h > 0:
            self.renderer.resize(fb_w, fb_h)

    def _sync_scene(self) -> None:
        """Upload meshes and textures added to the scene (a mesh file loaded from the panel)."""
        from diviewer.gl.resources import upload_texture

        if self.state.scene_revision == self._scene_revision:
            return
        scene, gpu = self.state.scene, self.renderer.gpu
        for key, mesh in scene.meshes.items():
            # A file loaded again under the same key replaces the mesh: compare the objects, not the keys.
            if key not in gpu.meshes or (key in self._uploaded and self._uploaded[key] is not mesh):
                gpu.add_mesh(self.ctx, mesh)
                self._uploaded[key] = mesh
        for key, mat in scene.materials.items():
            if mat.texture is not None and (key not in gpu.textures or self._uploaded.get(key) is not mat):
                if key in gpu.textures:
                    gpu.textures[key].release()
                gpu.textures[key] = upload_texture(self.ctx, mat.texture)
                self._uploaded[key] = mat
        self.renderer.scene = scene
        self._scene_revision = self.state.scene_revision

    # --- input handlers (called by GlfwImgui after imgui has seen the event) -----------------------
    def on_key(self, key: int, action: int, mods: int) -> None:
        glfw, st = self.glfw, self.state
        if action not in (glfw.PRESS, glfw.REPEAT) or self.gui.wants_keyboard:
            return
        shift, ctrl = bool(mods & glfw.MOD_SHIFT), bool(mods & glfw.MOD_CONTROL)
        step = 5.0
        if key in (glfw.KEY_LEFT, glfw.KEY_RIGHT, glfw.KEY_UP, glfw.KEY_DOWN) and st.config.lights:
            az, el = st.light_angles()
            az += step * ((key == glfw.KEY_RIGHT) - (key == glfw.KEY_LEFT))
            el = min(max(el + step * ((key == glfw.KEY_UP) - (key == glfw.KEY_DOWN)), -89.0), 89.0)
            st.set_light_direction(az, el)
            return
        if action != glfw.PRESS:
            return
        if key == glfw.KEY_ESCAPE:
            glfw.set_window_should_close(self.window, True)
        elif key == glfw.KEY_C:
            st.toggle_controller()
        elif key == glfw.KEY_R:
            st.reset() if shift else st.reset_camera()
        elif key == glfw.KEY_L:
            st.toggle_animation()
        elif key == glfw.KEY_P:
            st.toggle_path()
        elif key == glfw.KEY_TAB:
            names = [o.name for o in st.config.objects]
            i = names.index(st.selected) + 1 if st.selected in names else 0
            st.select_object(names[i % len(names)])
        elif key in (glfw.KEY_H, glfw.KEY_F1):
            st.show_panel = not st.show_panel
        elif key == glfw.KEY_V:
            self.set_vsync(not self.vsync)
        elif key == glfw.KEY_F12 or (ctrl and key == glfw.KEY_S):
            self.screenshot(self.shot_path)
        elif key in (glfw.KEY_EQUAL, glfw.KEY_KP_ADD):
            st.set_exposure(st.exposure + 0.5)
        elif key in (glfw.KEY_MINUS, glfw.KEY_KP_SUBTRACT):
            st.set_exposure(st.exposure - 0.5)
        elif not ctrl:
            name = glfw.get_key_name(key, 0)
            for m in VIEW_MODES:
                if m.key and name == m.key:
                    st.set_view_mode(m.name)

    def on_mouse_button(self, button: int, action: int, mods: int) -> None:
        glfw, m = self.glfw, self._mouse
        which = {glfw.MOUSE_BUTTON_LEFT: "left", glfw.MOUSE_BUTTON_RIGHT: "right"}.get(button)
        if which is None:
            return
        if action == glfw.PRESS:
            if self.gui.wants_mouse:
                return
            m[which] = True
            m["dragged"] = 0.0
        elif action == glfw.RELEASE and m[which]:
            m[which] = False
            if which == "left" and m["dragged"] < 3.0:
                self.pick_window_point(m["x"], m["y"])  # where on_cursor last saw the pointer

    def on_cursor(self, x: float, y: float) -> None:
        m = self._mouse
        dx, dy = x - m["x"], y - m["y"]
        m["x"], m["y"] = x, y
        if m["right"]:
            self.state.look(dx, dy)
        elif m["left"]:
            m["dragged"] += abs(dx) + abs(dy)
            if m["dragged"] >= 3.0:
                self.state.drag(dx, dy)

    def on_scroll(self, dx: float, dy: float) -> None:
        if not self.gui.wants_mouse:
            self.state.scroll(dy)

    def _held_keys(self, dt: float) -> None:
        glfw, st = self.glfw, self.state
        if self.gui.wants_keyboard:
            return
        down = lambda k: glfw.get_key(self.window, k) == glfw.PRESS  # noqa: E731
        if down(glfw.KEY_LEFT_CONTROL) or down(glfw.KEY_RIGHT_CONTROL):
            return
        f = down(glfw.KEY_W) - down(glfw.KEY_S)
        r = down(glfw.KEY_D) - down(glfw.KEY_A)
        u = down(glfw.KEY_E) - down(glfw.KEY_Q)
        if f or r or u:
            st.fly(f, r, u, dt, fast=down(glfw.KEY_LEFT_SHIFT) or down(glfw.KEY_RIGHT_SHIFT))

    # --- actions (also script actions) -------------------------------------------------------------
    def set_vsync(self, on: bool) -> None:
        self.vsync = bool(on)
        self.glfw.swap_interval(1 if self.vsync else 0)

    def resize(self, width: int, height: int) -> None:
        """Resize the window (screen units); the framebuffer follows on the next event poll."""
        self.glfw.set_window_size(self.window, int(width), int(height))

    def view_rect(self) -> tuple[int, int, int, int]:
        """Where the GI image is drawn in the framebuffer: (x, y, w, h), y from the bottom."""
        fb_w, fb_h = self.glfw.get_framebuffer_size(self.window)
        gw, gh = self.gi_size
        return letterbox(fb_w, fb_h, gw / gh)

    def pick_window_point(self, x: float, y: float) -> str | None:
        """Select the object under window point (x, y) (screen units, y down)."""
        glfw = self.glfw
        w, h = glfw.get_window_size(self.window)
        fb_w, fb_h = glfw.get_framebuffer_size(self.window)
        if w <= 0 or h <= 0:
            return None
        fx, fy = x * fb_w / w, y * fb_h / h
        rx, ry, rw, rh = self.view_rect()
        top = fb_h - (ry + rh)
        if not (rx <= fx < rx + rw and top <= fy < top + rh):
            return self.state.select_object(None)
        gw, gh = self.gi_size
        return self.state.pick((fx - rx) / rw * gw, (fy - top) / rh * gh, gw, gh)

    def reference_image(self) -> _Image:
        """The reference's latest image, uploaded when new (requests the current view)."""
        ref = self.reference
        if not ref.available:
            raise Unavailable(str(ref.error))
        gw, gh = self.gi_size
        s = min(1.0, self.settings.reference_max_size / max(gw, gh))
        rw, rh = max(1, round(gw * s)), max(1, round(gh * s))
        ref.request(self.state.scene, self.state.config, rw, rh)
        img = ref.latest()
        if img is None:
            raise Unavailable(ref.status())
        if img.serial != self._ref_serial:
            h, w = img.image.shape[:2]
            if self._ref_texture is None or self._ref_texture.size != (w, h):
                if self._ref_texture is not None:
                    self._ref_texture.release()
                self._ref_texture = self.ctx.texture((w, h), 3, dtype="f4")
                self._ref_texture.filter = (self.moderngl.LINEAR, self.moderngl.LINEAR)
                self._ref_texture.repeat_x = self._ref_texture.repeat_y = False
            self._ref_texture.write(img.image.tobytes())
            self._ref_serial = img.serial
        return _Image(self._ref_texture, True)

    def screenshot(self, path: str | Path) -> Path:
        """Save the view (without the panel) at the GI resolution as PNG, and the frame as JSON, at the
        end of the next frame (so image and configuration agree). The JSON is the frame.json that
        ``diviewer render --config`` reads, plus the view settings."""
        path = Path(path)
        if path.suffix.lower() != ".png":
            path = path.with_suffix(".png")
        self._pending_shots.append(path)
        return path

    def window_screenshot(self, path: str | Path) -> Path:
        """Save the whole window (with the panel) as PNG at the end of the next frame."""
        path = Path(path)
        self._pending_window_shots.append(path)
        return path

    def _save_screenshot(self, path: Path, images: list[_Image]) -> Path:
        from diviewer import imageio
        from diviewer.render import frame_record

        gw, gh = self.gi_size
        if self._shot_fbo is None or self._shot_fbo[0].size != (gw, gh):
            self._release_shot_fbo()
            tex = self.ctx.texture((gw, gh), 4)
            self._shot_fbo = (tex, self.ctx.framebuffer([tex]))
        tex, fbo = self._shot_fbo
        self._draw_view(fbo, (0, 0, gw, gh), images)
        rgb = np.frombuffer(fbo.read(components=3), np.uint8).reshape(gh, gw, 3)
        path.parent.mkdir(parents=True, exist_ok=True)
        imageio.write_png(path, np.ascontiguousarray(np.flipud(rgb)))
        st = self.state
        record = frame_record(st.scene, st.config, (gw, gh), view_mode=st.view_mode,
                              compare=list(st.compare) if view_mode(st.view_mode).layout != "single" else None,
                              model=str(self.model.path) if self.model is not None else None,
                              model_message=st.model_message or None, provider=st.provider or None,
                              display={"exposure": st.exposure, "tonemap": st.tonemap},
                              gl_renderer=self.gl_renderer, user_meshes=dict(st.user_meshes) or None)
        imageio.write_text(path.with_suffix(".json"), json.dumps(record, indent=2))
        self.screenshots.append(path)
        st.message = f"saved {path} and {path.with_suffix('.json').name}"
        return path

    def _save_window(self, path: Path, rect, images: list[_Image]) -> Path:
        """The window as just drawn (view + panel), redrawn into an offscreen target and saved as PNG.

        Redrawn rather than read back: reading the default framebuffer through moderngl reads
        GL_COLOR_ATTACHMENT0 (invalid there), and ``ctx.screen``'s size is the window's first size.
        """
        from diviewer import imageio
        from diviewer.gl.context import unbind_framebuffer

        fb_w, fb_h = self.glfw.get_framebuffer_size(self.window)
        tex = self.ctx.texture((fb_w, fb_h), 4)
        fbo = self.ctx.framebuffer([tex])
        try:
            fbo.use()
            fbo.clear(*BACKGROUND, 1.0)
            self._draw_view(fbo, rect, images)
            fbo.viewport = (0, 0, fb_w, fb_h)
            fbo.use()
            self.imgui_renderer.render(self.imgui.get_draw_data())
            rgb = np.frombuffer(fbo.read(components=3), np.uint8).reshape(fb_h, fb_w, 3)
        finally:
            unbind_framebuffer(self.ctx)
            fbo.release()
            tex.release()
        path.parent.mkdir(parents=True, exist_ok=True)
        imageio.write_png(path, np.ascontiguousarray(np.flipud(rgb)))
        return path

    def _release_shot_fbo(self) -> None:
        from diviewer.gl.context import unbind_framebuffer

        if self._shot_fbo is not None:
            unbind_framebuffer(self.ctx)
            self._shot_fbo[1].release()
            self._shot_fbo[0].release()
            self._shot_fbo = None

    # --- drawing -----------------------------------------------------------------------------------
    def _produce(self, mode: ViewMode, sources: _Sources) -> tuple[_Image, str | None]:
        try:
            img = mode.produce(sources)
            self.modes_drawn.add(mode.name)
            self.unavailable.pop(mode.name, None)
            return img, None
        except Unavailable as exc:
            self.unavailable[mode.name] = str(exc)
            return _Image(self.black, False), str(exc)

    def _depth_range(self) -> tuple[float, float]:
        cfg = self.state.config
        b = self.state.scene.bounds(cfg)
        corners = np.array([[b[i, 0], b[j, 1], b[k, 2], 1.0] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        z = -(cfg.camera.view_matrix() @ corners.T)[2]
        return max(float(z.min()), cfg.camera.near), max(float(z.max()), cfg.camera.near + 1e-3)

    def _images(self, sources: _Sources) -> tuple[list[_Image], list[str]]:
        """The images the current view mode shows (running the neural pass if one needs it), and the
        reasons of those that cannot be produced (shown as black)."""
        images, notes = [], []
        for m in self.state.modes_shown():
            img, note = self._produce(m, sources)
            images.append(img)
            if note:
                notes.append(f"{m.label}: {note}")
        return images, notes

    def _draw_view(self, target, rect: tuple[int, int, int, int], images: list[_Image]) -> None:
        """Draw the current view mode's images into ``rect`` of ``target``."""
        from diviewer.gl.resources import set_uniform

        st = self.state
        mode = view_mode(st.view_mode)
        shown = st.modes_shown()
        target.viewport = rect
        if mode.layout == "single" and shown[0].display == "radiance":
            # The project's display pass, the same as `diviewer render`'s PNGs.
            self.compositor.run(images[0].texture, target, st.exposure, st.tonemap, flip_y=images[0].flip)
            return
        a, b = images[0], images[-1]
        prog = self.view_program
        target.use()
        self.ctx.enable_only(self.moderngl.NOTHING)
        a.texture.use(location=0)
        b.texture.use(location=1)
        set_uniform(prog, "u_a", 0)
        set_uniform(prog, "u_b", 1)
        set_uniform(prog, "u_kind_a", DISPLAY_KINDS[shown[0].display])
        set_uniform(prog, "u_kind_b", DISPLAY_KINDS[shown[-1].display])
        set_uniform(prog, "u_flip_a", bool(a.flip))
        set_uniform(prog, "u_flip_b", bool(b.flip))
        set_uniform(prog, "u_layout", LAYOUTS[mode.layout])
        set_uniform(prog, "u_split", float(st.split_position))
        set_uniform(prog, "u_line", 1.0 / max(rect[2], 1))
        set_uniform(prog, "u_exposure", float(st.exposure))
        set_uniform(prog, "u_tonemap", {"clamp": 0, "reinhard": 1, "aces": 2}[st.tonemap])
        set_uniform(prog, "u_depth_range", self._depth_range())
        set_uniform(prog, "u_diff_gain", float(2.0 ** st.diff_gain_ev))
        self.view_vao.render(self.moderngl.TRIANGLES, vertices=3)

    def _timed(self, name: str, fn: Callable[[], Any]) -> Any:
        if self.settings.timing:
            self.ctx.finish()
        t0 = time.perf_counter()
        out = fn()
        if self.settings.timing:
            self.ctx.finish()
        self.stage_times[name] = self.stage_times.get(name, 0.0) + (time.perf_counter() - t0) * 1e3
        return out

    def frame(self) -> bool:
        """Poll events, advance, render and present one frame; False when the window should close."""
        glfw, imgui, st = self.glfw, self.imgui, self.state
        start = time.perf_counter()
        dt = min(start - self._last_frame_start, 0.25) if self._last_frame_start is not None else 1.0 / 60.0
        frame_ms = (start - self._last_frame_start) * 1e3 if self._last_frame_start is not None else 0.0
        self._last_frame_start = start
        glfw.poll_events()
        if glfw.window_should_close(self.window):
            return False
        fb_w, fb_h = glfw.get_framebuffer_size(self.window)
        if fb_w <= 0 or fb_h <= 0:  # minimised
            glfw.wait_events_timeout(0.05)
            return True
        if self._pending_model is not None:
            spec, self._pending_model = self._pending_model, None
            self.set_model(spec)
        self._held_keys(dt)
        st.step(dt)
        self._sync_scene()
        if self.neural is None and (self.renderer.width, self.renderer.height) != (fb_w, fb_h):
            self.renderer.resize(fb_w, fb_h)
        self.stage_times = {}
        self.renderer.timing = self.settings.timing
        self.renderer.render(st.config)
        self.stage_times.update(self.renderer.timings)
        uses_reference = any(m.name == "reference" for m in st.modes_shown())
        if not uses_reference:
            self.reference.pause()
        sources = _Sources(self)
        screen = self.ctx.screen
        screen.viewport = (0, 0, fb_w, fb_h)
        screen.use()
        screen.clear(*BACKGROUND, 1.0, viewport=(0, 0, fb_w, fb_h))
        rect = self.view_rect()
        images, notes = self._images(sources)
        self._timed("composite", lambda: self._draw_view(screen, rect, images))
        screen.viewport = (0, 0, fb_w, fb_h)
        screen.use()
        t0 = time.perf_counter()
        self.gui.new_frame()
        if st.show_panel:
            self._panel()
        self._overlay(rect, notes, fb_h)
        imgui.render()
        self.imgui_renderer.render(imgui.get_draw_data())
        self.stage_times["panel"] = (time.perf_counter() - t0) * 1e3
        while self._pending_window_shots:
            self._save_window(self._pending_window_shots.pop(0), rect, images)
        while self._pending_shots:
            self._save_screenshot(self._pending_shots.pop(0), images)
        glfw.swap_buffers(self.window)
        st.stats.record(frame_ms or (time.perf_counter() - start) * 1e3, self.stage_times, now=start)
        self.frame_index += 1
        return True

    def _overlay(self, rect, notes: list[str], fb_h: int) -> None:
        """Text at the image's bottom right, behind the panel: why an image is missing, what a split shows."""
        imgui, st = self.imgui, self.state
        w, h = self.glfw.get_window_size(self.window)
        fb_w, _ = self.glfw.get_framebuffer_size(self.window)
        sx = w / fb_w if fb_w else 1.0
        sy = h / fb_h if fb_h else 1.0
        right, bottom = (rect[0] + rect[2]) * sx, (fb_h - rect[1]) * sy
        mode = view_mode(st.view_mode)
        lines = list(notes)
        if mode.layout == "split":
            lines.insert(0, f"A: {view_mode(st.compare[0]).label}  |  B: {view_mode(st.compare[1]).label}")
        elif mode.layout == "difference":
            lines.insert(0, f"|{view_mode(st.compare[0]).label} - {view_mode(st.compare[1]).label}| "
                            f"x{2.0 ** st.diff_gain_ev:g}")
        if any(m.name == "reference" for m in st.modes_shown()) and self.reference.latest() is not None:
            lines.append(f"reference: {self.reference.status()}")
        if not lines:
            return
        dl = imgui.get_background_draw_list()  # under the panel, over the image
        white = imgui.get_color_u32(imgui.ImVec4(1.0, 1.0, 1.0, 1.0))
        shade = imgui.get_color_u32(imgui.ImVec4(0.0, 0.0, 0.0, 0.6))
        step = imgui.get_text_line_height_with_spacing()
        y = bottom - 6.0 - step * len(lines)
        for line in lines:
            tw = imgui.calc_text_size(line).x
            x = max(right - 8.0 - tw, rect[0] * sx + 4.0)
            dl.add_rect_filled(imgui.ImVec2(x - 3.0, y - 1.0), imgui.ImVec2(x + tw + 3.0, y + step - 1.0), shade)
            dl.add_text(imgui.ImVec2(x, y), white, line)
            y += step

    # --- the panel ---------------------------------------------------------------------------------
    PANEL_WIDTH = 390

    def _panel(self) -> None:
        imgui, st = self.imgui, self.state
        _, h = self.glfw.get_window_size(self.window)
        imgui.set_next_window_pos(imgui.ImVec2(8, 8), imgui.Cond_.first_use_ever)
        imgui.set_next_window_size(imgui.ImVec2(self.PANEL_WIDTH, max(min(h - 16, 720), 60)),
                                   imgui.Cond_.first_use_ever)
        imgui.set_next_window_bg_alpha(0.85)
        expanded, _ = imgui.begin("diviewer", None)
        if expanded:
            imgui.push_item_width(-150)
            gw, gh = self.gi_size
            imgui.text(f"{st.scene.name}   GI {gw}x{gh}   {st.stats.fps:5.1f} fps")
            if self.model is not None:
                imgui.text(f"neural GI: {st.model_name} ({st.provider.replace('ExecutionProvider', '')})")
            else:
                self._wrapped(f"no neural GI: {st.model_message}", WARN)
            if st.message:
                self._wrapped(st.message, DIM)
            for name, fn in (("View", self._panel_view), ("Lights", self._panel_lights),
                             ("Camera", self._panel_camera), ("Objects", self._panel_objects),
                             ("Model", self._panel_model), ("Stats", self._panel_stats),
                             ("Screenshot", self._panel_screenshot), ("Shortcuts", self._panel_shortcuts)):
                flags = imgui.TreeNodeFlags_.default_open if name in ("View", "Lights", "Stats") else 0
                if imgui.collapsing_header(name, flags):
                    imgui.push_id(name)
                    try:
                        fn()
                    except DiviewerError as exc:
                        st.message = str(exc)
                    imgui.pop_id()
            imgui.pop_item_width()
        imgui.end()

    def _wrapped(self, text: str, color=None) -> None:
        """Text wrapped at the panel's edge, optionally coloured."""
        imgui = self.imgui
        imgui.push_text_wrap_pos(0.0)
        if color is None:
            imgui.text(text)
        else:
            imgui.text_colored(imgui.ImVec4(*color), text)
        imgui.pop_text_wrap_pos()

    def _combo(self, label: str, current: str, items: list[tuple[str, str]]) -> str | None:
        """A combo over (value, text) pairs; returns the chosen value when it changed."""
        imgui = self.imgui
        chosen = None
        text = dict(items).get(current, current)
        if imgui.begin_combo(label, text):
            for value, item_text in items:
                clicked, _ = imgui.selectable(item_text, value == current)
                if clicked and value != current:
                    chosen = value
            imgui.end_combo()
        return chosen

    def _panel_view(self) -> None:
        imgui, st = self.imgui, self.state
        modes = [(m.name, f"{m.key}  {m.label}") for m in VIEW_MODES]
        chosen = self._combo("mode", st.view_mode, modes)
        if chosen:
            st.set_view_mode(chosen)
        mode = view_mode(st.view_mode)
        if mode.help:
            self._wrapped(mode.help, DIM)
        if mode.layout != "single":
            singles = [(m.name, m.label) for m in single_modes()]
            a = self._combo("A", st.compare[0], singles)
            b = self._combo("B", st.compare[1], singles)
            if a or b:
                st.set_compare(a or st.compare[0], b or st.compare[1])
            if mode.layout == "split":
                _, st.split_position = imgui.slider_float("divider", st.split_position, 0.0, 1.0)
            else:
                _, st.diff_gain_ev = imgui.slider_float("gain (stops)", st.diff_gain_ev, 0.0, 8.0, "%.1f")
        changed, ev = imgui.slider_float("exposure (EV)", st.exposure, -8.0, 8.0, "%.1f")
        if changed:
            st.set_exposure(ev)
        chosen = self._combo("tone map", st.tonemap, [(t, t) for t in TONEMAPS])
        if chosen:
            st.set_tonemap(chosen)
        for name, why in self.unavailable.items():
            if name != "reference" and any(m.name == name for m in st.modes_shown()):
                self._wrapped(f"{view_mode(name).label}: {why}", WARN)
        if any(m.name == "reference" for m in st.modes_shown()):
            self._wrapped(f"reference: {self.reference.status()}", None if self.reference.available else WARN)

    def _panel_lights(self) -> None:
        from diviewer.scene.model import DirectionalLight

        imgui, st = self.imgui, self.state
        if not st.config.lights:
            imgui.text_disabled("this scene has no lights")
            return
        if len(st.config.lights) > 1:
            chosen = self._combo("light", st.selected_light, [(l.name, l.name) for l in st.config.lights])
            if chosen:
                st.selected_light = chosen
        light = st.light()
        az, el = st.light_angles()
        c1, az2 = imgui.slider_float("azimuth", az, -180.0, 180.0, "%.1f deg")
        c2, el2 = imgui.slider_float("elevation", el, -89.0, 89.0, "%.1f deg")
        if c1 or c2:
            st.set_light_direction(az2, el2)
        ev = st.light_intensity_ev()
        field_name = "irradiance" if isinstance(light, DirectionalLight) else "intensity"
        value = getattr(light, field_name)
        changed, ev2 = imgui.slider_float("intensity (stops)", ev if math.isfinite(ev) else -10.0, -10.0, 6.0,
                                          f"%+.2f  ({field_name} {value:.3g})")
        if changed:
            st.set_light_intensity(ev2)
        changed, col = imgui.color_edit3("colour", list(light.color))
        if changed:
            st.set_light_color(col)
        if not isinstance(light, DirectionalLight):
            changed, pos = imgui.drag_float3("position", list(light.position), 0.01)
            if changed:
                st.set_light_position(pos)
        changed, on = imgui.checkbox("animate (L)", st.animate_light)
        if changed:
            st.toggle_animation()
        r = st.scene.ranges.lights.get(light.name)
        if r is not None:
            self._wrapped(f"trained range: {r.angle[0]:g}..{r.angle[1]:g} deg about {tuple(r.axis)}, "
                          f"x{r.intensity[0]:g}..{r.intensity[1]:g}", DIM)

    def _panel_camera(self) -> None:
        imgui, st = self.imgui, self.state
        c = st.controller
        if imgui.radio_button("fly", c.kind == "fly"):
            st.set_controller("fly")
        imgui.same_line()
        if imgui.radio_button("orbit", c.kind == "orbit"):
            st.set_controller("orbit")
        imgui.same_line()
        if imgui.button("reset (R)"):
            st.reset_camera()
        changed, fov = imgui.slider_float("fov", st.config.camera.fov, 5.0, 150.0, "%.1f deg")
        if changed:
            st.set_fov(fov)
        if c.kind == "fly":
            changed, speed = imgui.slider_float("speed", c.speed, 0.01, 100.0, "%.2f m/s",
                                                imgui.SliderFlags_.logarithmic)
            if changed:
                c.speed = speed
        else:
            changed, dist = imgui.slider_float("distance", c.distance, 0.05, 100.0, "%.2f m",
                                               imgui.SliderFlags_.logarithmic)
            if changed:
                c.distance = dist
                st._sync_camera()
        if st.scene.ranges.camera is not None:
            changed, _ = imgui.checkbox("play camera path (P)", st.play_path)
            if changed:
                st.toggle_path()
        p, t = st.config.camera.position, st.config.camera.target
        self._wrapped(f"position ({p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f})  "
                      f"target ({t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f})", DIM)

    def _panel_objects(self) -> None:
        imgui, st = self.imgui, self.state
        if imgui.begin_list_box("##objects", imgui.ImVec2(-1, min(6, len(st.config.objects)) * 19 + 6)):
            for o in st.config.objects:
                clicked, _ = imgui.selectable(f"{o.name}  ({o.mesh})", o.name == st.selected)
                if clicked:
                    st.select_object(o.name)
            imgui.end_list_box()
        imgui.text_disabled("click an object in the view to select it")
        if st.selected is None:
            return
        o = st.object(st.selected)
        changed, v = imgui.drag_float3("position", list(o.position), 0.01)
        if changed:
            st.move_object(o.name, v)
        changed, v = imgui.drag_float3("rotation", list(o.rotation), 0.5)
        if changed:
            st.rotate_object(o.name, v)
        changed, v = imgui.drag_float3("scale", list(o.scale), 0.01, 0.01, 100.0)
        if changed:
            st.scale_object(o.name, [max(x, 0.01) if x >= 0 else min(x, -0.01) for x in v])
        r = st.scene.ranges.objects.get(o.name)
        train = set(r.train_meshes) if r else set()
        test = set(r.test_meshes) if r else set()

        def tag(k: str) -> str:
            if k in train:
                return " (trained)"
            return " (held out)" if k in test else " (file)" if k in st.user_meshes else ""

        chosen = self._combo("mesh", o.mesh, [(k, k + tag(k)) for k in st.scene.meshes])
        if chosen:
            st.swap_mesh(o.name, chosen)
        _, self._mesh_path = imgui.input_text("mesh file", getattr(self, "_mesh_path", ""))
        imgui.same_line()
        if imgui.button("load"):
            key = st.load_mesh(self._mesh_path, o.name)
            st.message = f"loaded {self._mesh_path} as mesh '{key}'"
        if imgui.button("reset object"):
            st.reset_object(o.name)
        imgui.same_line()
        if imgui.button("deselect"):
            st.select_object(None)

    def _panel_model(self) -> None:
        imgui, st = self.imgui, self.state
        items = [("none", "none (direct light only)")] + [(str(p), p.name) for p in self.candidates]
        current = str(self.model.path) if self.model is not None else "none"
        if current not in dict(items):
            items.append((current, self.model.path.name))
        chosen = self._combo("model", current, items)
        if chosen:
            self._pending_model = chosen  # at the next frame's start: this frame's images are in use
        if not self.candidates:
            imgui.text_disabled(f"no assets/models/{st.scene.name}*.onnx")
        if self.model is not None and st.model_meta:
            imgui.text(f"provider: {st.provider}")
            if imgui.begin_table("meta", 2, imgui.TableFlags_.borders_inner_v):
                for k, v in meta_lines(st.model_meta):
                    imgui.table_next_row()
                    imgui.table_next_column()
                    imgui.text(k)
                    imgui.table_next_column()
                    imgui.text(v)
                imgui.end_table()
        elif st.model_message:
            self._wrapped(st.model_message, WARN)

    def _panel_stats(self) -> None:
        imgui, st = self.imgui, self.state
        s = st.stats
        imgui.text(f"frame {s.mean('frame'):6.2f} ms  ({s.fps:.1f} fps, vsync {'on' if self.vsync else 'off'})")
        series = s.series("frame")
        if len(series) > 1:
            imgui.plot_lines("##frame", series, overlay_text="frame ms (last 5 s)", scale_min=0.0,
                             graph_size=imgui.ImVec2(-1, 50))
        if imgui.begin_table("stages", 3, imgui.TableFlags_.borders_inner_v):
            last = s.last()
            for name in STAGES + ("panel",):
                if name not in last and s.mean(name) == 0.0:
                    continue
                imgui.table_next_row()
                imgui.table_next_column()
                imgui.text(name)
                imgui.table_next_column()
                imgui.text(f"{last.get(name, 0.0):7.2f} ms")
                imgui.table_next_column()
                imgui.text(f"mean {s.mean(name):7.2f}")
            imgui.end_table()
        inf = s.series("inference")
        if self.model is not None and len(inf) > 1:
            imgui.plot_lines("##inference", inf, overlay_text="inference ms", scale_min=0.0,
                             graph_size=imgui.ImVec2(-1, 40))
        imgui.text_disabled(f"provider: {st.provider or '-'}")
        self._wrapped(f"GL: {self.gl_renderer}", DIM)
        changed, on = imgui.checkbox("per-stage timing (syncs the GPU)", self.settings.timing)
        if changed:
            self.settings = dataclasses.replace(self.settings, timing=on)
        changed, on = imgui.checkbox("vsync (V)", self.vsync)
        if changed:
            self.set_vsync(on)

    def _panel_screenshot(self) -> None:
        imgui = self.imgui
        _, self.shot_path = imgui.input_text("file", self.shot_path)
        if imgui.button("save (F12)"):
            self.screenshot(self.shot_path)
        self._wrapped("PNG of the view + the frame's JSON (diviewer render --config reads it)", DIM)

    def _panel_shortcuts(self) -> None:
        imgui = self.imgui
        if imgui.begin_table("keys", 2, imgui.TableFlags_.borders_inner_v):
            for k, what in SHORTCUTS:
                imgui.table_next_row()
                imgui.table_next_column()
                imgui.text(k)
                imgui.table_next_column()
                imgui.push_text_wrap_pos(0.0)
                imgui.text(what)
                imgui.pop_text_wrap_pos()
            imgui.end_table()

    # --- scripts and shutdown ----------------------------------------------------------------------
    SCRIPT_ACTIONS = ("resize", "screenshot", "window_screenshot", "set_model", "set_vsync", "pick_window_point")

    def apply(self, action) -> None:
        """Apply one script action: a callable(viewer), or (name, kwargs) naming a Viewer action
        (resize, screenshot, window_screenshot, set_model, set_vsync, pick_window_point) or a ViewerState method."""
        if callable(action):
            action(self)
            return
        if isinstance(action, dict):
            action = dict(action)
            name, kwargs = action.pop("action"), action
        else:
            name, kwargs = action[0], (action[1] if len(action) > 1 else {})
        target = self if name in self.SCRIPT_ACTIONS else self.state
        fn = getattr(target, name, None)
        if fn is None or name.startswith("_"):
            raise DiviewerError(f"unknown viewer action '{name}'", field="script")
        fn(**kwargs)

    def close(self) -> None:
        """Release everything: the reference thread, the model, GL objects, imgui, the window, GLFW."""
        if self._closed:
            return
        self._closed = True
        glfw = self.glfw
        self.reference.close()
        try:
            self._drop_model()
            self._release_shot_fbo()
            if self._ref_texture is not None:
                self._ref_texture.release()
            self.gui.release()
            self.imgui_renderer.release()
            self.imgui.destroy_context(self.imgui_ctx)
            self.view_vao.release()
            self.black.release()
            self.compositor.release()
            self.renderer.release()
            self.shaders.release()
            self.ctx.release()
        finally:
            glfw.destroy_window(self.window)
            glfw.terminate()


def _open_window(glfw, settings: ViewerSettings):
    """A resizable window with an OpenGL 4.3 core, forward-compatible context, made current."""
    if not glfw.init():
        raise DiviewerError("cannot initialise GLFW: no display? Set DISPLAY, or run under Xvfb "
                            "(Xvfb :99 & export DISPLAY=:99)")
    glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 4)
    glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
    glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
    glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
    glfw.window_hint(glfw.RESIZABLE, True)
    glfw.window_hint(glfw.SCALE_TO_MONITOR, True)
    w, h = settings.size
    try:
        window = glfw.create_window(int(w), int(h), settings.title, None, None)
    except glfw.GLFWError as exc:
        window, why = None, str(exc)
    else:
        why = "the driver offers no OpenGL 4.3 core context"
    if not window:
        glfw.terminate()
        raise DiviewerError(f"cannot open a {w}x{h} window with OpenGL 4.3: {why}")
    glfw.make_context_current(window)
    glfw.swap_interval(1 if settings.vsync else 0)
    return window


def _normalise_script(script) -> dict[int, list]:
    """Script items (frame, action) / (frame, name, kwargs) / {"frame": i, "action": name, ...} by frame."""
    out: dict[int, list] = {}
    for item in script or ():
        if isinstance(item, dict):
            item = dict(item)
            frame = int(item.pop("frame"))
            out.setdefault(frame, []).append(item)
        elif len(item) == 2:
            out.setdefault(int(item[0]), []).append(item[1])
        else:
            out.setdefault(int(item[0]), []).append((item[1], item[2] if len(item) > 2 else {}))
    return out


def run_viewer(scene: str | Path | Scene = "cornell", model: str | Path | None = None, frames: int | None = None,
               screenshot: str | Path | None = None, script=None, size: tuple[int, int] = (768, 768),
               vsync: bool = True, provider: str | None = None, settings: ViewerSettings | None = None) -> dict:
    """Open the viewer on a scene and run it until the window closes, or for ``frames`` frames.

    Args:
        scene: a shipped scene name, a .toml path or a loaded Scene.
        model: a model path, ``"auto"`` (None means the same) or ``"none"``.
        frames: render this many frames, then exit (scripted mode).
        screenshot: save the last frame's view (PNG + frame JSON) here on exit.
        size, vsync, provider: window size, vsync and execution provider, when ``settings`` is not given.
        settings: everything else (render settings, the reference's, the camera controller).
        script: actions applied before given frames: ``(frame, callable(viewer))``,
            ``(frame, name, kwargs)`` or ``{"frame": i, "action": name, **kwargs}``; names are Viewer
            actions (resize, screenshot, window_screenshot, set_model, set_vsync, pick_window_point) or
            ViewerState methods (set_view_mode, set_light_direction, fly, drag, ...).

    Returns:
        A summary: frames drawn, GI size, model, screenshots, view modes drawn, the reasons of those
        that could not be, mean stage times, and the GL error state before shutdown.
    """
    from diviewer.scene import load_scene

    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    settings = settings or ViewerSettings(size=(int(size[0]), int(size[1])), vsync=vsync)
    changes = {"model": str(model)} if model is not None else {}
    if provider is not None:
        changes["provider"] = provider
    settings = dataclasses.replace(settings, **changes)
    if settings.provider:
        import onnxruntime as ort

        from diviewer.runtime import choose_providers

        choose_providers(ort.get_available_providers(), settings.provider)  # before a window opens
    steps = _normalise_script(script)
    viewer = Viewer(scene, settings)
    summary: dict = {}
    try:
        while frames is None or viewer.frame_index < frames:
            for action in steps.get(viewer.frame_index, ()):
                viewer.apply(action)
            if not viewer.frame():
                break
        if screenshot is not None:
            if viewer.frame_index == 0:
                viewer.frame()
            # The state is the last frame's: save its view now.
            viewer._save_screenshot(Path(screenshot).with_suffix(".png"), viewer._images(_Sources(viewer))[0])
        st = viewer.state
        summary = {
            "frames": viewer.frame_index,
            "gi_size": viewer.gi_size,
            "window_size": tuple(viewer.glfw.get_window_size(viewer.window)),
            "model": st.model_name,
            "model_message": st.model_message,
            "provider": st.provider,
            "screenshots": [str(p) for p in viewer.screenshots],
            "modes_drawn": sorted(viewer.modes_drawn),
            "unavailable": dict(viewer.unavailable),
            "stages_ms": {k: st.stats.mean(k) for k in ("frame",) + STAGES + ("panel",)},
            "config": st.config,
            "gl_error": viewer.ctx.error,
            "gl_renderer": viewer.gl_renderer,
        }
    finally:
        viewer.close()
    return summary


# --- command line ---------------------------------------------------------------------------------

def add_view_parser(subparsers) -> argparse.ArgumentParser:
    """Define ``diviewer view`` on the CLI's subparsers."""
    p = subparsers.add_parser("view", help="fly through a scene with neural GI every frame (window + panel)",
                              description="Open a window on a scene with its neural GI model; "
                                          "the panel lists the keyboard shortcuts.")
    p.add_argument("--scene", default="cornell", help="shipped scene name (cornell, atrium) or a .toml path")
    p.add_argument("--model", default="auto",
                   help="model file, 'auto' (assets/models/<scene>*.onnx, the first that fits) or 'none'")
    p.add_argument("--size", default="768x768", help="window size WxH (or N); default 768x768")
    p.add_argument("--no-vsync", action="store_true", help="do not wait for the display's refresh")
    p.add_argument("--frames", type=int, default=None, help="render N frames, then exit (with --screenshot)")
    p.add_argument("--screenshot", type=Path, default=None, help="on exit, save the view as PNG (+ frame JSON)")
    p.add_argument("--provider", default=None, choices=("cpu", "cuda", "tensorrt"),
                   help="onnxruntime execution provider (default: the fastest available)")
    p.add_argument("--camera", default="fly", choices=("fly", "orbit"), help="camera controller at start")
    p.set_defaults(func=run_view)
    return p


def run_view(args: argparse.Namespace) -> int:
    from diviewer.render import parse_resolution

    if args.frames is not None and args.frames < 1:
        raise DiviewerError(f"--frames must be at least 1, got {args.frames}", field="--frames")
    size = parse_resolution(args.size, "--size")
    if args.frames is not None and str(args.model).lower() not in ("auto", "none"):
        # Scripted mode: a model the user named and the viewer refuses is a user error (exit 2),
        # found before a window opens; interactively the panel says why and offers the others.
        from diviewer.scene import load_scene

        model, message = open_model(args.model, load_scene(args.scene), args.provider)
        if model is None:
            raise DiviewerError(message, field="--model")
    settings = ViewerSettings(size=size, vsync=not args.no_vsync, model=args.model, provider=args.provider,
                              controller=args.camera)
    summary = run_viewer(args.scene, frames=args.frames, screenshot=args.screenshot, settings=settings)
    if args.frames is not None:
        gw, gh = summary["gi_size"]
        print(f"viewer: {summary['frames']} frames at GI {gw}x{gh}, "
              f"{summary['stages_ms']['frame']:.1f} ms/frame"
              + (f", saved {args.screenshot}" if args.screenshot else ""))
    return 0
