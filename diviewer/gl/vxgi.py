"""Voxel cone tracing (VXGI, Crassin et al. 2011): the real-time GI baseline and a second ground truth.

The pass runs after the deferred renderer (diviewer.gl.renderer) and reuses its G-buffer, its shadow
maps and its direct light; it adds diffuse indirect light (one bounce, or two):

1. **voxelize** (shaders/vxgi_voxelize.glsl): every triangle is rasterised onto the face of a cubic
   grid fitted to the scene's bounds that its normal points at most along (dominant-axis projection,
   no conservative rasterisation on llvmpipe), and each fragment is appended to a *voxel fragment
   list* (position, normal, albedo, emission). Objects the scene's ranges cannot move are static:
   their list is made once; the others' list is remade only when one of them changes.
2. **inject** (vxgi_inject.glsl): per fragment and light, albedo / pi * E * |cos| * the renderer's own
   shadow-map lookup (direct.glsl's), plus emission, summed into the fragment's voxel with 64-bit
   fixed-point integer atomics (vxgi_fixed.glsl): the grid does not depend on draw order (bitwise).
   Runs only when the light or an object changed. **resolve** (vxgi_resolve.glsl, per fragment: only
   occupied voxels are touched) stores the voxel's mean radiance, premultiplied by its coverage
   (alpha = 1 where a surface fell), in an RGBA16F 3D texture.
3. **mip** (vxgi_mip.glsl): six directional grids (``anisotropic``, Crassin's): for cones travelling
   +x, -x, ... a parent is its children composited front to back along that axis, so that a wall hides
   what lies behind it at every level. Isotropic instead: one grid whose coverage is the most opaque
   axis's (the plain mean would make a one-voxel wall half transparent per level: a closed glowing
   box gave 0.2-0.4 of its radiance; this gives ~0.95).
4. **bounce** (vxgi_bounce.glsl, ``bounces = 2``): each fragment gathers the first-bounce grid through
   the same cones, adds albedo x indirect to its voxel; resolve and mip again.
5. **trace** (vxgi_trace.glsl + vxgi_cone.glsl): per pixel (at full or a lower trace resolution),
   ``cones`` cones of ``aperture`` degrees about the normal, weighted by their share of the
   cosine-weighted hemisphere, march front to back through the mips; out: indirect (E / pi, the
   cosine-weighted mean incoming radiance) and ambient occlusion.
6. **upsample** (vxgi_upsample.glsl, lower trace resolutions only): joint bilateral on depth and normal.
7. **composite** (vxgi_composite.glsl): ``vxgi = direct + albedo * indirect``; ``vxgi_indirect`` is
   ``albedo * indirect``, comparable with the path tracer's ``pt - pt_direct``.

Accuracy on cornell (64x64, 4 frames, MSE against a 1024-spp path tracer, vxgi_accuracy.py, docs/experiments.md):
direct light alone 0.0167; defaults (trace_scale 2) at grids 32/64/128: one bounce 0.0049/0.0057/0.0057,
two bounces 0.0033/0.0039/0.0038 (the coarse grid's extra leaking stands in for missing bounces). At
64^3 and full trace resolution: isotropic without lod bias 0.0059, the defaults 0.0055.
One bounce misses the light that bounced more (the path tracer has it): darker corners.

Artefacts, and what the settings do about them:

- **Light leaking through thin walls.** A coarse voxel mixes both sides of a wall, and a coarse
  sample's footprint (its trilinear neighbourhood of voxels a cone diameter wide) reaches behind the
  cone's apex: a surface sees the lit far side of the wall it stands on, or of the opposite wall
  (cornell's walls are sunlit outside: its red wall glows red inside where the path tracer has it
  dark). Measured on a closed box lit from outside (tests/gl/test_vxgi.py): 7 % of the outside radiance
  inside with the defaults, 14 % isotropic or without the lod bias, the same at 64^3 and 128^3.
  ``anisotropic`` stops a wall from showing its far side; ``lod_bias`` samples finer levels than the
  cone's diameter (smaller footprints, a little noisier, and a thin wall between samples is missed
  more often); a smaller ``aperture`` (with more ``cones``) and a shorter ``max_distance`` keep samples
  on finer levels, at the price of light from far away.
- **Self-occlusion and self-illumination.** A cone starting on a surface samples that surface's own
  voxels: they darken it and light it with its own radiance, most for cones near the tangent plane.
  ``offset`` (voxels along the normal before the first sample) and ``lift`` (samples kept off the
  tangent plane by a multiple of their radius) remove it; too much of either skips real nearby
  occluders (contact shadows in corners) and, on thin objects, starts the cone past the wall behind.
- **Energy lost between samples.** A one-voxel wall sampled trilinearly between two samples looks
  partly transparent and some cones pass through it (a closed glowing box: 0.89-0.93 of its radiance,
  down to 0.6 in corners). ``step`` below 1 is slower and barely changes it; above 1 loses more.
- **Gaps and blockiness.** Without conservative rasterisation a triangle thinner than a voxel can fall
  between pixel centres and leave holes that cones see through; a coarse ``resolution`` makes indirect
  light blocky and moves it by up to a voxel.
- **Lower trace resolution** (``trace_scale``) blurs indirect light over ``trace_scale`` pixels except
  across depth or normal edges, which the bilateral upsampling keeps (``depth_sigma``, ``normal_power``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import moderngl
import numpy as np

from diviewer.errors import DiviewerError
from diviewer.gl.context import unbind_framebuffer
from diviewer.gl.renderer import Renderer
from diviewer.gl.resources import set_uniform
from diviewer.gl.vxgi_grid import VoxelGridPasses, FragmentList
from diviewer.scene import camera as cam
from diviewer.scene.model import FrameConfig, Object
from diviewer.timing import StageTimer

MAX_CONES = 16
"""Must match MAX_CONES in shaders/vxgi_cone.glsl."""

STAGES = ("vxgi_voxelize", "vxgi_inject", "vxgi_mip", "vxgi_bounce", "vxgi_trace", "vxgi_upsample", "vxgi_composite")
"""Timed stages (``VXGIPass.timings``); the first four run only when something changed."""

_SUM_UINTS = 8    # per voxel: r, g, b as (lo, hi) words, count, unused


@dataclass(frozen=True)
class VXGISettings:
    """Settings of the VXGI pass (recorded with every render, capture and benchmark)."""

    resolution: int = 64
    """Voxels per side of the cubic grid: a power of two, 16 to 256 (32, 64 and 128 are the usual)."""
    cones: int = 6
    """Diffuse cones per pixel: one along the normal, the others in a ring around it; 1 to 16."""
    aperture: float = 60.0
    """Full cone angle in degrees; the ring sits at 90 - aperture / 2 degrees from the normal (45 for
    apertures over 90)."""
    step: float = 1.0
    """March step as a multiple of the sample's diameter (larger: faster, skips thin walls)."""
    offset: float = 1.5
    """Cone start offset along the surface normal, in level-0 voxels (against self-occlusion)."""
    lift: float = 2.0
    """Each sample is raised along the normal until its centre is lift x its radius above the surface's
    tangent plane (0: off; 2: a sample never overlaps the surface's own voxels at its mip level)."""
    lod_bias: float = 1.0
    """Sample this many mip levels finer than the cone's diameter asks (a coarse sample's trilinear
    footprint reaches behind the cone's apex: it sees walls behind the surface, e.g. their lit far side)."""
    max_distance: float = 1.0
    """Longest cone, as a fraction of the grid's side."""
    ao_distance: float = 0.15
    """Ambient occlusion counts what a cone hits within this fraction of the grid's side."""
    anisotropic: bool = True
    """Six directional grids above level 0 (front-to-back along each axis): walls hide what is behind them
    at every mip level, from either side. Off: one isotropic grid, faster, leaks light through walls."""
    bounces: int = 1
    """Bounces of indirect light: 1, or 2 (each voxel fragment gathers the first bounce through the same
    cones before the screen trace; costs a trace per fragment whenever the grid is re-injected)."""
    trace_scale: int = 2
    """Trace one pixel per trace_scale x trace_scale block (1 = full resolution), then upsample."""
    depth_sigma: float = 0.05
    """Upsampling: relative depth difference at which a trace pixel's weight falls to 1/e."""
    normal_power: float = 8.0
    """Upsampling: a trace pixel's weight is multiplied by max(n . n', 0) ** normal_power."""

    def validate(self) -> None:
        """Raise DiviewerError naming the field that is out of range."""
        r = self.resolution
        if not (16 <= r <= 256 and r & (r - 1) == 0):
            raise DiviewerError(f"must be a power of two from 16 to 256, got {r}", field="vxgi.resolution")
        if not 1 <= self.cones <= MAX_CONES:
            raise DiviewerError(f"must be 1 to {MAX_CONES}, got {self.cones}", field="vxgi.cones")
        if not 0.0 < self.aperture < 180.0:
            raise DiviewerError(f"must be in (0, 180) degrees, got {self.aperture}", field="vxgi.aperture")
        if not 0.05 <= self.step <= 8.0:
            raise DiviewerError(f"must be in [0.05, 8], got {self.step}", field="vxgi.step")
        if not 0.0 <= self.offset <= 16.0:
            raise DiviewerError(f"must be in [0, 16] voxels, got {self.offset}", field="vxgi.offset")
        if not (0.0 < self.max_distance <= 2.0 and 0.0 <= self.ao_distance <= 2.0):
            raise DiviewerError("max_distance must be in (0, 2] and ao_distance in [0, 2] (fractions of the grid)",
                                field="vxgi.max_distance")
        if self.bounces not in (1, 2):
            raise DiviewerError(f"must be 1 or 2, got {self.bounces}", field="vxgi.bounces")
        if not (isinstance(self.trace_scale, int) and 1 <= self.trace_scale <= 8):
            raise DiviewerError(f"must be an integer from 1 to 8, got {self.trace_scale}", field="vxgi.trace_scale")
        if self.depth_sigma <= 0.0 or self.normal_power < 0.0:
            raise DiviewerError("depth_sigma must be > 0 and normal_power >= 0", field="vxgi.depth_sigma")


def cone_layout(cones: int, aperture: float) -> tuple[np.ndarray, np.ndarray]:
    """Cone axes in tangent space (z = normal) and their weights.

    A cone's weight is the cosine-weighted share of the hemisphere whose directions lie closer to its
    axis than to any other (6 cones of 60 degrees: 0.277 for the normal cone, 0.145 for each of the
    ring, near the usual 1/4 and 3/20), so the weights sum to 1 and a uniform sky of radiance L gives
    indirect = L.
    """
    if cones == 1:
        dirs = np.array([[0.0, 0.0, 1.0]])
    else:
        # The ring's cones reach the horizon; wider than 90 degrees they would reach below it.
        theta = math.radians(90.0 - aperture / 2.0 if aperture <= 90.0 else 45.0)
        phi = 2.0 * math.pi * np.arange(cones - 1) / (cones - 1)
        ring = np.stack([math.sin(theta) * np.cos(phi), math.sin(theta) * np.sin(phi),
                         np.full(cones - 1, math.cos(theta))], axis=1)
        dirs = np.vstack([[0.0, 0.0, 1.0], ring])
    # Uniform points on the unit disk lifted to the hemisphere are cosine-distributed (Malley).
    g = (np.arange(256) + 0.5) / 128.0 - 1.0
    x, y = np.meshgrid(g, g)
    inside = x * x + y * y < 1.0
    d = np.stack([x[inside], y[inside], np.sqrt(1.0 - x[inside] ** 2 - y[inside] ** 2)], axis=1)
    owner = np.argmax(d @ dirs.T, axis=1)
    weights = np.bincount(owner, minlength=len(dirs)) / len(d)
    return dirs.astype("f4"), weights.astype("f4")


class VXGIPass(VoxelGridPasses):
    """VXGI over a Renderer's frame: call ``run(config)`` after ``renderer.render(config)``."""

    def __init__(self, ctx: moderngl.Context, renderer: Renderer, settings: VXGISettings = VXGISettings(),
                 timer: StageTimer | None = None):
        settings.validate()
        self.ctx, self.renderer, self.settings = ctx, renderer, settings
        self.timer = timer or renderer.timer
        """Each stage is timed here (the renderer's timer unless given one)."""
        self.shaders = renderer.shaders
        # The injection reads the sun's map over the whole grid, not the view: whole maps while this pass lives (the
        # viewer's, from the first VXGI frame to the scene's change), the renderer's choice again at its release.
        self._footprint_before, renderer.shadow_footprint = renderer.shadow_footprint, False
        res = settings.resolution
        self.levels = int(math.log2(res)) + 1
        self.voxels = ctx.texture3d((res, res, res), 4, dtype="f2")
        self.voxels.write(bytes(res ** 3 * 8))  # level 0 starts empty; resolve and clear keep it right
        self.voxels.build_mipmaps()  # allocates the levels; the mip pass fills them
        self.voxels.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self.voxels.repeat_x = self.voxels.repeat_y = self.voxels.repeat_z = False
        self.aniso: list[moderngl.Texture3D] = []
        if settings.anisotropic:  # for cones travelling +x, -x, +y, -y, +z, -z; grid levels 1 and up
            for _ in range(6):
                t = ctx.texture3d((res // 2,) * 3, 4, dtype="f2")
                t.build_mipmaps()
                t.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
                t.repeat_x = t.repeat_y = t.repeat_z = False
                self.aniso.append(t)
        self._defines = {"ANISO": 1} if settings.anisotropic else {}
        self._sums = ctx.buffer(reserve=res ** 3 * _SUM_UINTS * 4)
        self._sums.clear()
        self._raster = ctx.renderbuffer((res, res), 1, dtype="f1")
        self._raster_fbo = ctx.framebuffer([self._raster])
        self._raster_fbo.color_mask = (False, False, False, False)
        self._lists = {"static": FragmentList(ctx, 4 * res * res), "dynamic": FragmentList(ctx, res * res)}
        self._keys: dict[str, object] = {}
        self._vaos: dict[int, moderngl.VertexArray] = {}
        self.dirs, self.weights = cone_layout(settings.cones, settings.aperture)
        self.grid_min = np.zeros(3)
        self.grid_size = 1.0
        self.timings: dict[str, float] = {}
        """The last run's stage times (ms), also added to ``timer``."""
        self.updated: tuple[str, ...] = ()
        """What the last run redid: a subset of ('static', 'dynamic', 'inject')."""
        self.width = self.height = 0
        self.textures: dict[str, moderngl.Texture] = {}

    @property
    def scene(self):
        """The renderer's scene (the viewer swaps it when meshes are added)."""
        return self.renderer.scene

    # --- resources ------------------------------------------------------------------------------
    def _ensure_targets(self) -> None:
        w, h = self.renderer.width, self.renderer.height
        if (w, h) == (self.width, self.height):
            return
        if self.width:
            self._release_targets()
        self.width, self.height = w, h
        s = self.settings.trace_scale
        tw, th = -(-w // s), -(-h // s)
        ctx = self.ctx
        self.textures = {"trace": ctx.texture((tw, th), 4, dtype="f4"), "geom": ctx.texture((tw, th), 4, dtype="f4"),
                         "gi": ctx.texture((w, h), 4, dtype="f4") if s > 1 else None,
                         "vxgi": ctx.texture((w, h), 4, dtype="f4"), "vxgi_indirect": ctx.texture((w, h), 4, dtype="f4")}
        if s == 1:
            self.textures["gi"] = self.textures["trace"]
        for t in self.textures.values():
            t.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._trace_fbo = ctx.framebuffer([self.textures["trace"], self.textures["geom"]])
        self._upsample_fbo = ctx.framebuffer([self.textures["gi"]]) if s > 1 else None
        self._composite_fbo = ctx.framebuffer([self.textures["vxgi"], self.textures["vxgi_indirect"]])

    def _release_targets(self) -> None:
        unbind_framebuffer(self.ctx)
        for f in (self._trace_fbo, self._upsample_fbo, self._composite_fbo):
            if f is not None:
                f.release()
        for t in {id(t): t for t in self.textures.values()}.values():
            t.release()
        self.textures = {}

    def release(self) -> None:
        self.renderer.shadow_footprint = self._footprint_before
        if self.width:
            self._release_targets()
        unbind_framebuffer(self.ctx)
        for r in (self._raster_fbo, self._raster, self._sums, self.voxels, *self.aniso, *self._vaos.values()):
            r.release()
        for lst in self._lists.values():
            lst.release()

    def invalidate(self) -> None:
        """Forget the cached grid: the next run voxelizes and injects everything (for benchmarks)."""
        self._keys.clear()

    # --- the frame ------------------------------------------------------------------------------
    def run(self, config: FrameConfig | None = None) -> dict[str, moderngl.Texture]:
        """Update the grid where the frame changed, trace and composite; returns the named textures.

        The renderer must have rendered ``config`` (its G-buffer and direct light are read).
        """
        config = config or self.scene.default
        self.renderer.ensure_direct()  # read by the composite; a stage of its own, so not inside one of these
        before = {k: self.timer.times.get(k, 0.0) for k in STAGES}
        self._ensure_targets()
        grid = self._fit_grid(config)
        moving = set(self.scene.ranges.objects)
        parts = {"static": [o for o in config.objects if o.name not in moving],
                 "dynamic": [o for o in config.objects if o.name in moving]}
        updated = []
        for part, objects in parts.items():
            key = (grid, self._objects_key(objects))
            if self._keys.get(part) != key:
                with self.timer.stage("vxgi_voxelize", gpu=True):
                    self._voxelize(self._lists[part], objects)
                self._keys[part] = key
                updated.append(part)
        # again whenever a map is drawn again: at rest a sun's map is drawn at its full size (`moving_shadow_size`)
        light_key = (config.lights, self.renderer.settings, self.renderer.shadow_renders)
        if updated or self._keys.get("light") != light_key:
            with self.timer.stage("vxgi_inject", gpu=True):
                self._inject(config)
            with self.timer.stage("vxgi_mip", gpu=True):
                self._build_mips()
            if self.settings.bounces > 1:
                with self.timer.stage("vxgi_bounce", gpu=True):
                    self._bounce()
            self._per_fragment("ZERO")
            self._keys["light"] = light_key
            updated.append("inject")
        self.updated = tuple(updated)
        with self.timer.stage("vxgi_trace", gpu=True):
            self._trace(config)
        if self.settings.trace_scale > 1:
            with self.timer.stage("vxgi_upsample", gpu=True):
                self._upsample()
        with self.timer.stage("vxgi_composite", gpu=True):
            self._composite()
        self.timings = {k: self.timer.times.get(k, 0.0) - before[k] for k in STAGES if k in self.timer.times}
        return self.textures

    def _fit_grid(self, config: FrameConfig) -> tuple:
        """A cube around the scene's bounds with one empty voxel of margin on each side."""
        b = self.scene.bounds(config)
        res = self.settings.resolution
        side = max(float((b[1] - b[0]).max()), 1e-3) * res / (res - 2)
        self.grid_min = (b[0] + b[1]) / 2.0 - side / 2.0
        self.grid_size = side
        return (*(float(x) for x in self.grid_min), side)

    def _objects_key(self, objects: list[Object]) -> tuple:
        # Materials and meshes are compared by identity: the viewer swaps in new ones when edited.
        keys = [(o, id(self.scene.materials[o.material]), id(self.renderer.gpu.meshes[o.mesh])) for o in objects]
        return tuple(sorted(keys, key=lambda k: (k[0].name, repr(k[0]))))

    def _grid_uniforms(self, prog) -> None:
        set_uniform(prog, "u_grid_min", tuple(float(x) for x in self.grid_min))
        set_uniform(prog, "u_grid_size", float(self.grid_size))
        set_uniform(prog, "u_res", int(self.settings.resolution))

    def _fullscreen(self, prog: moderngl.Program) -> None:
        if prog.glo not in self._vaos:
            self._vaos[prog.glo] = self.ctx.vertex_array(prog, [])
        self._vaos[prog.glo].render(moderngl.TRIANGLES, vertices=3)

    def _cone_uniforms(self, prog, unit: int) -> None:
        """The uniforms of vxgi_cone.glsl; the grid is bound to texture ``unit``."""
        s = self.settings
        self.voxels.use(location=unit)
        set_uniform(prog, "u_voxels", unit)
        for i, (t, name) in enumerate(zip(self.aniso, ("px", "nx", "py", "ny", "pz", "nz"))):
            t.use(location=unit + 1 + i)
            set_uniform(prog, f"u_aniso_{name}", unit + 1 + i)
        set_uniform(prog, "u_grid_min", tuple(float(x) for x in self.grid_min))
        set_uniform(prog, "u_grid_size", float(self.grid_size))
        set_uniform(prog, "u_voxel", float(self.grid_size / s.resolution))
        set_uniform(prog, "u_max_lod", float(self.levels - 1))
        set_uniform(prog, "u_cones", int(s.cones))
        dirs = np.zeros((MAX_CONES, 3), "f4")
        dirs[:s.cones] = self.dirs
        weights = np.zeros(MAX_CONES, "f4")
        weights[:s.cones] = self.weights
        prog["u_cone_dirs"].write(dirs.tobytes())
        prog["u_cone_weights"].write(weights.tobytes())
        set_uniform(prog, "u_tan_half_aperture", math.tan(math.radians(s.aperture) / 2.0))
        set_uniform(prog, "u_step", float(s.step))
        set_uniform(prog, "u_offset", float(s.offset))
        set_uniform(prog, "u_lift", float(s.lift))
        set_uniform(prog, "u_lod_bias", float(s.lod_bias))
        set_uniform(prog, "u_max_dist", float(s.max_distance * self.grid_size))
        set_uniform(prog, "u_ao_dist", float(s.ao_distance * self.grid_size))
        set_uniform(prog, "u_ambient", tuple(float(x) for x in self.scene.ambient))

    def _trace(self, config: FrameConfig) -> None:
        s, r = self.settings, self.renderer
        prog = self.shaders.program("vxgi_trace.glsl", self._defines)
        self._trace_fbo.use()
        self.ctx.enable_only(moderngl.NOTHING)
        r.textures["depth"].use(location=0)
        r.textures["normal"].use(location=1)
        set_uniform(prog, "u_depth", 0)
        set_uniform(prog, "u_normal", 1)
        view = config.camera.view_matrix()
        t = math.tan(math.radians(config.camera.fov) / 2.0)
        set_uniform(prog, "m_inv_view", cam.view_to_world(view))
        set_uniform(prog, "u_tan_half_fov", (t * r.width / r.height, t))
        set_uniform(prog, "u_scale", int(s.trace_scale))
        self._cone_uniforms(prog, 2)
        self._fullscreen(prog)

    def _upsample(self) -> None:
        s, r = self.settings, self.renderer
        prog = self.shaders.program("vxgi_upsample.glsl")
        self._upsample_fbo.use()
        self.ctx.enable_only(moderngl.NOTHING)
        for i, tex in enumerate((r.textures["depth"], r.textures["normal"], self.textures["trace"], self.textures["geom"])):
            tex.use(location=i)
        for i, name in enumerate(("u_depth", "u_normal", "u_gi", "u_geom")):
            set_uniform(prog, name, i)
        set_uniform(prog, "u_scale", int(s.trace_scale))
        set_uniform(prog, "u_depth_sigma", float(s.depth_sigma))
        set_uniform(prog, "u_normal_power", float(s.normal_power))
        self._fullscreen(prog)

    def _composite(self) -> None:
        r = self.renderer
        prog = self.shaders.program("vxgi_composite.glsl")
        self._composite_fbo.use()
        self.ctx.enable_only(moderngl.NOTHING)
        for i, tex in enumerate((r.textures["direct"], r.textures["albedo"], self.textures["gi"])):
            tex.use(location=i)
        for i, name in enumerate(("u_direct", "u_albedo", "u_gi")):
            set_uniform(prog, name, i)
        self._fullscreen(prog)

    # --- read-back ------------------------------------------------------------------------------
    def read(self, name: str) -> np.ndarray:
        """A result as float32, top row first: ``vxgi``, ``vxgi_indirect``, ``indirect`` (E / pi), each
        (H, W, 3), or ``ao`` (H, W)."""
        if name in ("indirect", "ao"):
            tex = self.textures["gi"]
        elif name in ("vxgi", "vxgi_indirect"):
            tex = self.textures[name]
        else:
            raise KeyError(f"no VXGI buffer named {name!r}")
        raw = np.frombuffer(tex.read(), dtype="f4").reshape(self.height, self.width, 4)
        out = raw[..., 3] if name == "ao" else raw[..., :3]
        return np.ascontiguousarray(np.flipud(out))

    def read_grid(self) -> np.ndarray:
        """The grid's level 0 as float32 (z, y, x, 4): premultiplied radiance and coverage."""
        side = self.settings.resolution
        raw = np.frombuffer(self.voxels.read(), dtype="f2")
        return raw.reshape(side, side, side, 4).astype("f4")

    @property
    def fragment_counts(self) -> dict[str, int]:
        return {k: lst.count for k, lst in self._lists.items()}
