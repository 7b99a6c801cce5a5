"""The imgui panel: view modes, lights, camera, objects, model, stats, screenshot and shortcuts.

It reads and changes the viewer's state (a ViewerState); what it shows of the rest of the viewer comes as a
``PanelView`` (a frozen snapshot the app builds each frame), and the viewer's actions it asks for are returned as
requests (``panel_view.Request``) that the app applies after the panel has drawn. It never imports the app.
"""

from __future__ import annotations

import math
from pathlib import Path

from imgui_bundle import imgui

from diviewer.errors import DiviewerError
from diviewer.exposure import ExposureSettings
from diviewer.gl.display import TONEMAPS
from diviewer.scene.model import DirectionalLight
from diviewer.viewer.input import SHORTCUTS
from diviewer.viewer.models import meta_lines
from diviewer.viewer.panel_view import PanelView, Request
from diviewer.viewer.scale import MAX_SCALE
from diviewer.viewer.state import ViewerState
from diviewer.viewer.stats import STAGES
from diviewer.viewer.view_modes import VIEW_MODES, single_modes, view_mode

PANEL_WIDTH = 390
WARN = (1.0, 0.75, 0.3, 1.0)
DIM = (0.6, 0.6, 0.6, 1.0)
EXPOSURE_RANGE = ExposureSettings().limits
"""The exposure slider's range (stops): the auto exposure's, so a metered exposure always sits on the slider."""


def _xyz(v) -> str:
    return "(" + ", ".join(f"{x:.2f}" for x in v) + ")"


class Panel:
    """Draws the panel (``draw``) and the notes over the image (``overlay``) inside an imgui frame."""

    def __init__(self, state: ViewerState):
        self.state = state
        self._mesh_path = ""
        self.view: PanelView | None = None
        """The viewer as this frame shows it (``draw``'s)."""
        self._requests: list[Request] = []

    def _request(self, action: str, **kwargs) -> None:
        """Ask for a viewer action (one of ``script.SCRIPT_ACTIONS``), applied by the app after the panel drew."""
        self._requests.append((action, kwargs))

    def overlay(self, rect, notes: list[str], view: PanelView) -> None:
        """Text at the image's bottom right, behind the panel: why an image is missing, what a split shows."""
        st = self.state
        w, h = view.window_size
        fb_w, fb_h = view.fb_size
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
        if any(m.name == "reference" for m in st.modes_shown()) and view.reference_ready:
            lines.append(f"reference: {view.reference_status}")
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

    def draw(self, view: PanelView) -> list[Request]:
        """The panel window, its sections collapsible (View, Lights and Stats open at first); returns the viewer
        actions asked for, in order."""
        st, self.view, self._requests = self.state, view, []
        _, h = view.window_size
        imgui.set_next_window_pos(imgui.ImVec2(8, 8), imgui.Cond_.first_use_ever)
        imgui.set_next_window_size(imgui.ImVec2(PANEL_WIDTH, max(min(h - 16, 720), 60)),
                                   imgui.Cond_.first_use_ever)
        imgui.set_next_window_bg_alpha(0.85)
        expanded, _ = imgui.begin("diviewer", None)
        if expanded:
            imgui.push_item_width(-150)
            gw, gh = view.gi_size
            rw, rh = view.render_size
            imgui.text(f"{st.scene.name}  {rw}x{rh} (scale {view.render_scale:.2f})  GI {gw}x{gh}  "
                       f"{st.stats.fps:5.1f} fps  {view.motion}")
            reasons = st.out_of_range()
            if reasons:
                self._wrapped("outside what the model was trained on: " + "; ".join(reasons), WARN)
            if view.pipelined:
                imgui.text_colored(imgui.ImVec4(*DIM), f"GI one frame behind: {view.latency_ms:.1f} ms old")
            if view.model_path is not None:
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
        return self._requests

    def _wrapped(self, text: str, color=None) -> None:
        """Text wrapped at the panel's edge, optionally coloured."""
        imgui.push_text_wrap_pos(0.0)
        if color is None:
            imgui.text(text)
        else:
            imgui.text_colored(imgui.ImVec4(*color), text)
        imgui.pop_text_wrap_pos()

    def _combo(self, label: str, current: str, items: list[tuple[str, str]]) -> str | None:
        """A combo over (value, text) pairs; returns the chosen value when it changed."""
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
        st = self.state
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
        changed, ev = imgui.slider_float("exposure (EV)", st.exposure, *EXPOSURE_RANGE, "%.1f")
        if changed:
            st.set_auto_exposure(False)
            st.set_exposure(ev)
        changed, on = imgui.checkbox("auto exposure (metered)", st.auto_exposure)
        if changed:
            st.set_auto_exposure(on)
        view = self.view
        changed, fps = imgui.slider_int("target fps (0 off)", int(round(view.target_fps)), 0, 120)
        if changed:
            self._request("set_target_fps", fps=fps)
        changed, scale = imgui.slider_float("render scale", view.render_scale, 0.25, MAX_SCALE, "%.2f")
        if changed:
            self._request("set_render_scale", scale=scale)
        chosen = self._combo("tone map", st.tonemap, [(t, t) for t in TONEMAPS])
        if chosen:
            st.set_tonemap(chosen)
        for name, why in view.unavailable:
            if name != "reference" and any(m.name == name for m in st.modes_shown()):
                self._wrapped(f"{view_mode(name).label}: {why}", WARN)
        if any(m.name == "reference" for m in st.modes_shown()):
            self._wrapped(f"reference: {view.reference_status}", None if view.reference_available else WARN)

    def _panel_lights(self) -> None:
        st = self.state
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
            where = (f"in the box {tuple(r.position[0])}..{tuple(r.position[1])}" if r.position is not None
                     else f"{r.angle[0]:g}..{r.angle[1]:g} deg about {tuple(r.axis)}")
            self._wrapped(f"trained range: {where}, x{r.intensity[0]:g}..{r.intensity[1]:g}", DIM)

    def _panel_camera(self) -> None:
        st = self.state
        c = st.controller
        if imgui.radio_button("fly", c.kind == "fly"):
            st.set_controller("fly")
        imgui.same_line()
        if imgui.radio_button("orbit", c.kind == "orbit"):
            st.set_controller("orbit")
        imgui.same_line()
        if imgui.button("reset (R)"):
            st.reset_camera()
        imgui.same_line()
        if imgui.button("overview (O)"):
            st.overview_camera()
        lo, hi = st.scene_bounds()
        imgui.text(f"at {_xyz(st.config.camera.position)}; scene {_xyz(lo)} .. {_xyz(hi)}")
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
        path = st.playable_path()
        if path is not None:
            changed, _ = imgui.checkbox("play camera path (P)", st.play_path)
            if changed:
                st.toggle_path()
            imgui.same_line()
            self._wrapped(f"{Path(st.path_file).name if st.path is not None else 'the scene walk'}: "
                          f"{len(path.keys)} keys, {path.duration:.1f} s", DIM)
        if imgui.button("stop recording (Ctrl+R)" if st.recorder is not None else "record path (Ctrl+R)"):
            st.toggle_recording()
        if st.recorder is not None:
            imgui.same_line()
            self._wrapped(f"recording: {len(st.recorder.keys)} frames, {st.recorder.time:.1f} s", WARN)
        p, t = st.config.camera.position, st.config.camera.target
        self._wrapped(f"position ({p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f})  "
                      f"target ({t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f})", DIM)

    def _panel_objects(self) -> None:
        st = self.state
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
        _, self._mesh_path = imgui.input_text("mesh file", self._mesh_path)
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
        st, view = self.state, self.view
        items = [("none", "none (direct light only)")] + [(str(p), p.name) for p in view.candidates]
        current = str(view.model_path) if view.model_path is not None else "none"
        if current not in dict(items):
            items.append((current, view.model_path.name))
        chosen = self._combo("model", current, items)
        if chosen:
            self._request("request_model", spec=chosen)
        if not view.candidates:
            imgui.text_disabled(f"no assets/models/{st.scene.name}*.onnx")
        if view.model_path is not None:
            items = [(spec, f"{'training rows, window shape' if spec == 'model' else spec + ' of the shading size'}: "
                            f"{w}x{h}") for spec, (w, h) in view.gi_sizes]
            chosen = self._combo("GI resolution", st.gi_res, items)
            if chosen:
                self._request("set_gi_res", spec=chosen)
            if view.gi_note:
                self._wrapped(view.gi_note, WARN)
            changed, on = imgui.checkbox("inference one frame behind (worker thread)", view.pipelined)
            if changed:
                self._request("set_pipelined", on=on)
        if view.model_path is not None and st.model_meta:
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
        st, view = self.state, self.view
        s = st.stats
        imgui.text(f"frame {s.mean('frame'):6.2f} ms  ({s.fps:.1f} fps, vsync {'on' if view.vsync else 'off'})")
        imgui.text("frames " + ", ".join(f"{k} {n}" for k, n in view.frame_counts))
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
                imgui.text(f"mean {s.mean(name):6.2f}  p95 {s.p95(name):6.2f}")
            imgui.end_table()
        inf = s.series("inference")
        if view.model_path is not None and len(inf) > 1:
            imgui.plot_lines("##inference", inf, overlay_text="inference ms", scale_min=0.0,
                             graph_size=imgui.ImVec2(-1, 40))
        imgui.text_disabled(f"provider: {st.provider or '-'}")
        self._wrapped(f"GL: {view.gl_renderer}", DIM)
        imgui.text_disabled(f"GL stages: {view.timing_method}")
        if view.neural:
            imgui.text_disabled("direct light: " + ("computed in pack and upsample" if view.inline_direct
                                                    else "direct pass"))
        if view.pipelined:
            imgui.text(f"GI latency {view.latency_ms:.1f} ms (one frame behind)")
        changed, on = imgui.checkbox("per-stage timing", view.timer_sync)
        if changed:
            self._request("set_timing", on=on)
        changed, on = imgui.checkbox("vsync (V)", view.vsync)
        if changed:
            self._request("set_vsync", on=on)

    def _panel_screenshot(self) -> None:
        st = self.state
        _, st.shot_path = imgui.input_text("file", st.shot_path)
        if imgui.button("save (F12)"):
            self._request("screenshot", path=st.shot_path)
        self._wrapped("PNG of the view + the frame's JSON (diviewer render --config reads it)", DIM)

    def _panel_shortcuts(self) -> None:
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
