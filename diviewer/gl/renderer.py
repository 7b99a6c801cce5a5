"""The deferred GL renderer: a list of named passes (shadows, G-buffer, direct light); a frame is named buffers.

Each pass owns its targets and is timed as one stage by the shared ``StageTimer``. Shadow maps are
kept per light and re-rendered only when what they depend on changed (the light, an object's pose or
mesh, the shadow settings): a still scene seen from a moving camera renders no shadow map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import moderngl
import numpy as np

from diviewer.contract.encoding import INPUT_NAMES
from diviewer.gl.context import unbind_framebuffer
from diviewer.gl.draw import draw_objects
from diviewer.gl.frame import NAMES, Frame
from diviewer.gl.motion import MotionVectors
from diviewer.gl.resources import GpuScene, set_uniform
from diviewer.gl.shadow_fit import RenderSettings, light_defines, light_uniforms
from diviewer.gl.shadow_pass import ShadowPass
from diviewer.gl.shaders import ShaderCache
from diviewer.scene import camera as cam
from diviewer.scene.model import FrameConfig, Scene
from diviewer.timing import StageTimer

BUFFERS = INPUT_NAMES
"""The buffers a frame returns, in the network's input order (diviewer.contract.encoding.INPUT_CHANNELS)."""


@dataclass(frozen=True)
class FrameView:
    """What every pass of one frame reads: the configuration, camera matrices and the scene's bounds."""

    config: FrameConfig
    view: np.ndarray
    proj: np.ndarray
    bounds: np.ndarray
    settings: RenderSettings
    """The renderer's settings for this frame (the shadow pass's map sizes and lookups)."""


FLUSH_EVERY_DRAWS = 8
"""The G-buffer pass hands what it has drawn to the rasterizer (glFlush) every this many draws. llvmpipe shades and
bins a pass's triangles on the calling thread and rasterizes them on its own threads only once the pass is flushed;
flushed in parts, the rasterizer threads work on the first chunks while the calling thread bins the next. Sponza's
still view at 768x768, four alternating rounds: G-buffer 43-48 ms against 48-61, 10.6 fps against 10.4 on the mean
(docs/speed.md). The image is the same (a flush orders nothing differently)."""


class Renderer:
    """Renders a Scene's frames at a fixed resolution; textures stay on the GPU until read."""

    def __init__(self, ctx: moderngl.Context, scene: Scene, width: int, height: int,
                 settings: RenderSettings | None = None, shaders: ShaderCache | None = None,
                 timer: StageTimer | None = None, culling: bool = True, back_faces: bool = False,
                 flush_every: int = FLUSH_EVERY_DRAWS):
        self.ctx, self.scene = ctx, scene
        self.settings = settings or RenderSettings()
        self.culling = culling
        """Leave out what lies outside each pass's frustum (gl/culling.py); the image is the same either way."""
        self.back_faces = back_faces
        """Draw the back faces of single-sided materials (``Material.double_sided`` false) in the G-buffer too; by
        default they are culled: a closed surface's inside, seen only through its seams (docs/speed.md)."""
        self.flush_every = flush_every
        """The G-buffer pass flushes every this many draws (`FLUSH_EVERY_DRAWS`; 0: once, at its end, as GL does)."""
        self.flushes = 0
        """Flushes the G-buffer pass has made (its witness)."""
        self.drawn: dict[str, tuple[int, int]] = {}
        """The last frame's (draw calls, triangles) per pass: gbuffer, shadows (maps rendered this frame)."""
        self.shaders = shaders or ShaderCache(ctx)
        self.timer = timer or StageTimer()
        """Times each pass as a stage; the frame's owner resets it (GL passes need its sync or queries)."""
        self.gpu = GpuScene(ctx, scene.meshes, scene.materials)
        self._screen_vaos: dict[int, moderngl.VertexArray] = {}
        self.draw_cache: tuple = (None, None, [])
        """(scene, objects tuple, the draw list with its boxes and alpha-masked items): `gl.draw.frame_draw_list`."""
        self._bounds: tuple = (None, None, None)
        self._emissive: tuple = (None, False)
        self.shadow_renders = 0
        """Shadow maps drawn so far (a cached map is not counted, one drawn in bands counts at its last): the shadow
        cache's witness."""
        self.moving_shadow_size: int | None = None
        """A sun's map size while it, or an object, moves (the viewer's: an 8192 map takes ~325 ms here), the full one
        again once all rests (at the first frame, or over the next ones with ``rest_in_bands``); None: always the full
        size (captures, evaluation)."""
        self.shadow_footprint = True
        """A map drawn at ``moving_shadow_size`` holds only what can shade the camera's view (`shadow_casters`; the
        frame is the same); VXGI, which reads the map over its whole grid, turns it off."""
        self.rest_in_bands = False
        """At rest after a move, a sun's full map is drawn in bands over the next frames, each band as many texels as
        the moving map, the moving map shown meanwhile (gl/shadow_pass.py; the viewer's); else whole at once."""
        self.jitter = (0.0, 0.0)
        """Sub-pixel offset (pixels, x right, y up) of the G-buffer's image (``camera.jittered``; temporal
        upsampling's): pixel centre ``c`` shows what lies at ``c - jitter``. Lighting passes reconstruct positions
        through pixel centres, at the jittered depth."""
        self.motion_vectors = False
        """The G-buffer pass also draws the velocity target (gl/motion.py; temporal upsampling's): ``velocity``."""
        self.motion: MotionVectors | None = None
        """The velocity target and the previous frame's poses, made the first time ``motion_vectors`` is on."""
        self.shadow_pass = ShadowPass(self, self.settings)
        """The shadow maps: drawn, kept, and this frame's lookups (``shadow_pass.maps``)."""
        self.passes = (("shadows", self.shadow_pass.run), ("gbuffer", self._gbuffer_pass),
                       ("direct", self._direct_pass))
        """The frame, in order: (stage name, pass(frame view)); each pass is one timed stage."""
        self.frame_view: FrameView | None = None
        """The last frame rendered: its configuration, camera matrices and bounds."""
        self.direct_pending = False
        """The last frame's direct pass was deferred (``render(direct=False)``) and has not run yet."""
        self.width = self.height = 0
        self.resize(width, height)

    # --- resources ------------------------------------------------------------------------------
    @property
    def settings(self) -> RenderSettings:
        """The renderer's settings, the scene's shadow map size in place of none (`RenderSettings.for_scene`)."""
        return self._settings

    @settings.setter
    def settings(self, value: RenderSettings) -> None:
        self._settings = value.for_scene(self.scene)

    def resize(self, width: int, height: int) -> None:
        """(Re)allocate the screen-sized targets."""
        if (width, height) == (self.width, self.height):
            return
        if width < 1 or height < 1:
            raise ValueError(f"render size must be at least 1x1, got {width}x{height}")
        if self.width:
            self._release_targets()
        self.width, self.height = width, height
        size = (width, height)
        ctx = self.ctx
        self.textures = {
            "depth": ctx.texture(size, 1, dtype="f4"),
            "normal": ctx.texture(size, 4, dtype="f4"),
            "albedo": ctx.texture(size, 4, dtype="f4"),
            "emission": ctx.texture(size, 4, dtype="f4"),
            "direct": ctx.texture(size, 4, dtype="f4"),
        }
        for t in self.textures.values():
            t.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._zbuffer = ctx.depth_renderbuffer(size)
        self._gbuffer_fbo = ctx.framebuffer(
            [self.textures[k] for k in ("depth", "normal", "albedo", "emission")], self._zbuffer)
        # Without an emissive material the emission target is left out of the G-buffer pass (a
        # full-resolution float target fewer to write) and holds zeros, cleared once.
        self._gbuffer_fbo_dark = ctx.framebuffer([self.textures[k] for k in ("depth", "normal", "albedo")],
                                                 self._zbuffer)
        self._emission_fbo = ctx.framebuffer([self.textures["emission"]])
        self._emission_zero = False
        self._direct_fbo = ctx.framebuffer([self.textures["direct"]])

    def _release_targets(self) -> None:
        unbind_framebuffer(self.ctx)
        if self.motion is not None:
            self.motion.release()
        for t in self.textures.values():
            t.release()
        self._zbuffer.release()
        self._gbuffer_fbo.release()
        self._gbuffer_fbo_dark.release()
        self._emission_fbo.release()
        self._direct_fbo.release()

    def release(self) -> None:
        self._release_targets()
        self.shadow_pass.release()
        for vao in self._screen_vaos.values():
            vao.release()
        self.gpu.release()

    # --- passes ---------------------------------------------------------------------------------
    def render(self, config: FrameConfig | None = None, direct: bool = True) -> dict[str, moderngl.Texture]:
        """Render one frame; returns the named textures (depth, normal, albedo, emission, direct); `buffers` gives
        them as the frame's value, its direct light decided.

        ``direct=False`` defers the direct pass: ``textures["direct"]`` is then stale until
        ``ensure_direct()`` runs it. The viewer renders so, because its neural pass computes the direct
        light inline where it can (``inline_light``) and everything else that reads the buffer asks first.
        """
        config = config or self.scene.default
        if self._bounds[0] is not self.scene or self._bounds[1] is not config.objects:
            # The shadow maps' fit; a loop over the objects, so once per (scene, objects tuple).
            self._bounds = (self.scene, config.objects, self.scene.bounds(config))
        frame = FrameView(config, config.camera.view_matrix(), config.camera.projection(self.width / self.height),
                          self._bounds[2], self.settings)
        self.frame_view = frame
        self.direct_pending = not direct
        self.drawn = {}
        for name, run in self.passes:
            if name == "direct" and not direct:
                continue
            with self.timer.stage(name, gpu=True):
                run(frame)
        return self.textures

    @property
    def shadows_pending(self) -> bool:
        """Whether a sun's map is not yet the one drawn at rest (the moving map, or the full one still drawn in
        bands): the next frames draw it."""
        full = self.settings.shadow_size
        return any(m is not None and m.pending(full) for m in self.shadow_pass.maps.values())

    def ensure_direct(self) -> moderngl.Texture:
        """The direct-light target of the last frame, running the direct pass if ``render`` deferred it."""
        if self.direct_pending:
            with self.timer.stage("direct", gpu=True):
                self._direct_pass(self.frame_view)
            self.direct_pending = False
        return self.textures["direct"]

    def buffers(self, inline: bool = False, samples: int = 1) -> Frame:
        """The last frame's buffers (`diviewer.gl.frame.Frame`), its direct light decided once: ``inline`` where
        the reader asks for it (``inline``), the direct pass was deferred and the frame has at most one light;
        else the direct pass's target, the pass run now if it was deferred. ``samples`` > 1: this renderer draws
        at that many times the size of the frame it stands for (``area``, `diviewer.gl.area`)."""
        t, ok, light = self.textures, *self.inline_light()
        common = dict(size=(self.width, self.height), depth=t["depth"], normal=t["normal"], albedo=t["albedo"],
                      emissive=self.emissive, view=self.frame_view)
        if inline and self.direct_pending and ok and samples == 1:
            return Frame(direct=t["emission"], direct_from="inline", light=light,
                         light_uniforms=self.set_direct_uniforms, **common)
        return Frame(direct=self.ensure_direct(), direct_from="area" if samples > 1 else "pass", samples=samples,
                     **common)

    def buffer(self, name: str) -> moderngl.Texture:
        """One of the last frame's buffers (`diviewer.gl.frame.NAMES`) by name, without deciding the others: ``direct``
        is `buffers`' (the direct pass's target, the pass run now if it was deferred), depth, normal and albedo
        are the G-buffer's as drawn, so showing them leaves a deferred direct pass deferred."""
        if name == "direct":
            return self.buffers().direct
        if name not in NAMES:
            raise KeyError(f"no buffer {name!r}: one of {', '.join(NAMES)}")
        return self.textures[name]

    def inline_light(self) -> tuple[bool, object]:
        """Whether the last frame's direct light can be computed where it is read (direct_inline.glsl: at
        most one light), and that light (None: none)."""
        lights = self.frame_view.config.lights if self.frame_view is not None else ()
        return len(lights) <= 1, (lights[0] if lights else None)

    def set_direct_uniforms(self, prog, light) -> None:
        """The uniforms of direct.glsl's light_term() for ``light`` in the last frame: the camera's inverse
        view and field of view, the light, its shadow map (texture unit 4)."""
        config, view = self.frame_view.config, self.frame_view.view
        t = math.tan(math.radians(config.camera.fov) / 2.0)
        set_uniform(prog, "m_inv_view", cam.view_to_world(view))
        set_uniform(prog, "u_tan_half_fov", (t * self.width / self.height, t))
        set_uniform(prog, "u_jitter", tuple(map(float, self.jitter)))
        self.set_light_uniforms(prog, light, self.shadow_pass.maps.get(light.name))

    def _gbuffer_pass(self, frame: "FrameView") -> None:
        ctx, config, view, proj = self.ctx, frame.config, frame.view, frame.proj
        if self.jitter != (0.0, 0.0):
            proj = cam.jittered(proj, self.jitter, self.width, self.height)
        emissive = self.emissive
        if not emissive and not self._emission_zero:
            self._emission_fbo.clear(0.0, 0.0, 0.0, 0.0)
        self._emission_zero = not emissive
        fbo = self._gbuffer_fbo if emissive else self._gbuffer_fbo_dark
        defines, motion, motion_uniforms = {}, None, None
        if self.motion_vectors:
            motion = self.motion = self.motion or MotionVectors(ctx)
            fbo = motion.framebuffer(fbo.color_attachments, self._zbuffer, emissive)
            defines = {"VELOCITY": len(fbo.color_attachments) - 1}  # its location: after the G-buffer's targets
            motion_uniforms = motion.begin(config, frame.view, frame.proj)
        elif self.motion is not None:
            self.motion.forget()
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable_only(moderngl.DEPTH_TEST)
        uniforms = {"m_proj": proj, "m_view": view, **(motion_uniforms or {})}
        draw_objects(self, config, "gbuffer.glsl", defines, uniforms, view, proj @ view, "gbuffer",
                     not self.back_faces, previous_model=motion and motion.previous_model)
        if motion is not None:
            motion.end()

    @property
    def velocity(self) -> moderngl.Texture | None:
        """The last frame's velocity target (gl/motion.py), None where it was drawn without motion vectors."""
        return self.motion.texture if self.motion is not None and self.motion.drawn else None

    def _screen_program(self, defines: dict) -> moderngl.Program:
        prog = self.shaders.program("direct.glsl", defines)
        for i, name in enumerate(("depth", "normal", "albedo", "emission")):
            self.textures[name].use(location=i)
            set_uniform(prog, f"u_{name}", i)
        return prog

    def _fullscreen(self, prog: moderngl.Program) -> None:
        """Draw the one-triangle screen cover (shaders/fullscreen.glsl) with ``prog``."""
        if prog.glo not in self._screen_vaos:
            self._screen_vaos[prog.glo] = self.ctx.vertex_array(prog, [])
        self._screen_vaos[prog.glo].render(moderngl.TRIANGLES, vertices=3)

    def _direct_pass(self, frame: "FrameView") -> None:
        """Each light's shadowed Lambert term, then emission, added into the direct-light target.

        The first light writes over the cleared target (adding to zero is writing; a full-resolution
        float blend is a read per pixel on a software rasterizer); emission is drawn only when a material
        of the scene emits (otherwise it is a full-resolution pass that adds zeros).
        """
        self._direct_fbo.use()
        self._direct_fbo.clear(0.0, 0.0, 0.0, 0.0)
        for i, light in enumerate(frame.config.lights):
            self._light_pass(light, blend=i > 0)
        if self.emissive:
            self._emission_pass()

    @property
    def emissive(self) -> bool:
        """Whether any material of the scene emits light (looked up once per scene object)."""
        if self._emissive[0] is not self.scene:
            self._emissive = (self.scene, any(any(c > 0.0 for c in m.emission) for m in self.scene.materials.values()))
        return self._emissive[1]

    def _light_pass(self, light, blend: bool = True) -> None:
        """One light's term in the last frame, added to the target (``blend``) or written over it."""
        ctx = self.ctx
        self._direct_fbo.use()
        ctx.enable_only(moderngl.BLEND if blend else moderngl.NOTHING)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        prog = self._screen_program(light_defines(light))
        self.set_direct_uniforms(prog, light)
        self._fullscreen(prog)
        ctx.disable(moderngl.BLEND)

    def set_light_uniforms(self, prog, light, shadow) -> None:
        """One light's radiometry and shadow-lookup uniforms for direct.glsl's code (the direct pass, and
        VXGI's injection, which shares the shadow lookup); ``shadow`` is this frame's map of the light."""
        light_uniforms(prog, light, shadow, self.settings)

    def _emission_pass(self) -> None:
        ctx = self.ctx
        self._direct_fbo.use()
        ctx.enable_only(moderngl.BLEND)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        self._fullscreen(self._screen_program({"EMISSION": 1}))
        ctx.disable(moderngl.BLEND)

    # --- read-back ------------------------------------------------------------------------------
    def read(self, name: str) -> np.ndarray:
        """A buffer as float32, top row first: depth (H, W), the others (H, W, 3)."""
        tex = self.ensure_direct() if name == "direct" else self.textures[name]
        comps = 1 if name == "depth" else 3
        raw = np.frombuffer(tex.read(), dtype="f4").reshape(self.height, self.width, tex.components)
        return np.ascontiguousarray(np.flipud(raw[..., 0] if comps == 1 else raw[..., :3]))

    def frame(self, config: FrameConfig | None = None) -> dict[str, np.ndarray]:
        """Render and read back the network's input buffers."""
        self.render(config)
        with self.timer.stage("readback", gpu=True):
            return {name: self.read(name) for name in BUFFERS}
