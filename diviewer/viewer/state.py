"""The viewer's state and the actions the panel, the keyboard and scripts apply to it. Pure data: no GL.

A frame is drawn from ``ViewerState.scene`` and ``ViewerState.config`` (a frozen FrameConfig that each
action replaces); everything else here says how to show it (view mode, exposure) and what was
measured (``Stats``).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.gl.display import DEFAULT_TONEMAP, tonemap_code
from diviewer.scene.lights import angles_to_vector, box_sweep, power_field, rotate_light, vector_to_angles
from diviewer.scene.model import DirectionalLight, FrameConfig, PointLight, Scene
from diviewer.scene.picking import pick_object, pixel_ray
from diviewer.scene.camera_path import CameraPath, read_path, scene_camera_path
from diviewer.scene.ranges_check import out_of_range
from diviewer.viewer.controls import Controller, make_controller, overview
from diviewer.exposure import SHOWN, WHITE_POINTS, AutoExposure
from diviewer.viewer.stats import Stats
from diviewer.viewer.view_modes import ViewMode, view_mode


class ViewerState:
    """Scene, current frame configuration, camera controller, selection and display settings.

    Each action replaces ``config`` (frozen) and returns it. ``scene`` is replaced too when a mesh
    is loaded from a file (``scene_revision`` counts those changes, so the GPU copy can follow).
    """

    def __init__(self, scene: Scene, controller: str = "fly"):
        self.base_scene = scene
        self.scene = scene
        self.scene_revision = 0
        self.user_meshes: dict[str, str] = {}
        """Meshes loaded from files: key -> path (recorded with screenshots)."""
        self.config: FrameConfig = scene.default
        self.controller: Controller = make_controller(controller, scene.default.camera, self.scene_centre())
        self.selected: str | None = None
        self.selected_light: str | None = scene.default.lights[0].name if scene.default.lights else None
        self.view_mode = "final"
        self.compare = ("final", "reference")
        """Modes A and B of the split-screen and difference layouts."""
        self.split_position = 0.5
        """Where the split-screen divider is, as a fraction of the width."""
        self.diff_gain_ev = 2.0
        """The difference image is brightened by this many stops."""
        self.exposure = float(scene.exposure)
        self.auto_exposure = False
        """Meter the exposure from the shown frame each frame (``auto``), instead of the slider's."""
        self.auto = AutoExposure(SHOWN)
        self._ranges: tuple = (None, None, [])
        self.tonemap = DEFAULT_TONEMAP
        self.animate_light = False
        self.light_time = 0.0
        self.light_period = 10.0
        """Seconds for one sweep of the light across its range and back."""
        self.play_path = False
        self.path_time = 0.0
        """Seconds into the path being played (`playable_path`)."""
        self._path_started = False
        self.path: CameraPath | None = None
        """A camera path loaded from a file (`load_path`); None: P plays the scene file's own walk."""
        self.path_file: str | None = None
        self._scene_path = scene_camera_path(scene)
        self.recorder = None
        """The recording in progress (a `diviewer.viewer.recording.Recorder`), or None."""
        self.record_file: str | None = None
        """Where recordings go (``--record-path``); None: a free diviewer_<scene>_path.json."""
        self.exact_recording = False
        """Keep every frame of a recording (a fixed time step: a replay then draws each frame exactly)."""
        self.model_name: str | None = None
        """The model requested: a file name in the models folder, a path, or None for no model."""
        self.model_meta: dict | None = None
        self.model_message = ""
        """Why there is no neural GI (no model for this scene, or the model's refusal)."""
        self.provider = ""
        self.gi_res = "model"
        """The GI resolution asked for (``model``, a fraction of the window, WxH)."""
        self.stats = Stats()
        self.show_panel = True
        self.shot_path = f"diviewer_{scene.name}.png"
        """Where the panel's and F12's screenshots go."""
        self.message = ""
        """The last action's outcome for the panel (a loaded mesh, a saved screenshot, an error)."""

    # --- helpers ---------------------------------------------------------------------------------
    def scene_centre(self) -> np.ndarray:
        return self.base_scene.bounds(self.base_scene.default).mean(axis=0)

    def _set(self, config: FrameConfig) -> FrameConfig:
        self.config = config
        return config

    def object(self, name: str):
        for o in self.config.objects:
            if o.name == name:
                return o
        raise DiviewerError(f"no object named '{name}'; objects: {', '.join(o.name for o in self.config.objects)}")

    def light(self, name: str | None = None):
        name = name or self.selected_light
        for l in self.config.lights:
            if l.name == name:
                return l
        names = ", ".join(l.name for l in self.config.lights) or "none"
        raise DiviewerError(f"no light named '{name}'; lights: {names}")

    def _default_light(self, name: str):
        for l in self.scene.default.lights:
            if l.name == name:
                return l
        return self.light(name)

    # --- camera ----------------------------------------------------------------------------------
    def _sync_camera(self) -> FrameConfig:
        return self._set(dataclasses.replace(self.config, camera=self.controller.camera()))

    def set_controller(self, kind: str) -> FrameConfig:
        """Switch between 'fly' and 'orbit', keeping the view (orbit turns about the scene centre)."""
        self.controller = make_controller(kind, self.config.camera, self.scene_centre())
        return self._sync_camera()

    def toggle_controller(self) -> FrameConfig:
        return self.set_controller("orbit" if self.controller.kind == "fly" else "fly")

    def reset_camera(self) -> FrameConfig:
        """Back to the scene's camera, with the current controller kind."""
        self.play_path = False
        self.controller = make_controller(self.controller.kind, self.scene.default.camera, self.scene_centre())
        return self._sync_camera()

    def scene_bounds(self) -> np.ndarray:
        """The box (2, 3: min, max corners) around the current frame's objects."""
        return np.asarray(self.scene.bounds(self.config), np.float64)

    def overview_camera(self) -> FrameConfig:
        """The camera above the scene's box on the side it looks from, at its centre (``controls.overview``)."""
        self.play_path = False
        return self.set_camera(overview(self.config.camera, self.scene_bounds()))

    def set_camera(self, camera) -> FrameConfig:
        self.controller = make_controller(self.controller.kind, camera, self.scene_centre())
        return self._sync_camera()

    def fly(self, forward: float = 0.0, right: float = 0.0, up: float = 0.0, dt: float = 1.0 / 60,
            fast: bool = False) -> FrameConfig:
        """WASD/QE movement (each input in [-1, 1]) for ``dt`` seconds."""
        self.play_path = False
        self.controller.move(forward, right, up, dt, fast)
        return self._sync_camera()

    def look(self, dx: float, dy: float) -> FrameConfig:
        """Mouse look (right button held), in pixels."""
        self.play_path = False
        self.controller.look(dx, dy)
        return self._sync_camera()

    def drag(self, dx: float, dy: float) -> FrameConfig:
        """Left-button drag: orbit (orbit mode) or look (fly mode), in pixels."""
        self.play_path = False
        self.controller.drag(dx, dy)
        return self._sync_camera()

    def scroll(self, dy: float) -> FrameConfig:
        """Wheel: zoom (orbit) or change the flying speed (fly)."""
        self.controller.scroll(dy)
        return self._sync_camera()

    def set_fov(self, fov: float) -> FrameConfig:
        self.controller.fov = float(min(max(fov, 5.0), 150.0))
        return self._sync_camera()

    # --- objects ---------------------------------------------------------------------------------
    def select_object(self, name: str | None) -> str | None:
        if name is not None:
            self.object(name)  # raises for an unknown name
        self.selected = name
        return name

    def pick(self, x: float, y: float, width: int, height: int) -> str | None:
        """Select the object under image point (x, y) (pixels, y down) of a width x height view; None: sky."""
        origin, d = pixel_ray(self.config.camera, x, y, width, height)
        hit = pick_object(self.scene, self.config, origin, d)
        return self.select_object(hit[0] if hit else None)

    def move_object(self, name: str, position) -> FrameConfig:
        return self._set(self.config.replace_object(name, position=tuple(float(v) for v in position)))

    def translate_object(self, name: str, delta) -> FrameConfig:
        p = np.add(self.object(name).position, delta)
        return self.move_object(name, p)

    def rotate_object(self, name: str, rotation) -> FrameConfig:
        """Set the Euler angles (degrees, about x then y then z)."""
        return self._set(self.config.replace_object(name, rotation=tuple(float(v) for v in rotation)))

    def scale_object(self, name: str, scale) -> FrameConfig:
        """Set the scale: one number (uniform) or three; zero is refused (it would flatten the normals)."""
        s = (float(scale),) * 3 if np.ndim(scale) == 0 else tuple(float(v) for v in scale)
        if len(s) != 3 or min(abs(v) for v in s) < 1e-6:
            raise DiviewerError(f"scale must be three non-zero numbers, got {scale}", field="scale")
        return self._set(self.config.replace_object(name, scale=s))

    def swap_mesh(self, name: str, mesh: str) -> FrameConfig:
        """Give an object another mesh from the scene's library (or one loaded with load_mesh)."""
        if mesh not in self.scene.meshes:
            raise DiviewerError(f"scene '{self.scene.name}' has no mesh '{mesh}'; "
                                f"meshes: {', '.join(self.scene.meshes)}", field="mesh")
        return self._set(self.config.replace_object(name, mesh=mesh))

    def reset_object(self, name: str) -> FrameConfig:
        for o in self.scene.default.objects:
            if o.name == name:
                return self._set(dataclasses.replace(
                    self.config, objects=tuple(o if x.name == name else x for x in self.config.objects)))
        raise DiviewerError(f"object '{name}' is not in the scene's default frame")

    def load_mesh(self, path: str | Path, name: str | None = None) -> str:
        """Add a mesh file (OBJ, PLY, glTF, ...) to the scene's library and give it to object ``name``.

        Returns the new mesh's key (``file:<stem>``). The file's own base colour or texture becomes the
        object's material; otherwise the object keeps its material.
        """
        from diviewer.scene.loader import add_mesh_file

        path = Path(path).expanduser()
        self.scene, key, material = add_mesh_file(self.scene, path)
        self.scene_revision += 1
        self.user_meshes[key] = str(path)
        if name is not None:
            self.swap_mesh(name, key)
            if material is not None:
                self._set(self.config.replace_object(name, material=material))
        return key

    # --- lights ----------------------------------------------------------------------------------
    def light_angles(self, name: str | None = None) -> tuple[float, float]:
        """(azimuth, elevation) in degrees of the direction towards the light (a sun), or of its position about
        the scene centre (a point light)."""
        l = self.light(name)
        if isinstance(l, DirectionalLight):
            return vector_to_angles(-np.asarray(l.direction))
        return vector_to_angles(np.asarray(l.position) - self.scene_centre())

    def set_light_direction(self, azimuth: float, elevation: float, name: str | None = None) -> FrameConfig:
        """Put the light at (azimuth, elevation): a sun shines from there; a point light moves there, keeping its
        distance to the scene centre."""
        l = self.light(name)
        self.animate_light = False
        v = angles_to_vector(azimuth, elevation)
        if isinstance(l, DirectionalLight):
            return self._set(self.config.replace_light(l.name, direction=tuple(map(float, -v))))
        c = self.scene_centre()
        r = float(np.linalg.norm(np.asarray(l.position) - c))
        return self._set(self.config.replace_light(l.name, position=tuple(map(float, c + r * v))))

    def set_light_position(self, position, name: str | None = None) -> FrameConfig:
        l = self.light(name)
        if not isinstance(l, PointLight):
            raise DiviewerError(f"light '{l.name}' is directional: set its direction, not its position")
        self.animate_light = False
        return self._set(self.config.replace_light(l.name, position=tuple(float(v) for v in position)))

    def light_intensity_ev(self, name: str | None = None) -> float:
        """The light's irradiance (sun) or intensity (point) in stops relative to the scene file's value."""
        l = self.light(name)
        f = power_field(l)
        base, now = getattr(self._default_light(l.name), f), getattr(l, f)
        if base <= 0.0 or now <= 0.0:
            return -math.inf if now <= 0.0 else 0.0
        return math.log2(now / base)

    def set_light_intensity(self, ev: float, name: str | None = None) -> FrameConfig:
        """Log scale: the scene file's irradiance/intensity times 2**ev (ev = -inf turns the light off)."""
        l = self.light(name)
        f = power_field(l)
        base = getattr(self._default_light(l.name), f) or 1.0
        value = 0.0 if ev == -math.inf else base * 2.0 ** float(ev)
        return self._set(self.config.replace_light(l.name, **{f: value}))

    def set_light_color(self, color, name: str | None = None) -> FrameConfig:
        c = tuple(float(v) for v in color)
        if len(c) != 3 or min(c) < 0.0:
            raise DiviewerError(f"a light colour is three non-negative numbers, got {color}", field="color")
        return self._set(self.config.replace_light(self.light(name).name, color=c))

    def toggle_animation(self) -> bool:
        self.animate_light = not self.animate_light
        return self.animate_light

    def playable_path(self) -> CameraPath | None:
        """What P plays: the loaded path, else the scene file's own walk (None: neither)."""
        return self.path if self.path is not None else self._scene_path

    def toggle_path(self) -> bool:
        """Play or stop the camera path (`playable_path`; scenes without one have nothing to play)."""
        self.play_path = not self.play_path and self.playable_path() is not None
        self._path_started = False
        return self.play_path

    def load_path(self, file: str | Path) -> CameraPath:
        """Load a camera path file recorded in this scene and play it from its start."""
        self.path, self.scene = read_path(file, self.scene)
        self.path_file, self.path_time, self.play_path, self._path_started = str(file), 0.0, True, False
        if self.path.user_meshes:  # mesh files the path's objects wear: uploaded at the next frame
            self.user_meshes.update(self.path.user_meshes)
            self.scene_revision += 1
        return self.path

    def begin(self, path=None, record=None, exact: bool = False) -> None:
        """A session's start: play a path file, record from the first frame into ``record`` (a file), keep every
        frame of recordings (``exact``: the viewer runs a fixed time step)."""
        self.exact_recording, self.record_file = exact, (str(record) if record is not None else None)
        if path is not None:
            self.load_path(path)
        if record is not None:
            self.toggle_recording()

    def toggle_recording(self) -> str:
        """Start recording the frames as a camera path, or stop and write it; returns the panel's message."""
        from diviewer.viewer.recording import Recorder

        if self.recorder is None:  # --record-path takes the first recording; later ones get free names
            self.recorder = Recorder(self.base_scene, self.record_file, exact=self.exact_recording)
            self.record_file = None
            self.message = "recording the camera path (Ctrl+R stops)"
        else:
            self.message = self.stop_recording()
        return self.message

    def stop_recording(self) -> str:
        """Write the recording in progress, if any (atomically); returns what was written."""
        rec, self.recorder = self.recorder, None
        if rec is None:
            return ""
        file = rec.write(self.scene, self.user_meshes)
        return f"recorded {len(rec.keys)} frames, {rec.time:.1f} s, to {file}" if file else "nothing recorded"

    def _animated_lights(self) -> tuple:
        """Each light turned about its range axis: swept across the range angle, or all round without one."""
        phase = 2.0 * math.pi * self.light_time / self.light_period
        out = []
        for light in self.config.lights:
            r = self.scene.ranges.lights.get(light.name)
            if r is not None and r.position is not None:  # a point light moving in its box, never through walls
                out.append(dataclasses.replace(light, position=box_sweep(r.position, phase)))
                continue
            if r is not None and r.angle[1] > r.angle[0]:
                lo, hi = r.angle
                angle = 0.5 * (lo + hi) + 0.5 * (hi - lo) * math.sin(phase)
            else:
                angle = math.degrees(phase) % 360.0
            axis = r.axis if r is not None else (0.0, 1.0, 0.0)
            # Turned from the scene file's pose; power and colour stay as the panel set them.
            turned = rotate_light(self._default_light(light.name), axis, angle, self.scene_centre())
            keep = {"direction": turned.direction} if isinstance(light, DirectionalLight) else {"position": turned.position}
            out.append(dataclasses.replace(light, **keep))
        return tuple(out)

    def step(self, dt: float) -> FrameConfig:
        """Advance time: animate the lights and play the camera path when those are on."""
        if self.animate_light and self.config.lights:
            self.light_time += dt
            self._set(dataclasses.replace(self.config, lights=self._animated_lights()))
        path = self.playable_path()
        if self.play_path and path is not None:
            self.path_time += dt if self._path_started else 0.0
            self._path_started = True
            t = path.wrap(path.start + self.path_time)
            # A loaded path also sets lights and objects; the scene's walk only the camera.
            config = path.config_at(t, self.config) if path is self.path else \
                dataclasses.replace(self.config, camera=path.camera_at(t))
            self.controller = make_controller(self.controller.kind, config.camera, self.scene_centre())
            self._set(config)  # the path's camera exactly (the controller takes over from it when the user flies)
        if self.recorder is not None:
            self.recorder.add(dt, self.config)
        return self.config

    # --- display ---------------------------------------------------------------------------------
    def set_view_mode(self, name: str, a: str | None = None, b: str | None = None) -> ViewMode:
        """Show a view mode; ``a`` and ``b`` choose the two modes of split screen and difference."""
        mode = view_mode(name)
        if a is not None or b is not None:
            self.set_compare(a or self.compare[0], b or self.compare[1])
        self.view_mode = mode.name
        return mode

    def set_compare(self, a: str, b: str) -> tuple[str, str]:
        for m in (a, b):
            if view_mode(m).layout != "single":
                raise DiviewerError(f"split screen and difference combine single-image modes, not '{m}'",
                                    field="view mode")
        self.compare = (a, b)
        return self.compare

    def modes_shown(self) -> tuple[ViewMode, ...]:
        """The single-image modes the current view mode draws."""
        mode = view_mode(self.view_mode)
        if mode.layout == "single":
            return (mode,)
        return (view_mode(self.compare[0]), view_mode(self.compare[1]))

    def set_exposure(self, ev: float) -> float:
        self.exposure = float(ev)
        return self.exposure

    def set_auto_exposure(self, on: bool) -> bool:
        """Meter the exposure from each shown frame (smoothed; restarts from the next frame), or keep the slider's."""
        if on and not self.auto_exposure:
            self.auto.reset()
        self.auto_exposure = bool(on)
        return self.auto_exposure

    def meter(self, samples) -> float:
        """Auto exposure: feed one shown frame's radiance samples; the exposure follows (when on)."""
        ev = self.auto.update(samples, WHITE_POINTS[self.tonemap])
        if self.auto_exposure and ev is not None:
            self.exposure = float(ev)
        return self.exposure

    def out_of_range(self) -> list[str]:
        """Why the current frame lies outside what the scene's model was trained on (empty: inside)."""
        if self._ranges[0] is not self.scene or self._ranges[1] is not self.config:
            self._ranges = (self.scene, self.config, out_of_range(self.scene, self.config))
        return self._ranges[2]

    def set_tonemap(self, name: str) -> str:
        tonemap_code(name)  # refuses an unknown name
        self.tonemap = name
        return name

    def reset(self) -> FrameConfig:
        """Back to the scene's default frame (lights, objects, camera); loaded meshes stay in the library."""
        self.animate_light = self.play_path = False
        self.light_time = self.path_time = 0.0
        self._set(self.scene.default)
        return self.reset_camera()
