"""`diviewer view`: a GLFW window that renders a scene with neural GI every frame, with an imgui panel.

Usage::

    diviewer view --scene cornell                      # interactive, the scene's model if one is shipped
    diviewer view --frames 60 --screenshot shot.png    # scripted: 60 frames, save the last, exit

Each frame: the GL renderer draws the G-buffer and direct light at the GI resolution (the model's
training resolution when a model is loaded, else the window's framebuffer), the neural pass turns
them into the final image, the display pass draws the view mode's image into the window (letterboxed
to the GI aspect ratio), and the panel goes on top. Nothing here imports torch. The rooms: window.py
(size, scale, letterbox), input.py (key table), panel.py, screenshots.py, sources.py (the view modes'
textures), models.py (which model), state.py (what is shown, no GL).
"""

from __future__ import annotations

import dataclasses
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from diviewer.errors import DiviewerError
from diviewer.gl.display import Image, Look, depth_range
from diviewer.gl.renderer import RenderSettings
from diviewer.reference.progressive import ReferenceSettings
from diviewer.scene.model import Scene
from diviewer.viewer.models import model_candidates, open_model
from diviewer.viewer.stats import STAGES
from diviewer.viewer.view_modes import Unavailable, view_mode

BACKGROUND = (0.08, 0.08, 0.09)
"""Colour of the bars around the GI image when the window's aspect ratio differs."""


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


class Viewer:
    """The window, its GL resources and the frame loop. ``run_viewer`` is the usual entry point."""

    def __init__(self, scene: Scene, settings: ViewerSettings = ViewerSettings()):
        from imgui_bundle import imgui

        from diviewer.reference.progressive import ProgressiveReference
        from diviewer.viewer.window import Window

        self.imgui = imgui
        self.settings = settings
        self._closed = False
        self.window = Window(settings.size, settings.title, settings.vsync)
        self.glfw = self.window.glfw
        self.imgui_ctx = None
        self.reference = ProgressiveReference(settings.reference)
        try:
            self._setup(scene)
        except BaseException:
            # GL objects die with the window's context; the rest is released here.
            self.reference.close()
            if self.imgui_ctx is not None:
                imgui.destroy_context(self.imgui_ctx)
            self.window.close()
            raise

    def _setup(self, scene: Scene) -> None:
        """Everything that needs the window's GL context: renderer, display pass, imgui, the model."""
        from diviewer.gl.context import create_context, describe, stage_timer
        from diviewer.gl.display import DisplayPass
        from diviewer.gl.renderer import Renderer
        from diviewer.gl.shaders import ShaderCache
        from diviewer.viewer.imgui_gl import GlfwImgui, ImguiRenderer
        from diviewer.viewer.input import Input
        from diviewer.viewer.panel import Panel
        from diviewer.viewer.screenshots import Screenshots
        from diviewer.viewer.sources import ReferenceTexture, black_texture
        from diviewer.viewer.state import ViewerState

        imgui, settings = self.imgui, self.settings
        self.ctx = create_context("window")
        self.gl_renderer = describe(self.ctx)
        self.state = ViewerState(scene, controller=settings.controller)
        self.state.show_panel = settings.panel
        self.shaders = ShaderCache(self.ctx)
        self.timer = stage_timer(self.ctx, sync=settings.timing)
        """One timer for every stage of a frame: renderer passes, neural pass, inference, display, panel."""
        fb_w, fb_h = (max(1, s) for s in self.window.fb_size)
        self.renderer = Renderer(self.ctx, scene, fb_w, fb_h, settings.render, self.shaders, timer=self.timer)
        self.display = DisplayPass(self.ctx, self.shaders)
        self.black = black_texture(self.ctx)
        self.reference_texture = ReferenceTexture(self.ctx, self.reference, settings.reference_max_size)
        self.shots = Screenshots(self.ctx)
        self.shot_path = f"diviewer_{scene.name}.png"
        self._scene_revision = 0
        self.model = None
        self.neural = None
        self.vxgi = None
        """The VXGI pass, made the first time the VXGI view mode is shown."""
        self.imgui_ctx = imgui.create_context()
        imgui.get_io().set_ini_filename(None)  # no imgui.ini in the user's working folder
        self.input = Input(self.state, self, self.glfw)
        self.gui = GlfwImgui(self.window.handle, handler=self.input)
        self.imgui_renderer = ImguiRenderer(self.ctx, self.shaders)
        self.panel = Panel(self.state, self)
        s = self.window.ui_scale()
        if s > 1.05:  # a HiDPI screen whose framebuffer is not already larger than the window
            style = imgui.get_style()
            style.scale_all_sizes(s)
            style.font_scale_dpi = s
        self.frame_index = 0
        self._last_frame_start: float | None = None
        self._pending_model: str | None = None
        self.unavailable: dict[str, str] = {}
        self.modes_drawn: set[str] = set()
        self.candidates = model_candidates(scene)
        self.set_model(settings.model)

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
        fb_w, fb_h = self.window.fb_size
        if fb_w > 0 and fb_h > 0:
            self.renderer.resize(fb_w, fb_h)

    def _sync_scene(self) -> None:
        """Upload meshes and textures added to the scene (a mesh file loaded from the panel)."""
        if self.state.scene_revision != self._scene_revision:
            self.renderer.gpu.sync(self.ctx, self.state.scene)
            self.renderer.scene = self.state.scene
            self._scene_revision = self.state.scene_revision

    # --- actions (the panel's, the keys', scripts') --------------------------------------------------
    def request_model(self, spec: str) -> None:
        """Switch models at the next frame's start (this frame's images are in use)."""
        self._pending_model = spec

    @property
    def timer_sync(self) -> bool:
        return self.timer.sync is not None

    def set_timing(self, on: bool) -> None:
        """Wait for the GPU around each GL stage (honest stage times, a slower frame) or not."""
        self.timer.sync = self.ctx.finish if on else None
        self.settings = dataclasses.replace(self.settings, timing=bool(on))

    def set_vsync(self, on: bool) -> None:
        self.window.set_vsync(on)

    def resize(self, width: int, height: int) -> None:
        """Resize the window (screen units); the framebuffer follows on the next event poll."""
        self.window.resize(width, height)

    def view_rect(self) -> tuple[int, int, int, int]:
        """Where the GI image is drawn in the framebuffer: (x, y, w, h), y from the bottom."""
        return self.window.view_rect(self.gi_size)

    def pick_window_point(self, x: float, y: float) -> str | None:
        """Select the object under window point (x, y) (screen units, y down)."""
        point = self.window.to_image(x, y, self.gi_size)
        if point is None:
            return self.state.select_object(None)
        return self.state.pick(*point, *self.gi_size)

    def screenshot(self, path: str | Path) -> Path:
        """Save the view (without the panel) at the GI resolution as PNG, and the frame as JSON, at the
        end of the next frame (so image and configuration agree)."""
        return self.shots.request(path)

    def window_screenshot(self, path: str | Path) -> Path:
        """Save the whole window (with the panel) as PNG at the end of the next frame."""
        return self.shots.request_window(path)

    # --- drawing -----------------------------------------------------------------------------------
    def _images(self, sources) -> tuple[list[Image], list[str]]:
        """The images the current view mode shows (running the neural pass if one needs it), and the
        reasons of those that cannot be produced (shown as black)."""
        images, notes = [], []
        for m in self.state.modes_shown():
            try:
                images.append(sources.produce(m))
                self.modes_drawn.add(m.name)
                self.unavailable.pop(m.name, None)
            except Unavailable as exc:
                self.unavailable[m.name] = str(exc)
                images.append(Image(self.black, False, m.display))
                notes.append(f"{m.label}: {exc}")
        return images, notes

    def _draw_view(self, target, rect: tuple[int, int, int, int], images: list[Image]) -> None:
        """Draw the current view mode's images into ``rect`` of ``target``."""
        st = self.state
        look = Look(st.exposure, st.tonemap, depth_range(st.scene, st.config), st.split_position,
                    2.0 ** st.diff_gain_ev)
        self.display.show(target, rect, images[0], images[-1], view_mode(st.view_mode).layout, look)

    def _save_view(self, path: Path, images: list[Image]) -> Path:
        from diviewer.viewer.screenshots import view_record

        st, size = self.state, self.gi_size
        record = view_record(st, size, self.model.path if self.model is not None else None, self.gl_renderer)
        self.shots.save_view(path, size, lambda fbo, rect: self._draw_view(fbo, rect, images), record)
        st.message = f"saved {path} and {path.with_suffix('.json').name}"
        return path

    def frame(self) -> bool:
        """Poll events, advance, render and present one frame; False when the window should close."""
        from diviewer.viewer.sources import FrameImages

        glfw, imgui, st = self.glfw, self.imgui, self.state
        start = time.perf_counter()
        dt = min(start - self._last_frame_start, 0.25) if self._last_frame_start is not None else 1.0 / 60.0
        frame_ms = (start - self._last_frame_start) * 1e3 if self._last_frame_start is not None else 0.0
        self._last_frame_start = start
        glfw.poll_events()
        if self.window.should_close():
            return False
        fb_w, fb_h = self.window.fb_size
        if fb_w <= 0 or fb_h <= 0:  # minimised
            glfw.wait_events_timeout(0.05)
            return True
        if self._pending_model is not None:
            spec, self._pending_model = self._pending_model, None
            self.set_model(spec)
        self.input.held_keys(dt)
        st.step(dt)
        self._sync_scene()
        if self.neural is None and self.gi_size != (fb_w, fb_h):
            self.renderer.resize(fb_w, fb_h)
        self.timer.reset()
        self.renderer.render(st.config)
        if not any(m.name == "reference" for m in st.modes_shown()):
            self.reference.pause()
        screen = self.ctx.screen
        screen.viewport = (0, 0, fb_w, fb_h)
        screen.use()
        screen.clear(*BACKGROUND, 1.0, viewport=(0, 0, fb_w, fb_h))
        rect = self.view_rect()
        images, notes = self._images(FrameImages(self))
        with self.timer.stage("composite", gpu=True):
            self._draw_view(screen, rect, images)
        screen.viewport = (0, 0, fb_w, fb_h)
        screen.use()
        with self.timer.stage("panel"):
            self.gui.new_frame()
            if st.show_panel:
                self.panel.draw()
            self.panel.overlay(rect, notes)
            imgui.render()
            self.imgui_renderer.render(imgui.get_draw_data())
        while self.shots.pending_window:
            self.shots.save_window(self.shots.pending_window.pop(0), (fb_w, fb_h), BACKGROUND, rect,
                                   lambda fbo, r: self._draw_view(fbo, r, images),
                                   lambda: self.imgui_renderer.render(imgui.get_draw_data()))
        while self.shots.pending:
            self._save_view(self.shots.pending.pop(0), images)
        self.window.swap()
        st.stats.record(frame_ms or (time.perf_counter() - start) * 1e3, self.timer.times, now=start)
        self.frame_index += 1
        return True

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
        self.reference.close()
        try:
            self._drop_model()
            self.shots.release()
            self.reference_texture.release()
            self.gui.release()
            self.imgui_renderer.release()
            self.imgui.destroy_context(self.imgui_ctx)
            self.black.release()
            self.display.release()
            if self.vxgi is not None:
                self.vxgi.release()
            self.timer.release()
            self.renderer.release()
            self.shaders.release()
            self.ctx.release()
        finally:
            self.window.close()


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
    from diviewer.viewer.sources import FrameImages

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
            viewer._save_view(Path(screenshot).with_suffix(".png"), viewer._images(FrameImages(viewer))[0])
        st = viewer.state
        summary = {
            "frames": viewer.frame_index,
            "gi_size": viewer.gi_size,
            "window_size": viewer.window.size,
            "model": st.model_name,
            "model_message": st.model_message,
            "provider": st.provider,
            "screenshots": [str(p) for p in viewer.shots.saved],
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
