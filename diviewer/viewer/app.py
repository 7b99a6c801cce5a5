"""`diviewer view`: a GLFW window that renders a scene with neural GI every frame, with an imgui panel.

Usage::

    diviewer view --scene cornell                      # interactive, the scene's model if one is shipped
    diviewer view --frames 60 --screenshot shot.png    # scripted: 60 frames, save the last, exit

Each frame: the GL renderer draws shadows (cached while nothing moves), the G-buffer and direct light
at the shading resolution (the window's framebuffer times the render scale, which ``scale.py`` moves to
hold ``--target-fps``); the neural pass reduces them to the GI resolution (``gi_res``: the model's row
count at the window's shape, or a fraction of the shading size), runs the network (optionally one frame
behind, on a worker thread), and upsamples its indirect light over the direct light; the display pass
draws the view mode's image into the window (bilinear where it is upscaled), and the panel goes on top.
Nothing here imports torch. The rooms: window.py, input.py (key table), panel.py and panel_view.py (what it shows,
what it asks), screenshots.py, sources.py (the view modes' textures), models.py, gi.py (the neural pass, the GI
resolution), script.py, report.py (summary, stats JSON), state.py (no GL), recording.py (camera paths), scale.py
(dynamic resolution), still.py (a still view refined), meter.py (auto exposure).
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import moderngl

from diviewer.errors import DiviewerError
from diviewer.gl.display import Image, Look, depth_range
from diviewer.scene.model import Scene
from diviewer.viewer.input import Input, pick_window_point
from diviewer.viewer.models import model_candidates
from diviewer.viewer.panel_view import panel_view
from diviewer.viewer.screenshots import Screenshots, view_record
from diviewer.viewer.still import can_rest, still_key
from diviewer.viewer.settings import BACKGROUND, ViewerSettings, check_render_scale, scale_settings
from diviewer.viewer.view_modes import Unavailable, produce, view_mode

STILL_WAIT_S = 1.0 / 120.0
"""How long a still view's frame waits for an input event before presenting the same image again."""

__all__ = ["BACKGROUND", "Viewer", "ViewerSettings"]


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
        from diviewer.viewer.gi import GIControl
        from diviewer.viewer.imgui_gl import GlfwImgui, ImguiRenderer
        from diviewer.viewer.panel import Panel
        from diviewer.viewer.sources import ReferenceTexture, VXGISlot, black_texture
        from diviewer.viewer.meter import Meter
        from diviewer.viewer.scale import ScaleController, moving_map_size, render_size
        from diviewer.viewer.state import ViewerState
        from diviewer.viewer.still import StillTracker

        imgui, settings = self.imgui, self.settings
        self.ctx = create_context("window")
        self.gl_renderer = describe(self.ctx)
        self.state = ViewerState(scene, controller=settings.controller)
        self.state.show_panel = settings.panel
        self.state.begin(settings.path, settings.record_path, exact=settings.fixed_step is not None)
        self.shaders = ShaderCache(self.ctx)
        self.timer = stage_timer(self.ctx, deferred=True)  # read after the swap: timing does not stall the frame
        """One timer for every stage of a frame: renderer passes, neural pass, inference, display, panel."""
        self.set_timing(settings.timing)
        fb_w, fb_h = (max(1, s) for s in self.window.fb_size)
        self.scaler = ScaleController(scale_settings(settings))
        self.view_size = (fb_w, fb_h)
        """The window's framebuffer size the image is shown at (the renderer's is this times the scale)."""
        self.drawn_scale = self.scaler.scale  # the render scale of the frame drawn last
        self.still = StillTracker(settings.still)
        """The motion state of each frame (moving, refining, still: still.py)."""
        self._shown: tuple[list[Image], list[str]] | None = None  # the last drawn frame's images, for a still one
        self.temporal = None
        """The temporal upsampler (gl/temporal.py) with ``--temporal on``, else None."""
        if settings.temporal:
            from diviewer.gl.temporal import TemporalPass

            self.temporal = TemporalPass(self.ctx, self.shaders)
        self.renderer = r = Renderer(self.ctx, scene, *render_size(self.view_size, self.scaler.scale), settings.render,
                                     self.shaders, timer=self.timer, back_faces=settings.back_faces)
        r.moving_shadow_size = moving_map_size(settings.moving_shadow_size, (r.width, r.height))
        r.rest_in_bands = settings.rest_in_bands
        self.upscale = self.ctx.sampler(filter=(moderngl.LINEAR, moderngl.LINEAR), repeat_x=False, repeat_y=False)
        """Bound over the display's texture units where the image is upscaled to the window: bilinear."""
        self.meter = Meter(self.ctx, self.shaders)
        self.state.set_auto_exposure(scene.auto_exposure if settings.auto_exposure is None else settings.auto_exposure)
        self.display = DisplayPass(self.ctx, self.shaders)
        self.black = black_texture(self.ctx)
        self.reference_texture = ReferenceTexture(self.ctx, self.reference, settings.reference_max_size)
        self.shots = Screenshots(self.ctx)
        self._scene_revision = 0
        self.gi = GIControl(self.ctx, self.renderer, self.state, settings.gi_res, settings.gi, settings.provider)
        self.gi.view_size = self.view_size
        self.vxgi = VXGISlot(self.ctx, self.renderer, timer=self.timer)
        """Holds the VXGI pass, made the first time the VXGI view mode is shown (``sources.VXGISlot``)."""
        self.imgui_ctx = imgui.create_context()
        imgui.get_io().set_ini_filename(None)  # no imgui.ini in the user's working folder
        self.input = Input(self.state, self.window, self.shots, self.glfw)
        self.input.view_size = self.view_size
        self.gui = GlfwImgui(self.window.handle, handler=self.input)
        self.imgui_renderer = ImguiRenderer(self.ctx, self.shaders)
        self.panel = Panel(self.state)
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
    def render_size(self) -> tuple[int, int]:
        """The G-buffer's resolution (the shading resolution): the window's framebuffer times the render scale."""
        return self.renderer.width, self.renderer.height

    @property
    def render_scale(self) -> float:
        """The render scale of the frame drawn last (the controller's; each side is rounded to whole pixels)."""
        return self.drawn_scale

    @property
    def gi_size(self) -> tuple[int, int]:
        """The neural GI's resolution (the render size without a model)."""
        return self.gi.size

    @property
    def model(self):
        """The loaded ``runtime.NeuralGI``, or None."""
        return self.gi.model

    @property
    def neural(self):
        """The ``gl.neural.NeuralPass`` of the model, or None."""
        return self.gi.neural

    def _sync_scene(self) -> None:
        """Upload meshes and textures added to the scene (a mesh file loaded from the panel)."""
        if self.state.scene_revision != self._scene_revision:
            self.renderer.gpu.sync(self.ctx, self.state.scene)
            self.renderer.scene = self.state.scene
            self._scene_revision = self.state.scene_revision

    # --- actions (the panel's, the keys', scripts': script.SCRIPT_ACTIONS) ----------------------------
    def set_model(self, spec: str | Path | None) -> None:
        """Load a model (path, ``auto`` or ``none``); without one the viewer shows direct light and says why."""
        self.gi.release()
        self._shown = None
        self._follow_window()
        self.gi.load(spec)

    def _follow_window(self, scale: float | None = None) -> None:
        """Size the renderer to the window's framebuffer times ``scale`` (default: the controller's; the GI
        follows)."""
        from diviewer.viewer.scale import moving_map_size, render_size

        fb_w, fb_h = self.window.fb_size
        if fb_w <= 0 or fb_h <= 0:
            return
        scale = self.scaler.scale if scale is None else scale
        want = render_size((fb_w, fb_h), scale)
        if want != self.render_size or (fb_w, fb_h) != self.view_size:
            self.view_size = self.input.view_size = (fb_w, fb_h)
            self.renderer.resize(*want)
            self.gi.follow_window(self.view_size)
            self._shown = None
            self.renderer.moving_shadow_size = moving_map_size(self.settings.moving_shadow_size, want)
        self.drawn_scale = scale

    def _temporal_on(self, phase: str) -> bool:
        """Whether this frame goes through the temporal upsampler: the final view mode, while moving (a still
        view is refined at full scale instead), or at a fixed render scale (it then refines the still view)."""
        on = self.temporal is not None and self.state.view_mode == "final"
        on = on and (phase == "moving" or not self.scaler.enabled)
        self.renderer.jitter = self.temporal.jitter(self.render_size[0] / self.view_size[0]) if on else (0.0, 0.0)
        self.renderer.motion_vectors = on
        if not on and self.temporal is not None:
            self.temporal.reset()
        return on

    def set_render_scale(self, scale: float) -> float:
        """Fix the render scale (0 < scale <= 2, above 1 supersampled; dynamic resolution turns off); applied at
        the next frame."""
        return self.scaler.fix(check_render_scale(scale))

    def set_target_fps(self, fps: float) -> float:
        """Hold ``fps`` by moving the render scale from the current one (0: keep the current scale)."""
        return self.scaler.hold(fps)

    def request_model(self, spec: str) -> None:
        """Switch models at the next frame's start (this frame's images are in use)."""
        self._pending_model = spec

    def set_gi_res(self, spec: str) -> tuple[int, int]:
        """Run the network at another GI resolution (``model``, ``1/4``, ``WxH``); refused sizes change nothing."""
        return self.gi.set_gi_res(spec)

    def set_pipelined(self, on: bool) -> None:
        """Run inference one frame behind on a worker thread, or in the frame."""
        self.gi.set_pipelined(on)

    def set_timing(self, on: bool) -> None:
        """Time GL stages (by timer queries, or a GPU sync where the driver has none), or not at all."""
        from diviewer.gl.context import set_stage_timing

        set_stage_timing(self.timer, self.ctx, on)

    def set_vsync(self, on: bool) -> None:
        self.window.set_vsync(on)

    def resize(self, width: int, height: int) -> None:
        """Resize the window (screen units); the framebuffer follows on the next event poll."""
        self.window.resize(width, height)

    def view_rect(self) -> tuple[int, int, int, int]:
        """Where the image is drawn in the framebuffer: (x, y, w, h), y from the bottom; all of it (letterboxed
        only if the framebuffer's size changed since the frame started)."""
        return self.window.view_rect(self.view_size)

    def pick_window_point(self, x: float, y: float) -> str | None:
        """Select the object under window point (x, y) (screen units, y down)."""
        return pick_window_point(self.state, self.window, x, y, self.view_size)

    def screenshot(self, path: str | Path) -> Path:
        """Save the view (without the panel) at the window's resolution (upscaled from the shading resolution)
        as PNG, and the frame as JSON, at the end of the next frame (so image and configuration agree)."""
        return self.shots.request(path)

    def window_screenshot(self, path: str | Path) -> Path:
        """Save what the window shows (with the panel), read back from its framebuffer before the swap."""
        return self.shots.request_window(path)

    # --- drawing -----------------------------------------------------------------------------------
    def _sources(self):
        """This frame's ``sources.FrameImages``: what the view modes draw from."""
        from diviewer.viewer.sources import FrameImages

        return FrameImages(self.renderer, self.neural, self.state, self.reference_texture, self.render_size, self.vxgi)

    def _images(self, sources) -> tuple[list[Image], list[str]]:
        """The images the current view mode shows (running the neural pass if one needs it), and the
        reasons of those that cannot be produced (shown as black)."""
        images, notes = [], []
        for m in self.state.modes_shown():
            try:
                img = produce(m, sources)
                images.append(Image(img.texture, img.flip, m.display))
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
        upscaled = tuple(rect[2:]) != self.render_size
        if upscaled:  # the G-buffer's textures filter nearest; shown larger than drawn they are filtered bilinearly
            self.upscale.use(location=0)
            self.upscale.use(location=1)
        self.display.show(target, rect, images[0], images[-1], view_mode(st.view_mode).layout, look)
        if upscaled:
            self.upscale.clear(location=0)
            self.upscale.clear(location=1)

    def _save_view(self, path: Path, images: list[Image]) -> Path:
        st, size = self.state, self.view_size
        record = view_record(st, size, self.model.path if self.model is not None else None, self.gl_renderer,
                             gi_size=self.gi_size if self.neural is not None else None,
                             gi_settings=dataclasses.asdict(self.gi.settings) if self.neural is not None else None,
                             render_size=list(self.render_size), render_scale=self.render_scale,
                             out_of_range=st.out_of_range())
        self._draw_view(self.shots.target(size), (0, 0, *size), images)
        self.shots.save_view(path, record)
        st.message = f"saved {path} and {path.with_suffix('.json').name}"
        return path

    def frame(self) -> bool:
        """Poll events, advance, render and present one frame; False when the window should close."""
        glfw, st = self.glfw, self.state
        start = time.perf_counter()
        dt = self.settings.fixed_step or (min(start - self._last_frame_start, 0.25)
                                          if self._last_frame_start is not None else 1.0 / 60.0)
        frame_ms = (start - self._last_frame_start) * 1e3 if self._last_frame_start is not None else 0.0
        self._last_frame_start = start
        if self.still.state == "still":
            glfw.wait_events_timeout(STILL_WAIT_S)  # nothing to draw: wait for an event (or the next frame)
        else:
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
        last = self.still.state
        if frame_ms > 0 and last == "moving":  # refined frames' times would pull the dynamic scale down
            self.scaler.update(frame_ms, self.drawn_scale)  # the last frame's time, at the scale it was drawn at
        phase = self.still.update(still_key(self), can_rest(self) and self._shown is not None)
        if phase == "moving" and last != "moving":
            self.scaler.resume()  # back at its scale; the first frames there reallocate targets
        self._follow_window(self.scaler.scale if phase == "moving" else self.scaler.refined)
        self.timer.reset()
        temporal = phase != "still" and self._temporal_on(phase)
        if phase != "still":
            # The direct pass is deferred: the neural pass computes the direct light inline where it can,
            # and whatever else reads the buffer (a view mode, VXGI) runs the pass first.
            self.renderer.render(st.config, direct=False)
        if not any(m.name == "reference" for m in st.modes_shown()):
            self.reference.pause()
        screen = self.ctx.screen
        screen.viewport = (0, 0, fb_w, fb_h)
        screen.use()
        screen.clear(*BACKGROUND, 1.0, viewport=(0, 0, fb_w, fb_h))
        rect = self.view_rect()
        if phase == "still" and self._shown is not None:
            images, notes = self._shown  # the refined frame's images, unchanged since
        else:
            images, notes = self._frame_images(self._sources(), temporal, resting=phase != "moving")
            self._shown = (images, notes)
        if st.auto_exposure and images[0].kind == "radiance":
            st.meter(self.meter.read(images[0].texture))
        self._present(screen, (fb_w, fb_h), rect, images, notes)
        st.stats.record(frame_ms or (time.perf_counter() - start) * 1e3, self.timer.collect(), now=start)
        self.frame_index += 1
        return True

    def _frame_images(self, sources, temporal: bool, resting: bool) -> tuple[list[Image], list[str]]:
        """This frame's images (`_images`), the first resolved by the temporal upsampler where it is on."""
        images, notes = self._images(sources)
        if temporal and images[0].kind == "radiance" and not images[0].flip:
            r = self.renderer
            with self.timer.stage("temporal", gpu=True):
                images[0] = Image(self.temporal.resolve(images[0].texture, r.buffer("depth"), self.view_size,
                                                        r.jitter, r.frame_view.view, r.frame_view.proj,
                                                        resting=resting, velocity=r.velocity))
        return images, notes

    def _panel_view(self):
        """What the panel shows of the viewer this frame (``panel_view.PanelView``), once its images are drawn."""
        return panel_view(self.window, self.gi, self.scaler, self.still, self.reference, self.timer,
                          render_size=self.render_size, render_scale=self.render_scale, unavailable=self.unavailable,
                          candidates=self.candidates, gl_renderer=self.gl_renderer,
                          reference_shown=any(m.name == "reference" for m in self.state.modes_shown()))

    def _present(self, screen, fb: tuple[int, int], rect, images: list[Image], notes: list[str]) -> None:
        """The view drawn into the window, the panel over it, the screenshots asked for, and the swap."""
        st, imgui = self.state, self.imgui
        with self.timer.stage("composite", gpu=True):
            self._draw_view(screen, rect, images)
        screen.viewport = (0, 0, *fb)
        screen.use()
        with self.timer.stage("panel"):
            self.gui.new_frame()
            self.input.wants_keyboard, self.input.wants_mouse = self.gui.wants_keyboard, self.gui.wants_mouse
            view = self._panel_view()
            requests = self.panel.draw(view) if st.show_panel else []
            self.panel.overlay(rect, notes, view)
            imgui.render()
            self.imgui_renderer.render(imgui.get_draw_data())
            for name, kwargs in requests:  # the panel's, once it has drawn: named actions (script.SCRIPT_ACTIONS)
                try:
                    getattr(self, name)(**kwargs)
                except DiviewerError as exc:
                    st.message = str(exc)
        if self.shots.pending_window:
            shown = self.window.read_pixels()  # the back buffer, as the swap will show it
            screen.use()
            while self.shots.pending_window:
                self.shots.save_window(self.shots.pending_window.pop(0), shown)
        while self.shots.pending:
            self._save_view(self.shots.pending.pop(0), images)
        self.window.swap()

    # --- shutdown ---------------------------------------------------------------------------------
    def close(self) -> None:
        """Release everything: the reference thread, the model, GL objects, imgui, the window, GLFW."""
        if self._closed:
            return
        self._closed = True
        self.reference.close()
        try:
            self.gi.release()
            self.shots.release()
            self.reference_texture.release()
            self.gui.release()
            self.imgui_renderer.release()
            self.imgui.destroy_context(self.imgui_ctx)
            self.black.release()
            self.meter.release()
            self.upscale.release()
            self.display.release()
            if self.temporal is not None:
                self.temporal.release()
            self.vxgi.release()
            self.timer.release()
            self.renderer.release()
            self.shaders.release()
            self.ctx.release()
        finally:
            self.window.close()
            self.state.message = self.state.stop_recording() or self.state.message  # also when the window closes
