"""Mitsuba 3 path-traced reference: a Scene + FrameConfig translated to a Mitsuba scene, same camera as GL.

Usage::

    from diviewer.reference.mitsuba import render_full, render_direct, render_aovs
    rgb = render_full(scene, config, 256, 256, spp=256, seed=0)      # (H, W, 3) float32, top row first

Camera matching (the one source of truth is diviewer.scene.camera):

- ``to_world`` is ``view_to_world(look_at(...)) @ diag(-1, 1, -1, 1)``: Mitsuba's camera looks down its
  local +z with local +x to the image's *left*; GL's looks down -z with +x to the right. The flip is a
  180 degree turn about the camera's y axis (a rotation, not a mirror) and is exactly Mitsuba's own
  ``look_at`` for the same eye, target and up.
- ``fov_axis = 'y'`` (Mitsuba's default is x), the same near and far clip, and a box pixel filter of
  radius 0.5: pixel (i, j) integrates the square ``[j, j+1] x [i, i+1]`` whose centre is GL's sample.
- Mitsuba's film rows already run top to bottom, as every image of this package does: no flip.
- Mitsuba's ``depth`` AOV is the ray distance from the near-clip plane (its rays start there), so
  ``z_view = depth / |d| + near`` with ``d`` the pixel-centre direction scaled to unit -z.
- Texture coordinates: GL samples ``t = 0`` at the image's bottom row, Mitsuba's ``bitmap`` samples
  ``v = 0`` at its first (top) row; meshes get ``v' = 1 - v``.

- Alpha-masked materials (glTF MASK): a ``mask`` BSDF with the thresholded alpha as opacity, rendered
  with ``volpath`` (``path_integrator``); AOVs then come from ``reference/aovs.py``, which sees through
  cut-out texels as the G-buffer does. The variant machinery is in ``reference/variant.py``.

What the reference contains that the GL direct pass does not (by design, it is the ground truth):
light bounced between surfaces, exact hard shadows, light from emissive surfaces and from the ambient
sky (``constant`` emitter) falling on other surfaces, and the sky's radiance in background pixels.
"""

from __future__ import annotations

import time

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.reference.variant import (  # noqa: F401 (re-exported: the variant is part of this API)
    VARIANTS, VariantInfo, current_variant, import_mitsuba, find_libllvm, select_variant, variant_info,
)
from diviewer.scene import camera as cam
from diviewer.scene.model import DirectionalLight, FrameConfig, PointLight, Scene

DEFAULT_MAX_DEPTH = 16
"""Path length limit of the full reference (2 = direct light only). In the Cornell box each bounce
keeps at most ~0.6 of the energy (albedo 0.73, some escapes through the open front), so the light
beyond 15 bounces is < 0.6^15 ~ 5e-4 of the first bounce (measured: the image mean at max_depth 64
differs by 1e-5 relative), far below the noise at any spp we render."""

DEFAULT_RR_DEPTH = 5
"""Russian roulette from this path length on (Mitsuba's default). Roulette is unbiased and, measured on
the Cornell box (128 px), cheaper per unit of noise than none: at equal time +1.4 to +1.8 dB PSNR with
llvm_ad_rgb (a vectorised path only stops when all its lanes stop) and +0.3 dB with scalar_rgb, for
~1.1 dB more noise per sample. ``path_integrator(max_depth, rr_depth=max_depth)`` turns it off."""

# --- translation ------------------------------------------------------------------------------------------------

_FLIP_XZ = np.diag([-1.0, 1.0, -1.0, 1.0])
"""GL camera frame (x right, y up, looking down -z) to Mitsuba's (x left, y up, looking down +z)."""


def camera_to_world(config: FrameConfig) -> np.ndarray:
    """Mitsuba sensor ``to_world`` (4x4) for the frame's camera, derived from the GL view matrix."""
    return cam.view_to_world(config.camera.view_matrix()) @ _FLIP_XZ


def _rgb(value) -> dict:
    return {"type": "rgb", "value": [float(c) for c in value]}


def _is_closed(vertices: np.ndarray, faces: np.ndarray) -> bool:
    """Whether a triangle mesh is closed once coincident vertices (crease splits) are merged."""
    import trimesh

    return bool(trimesh.Trimesh(vertices, faces, process=True).is_watertight)


def _mesh(mi, key: str, vertices, normals, faces, uvs, bsdf, emitter):
    props = mi.Properties()
    props["bsdf"] = bsdf
    if emitter is not None:
        props["emitter"] = emitter
    mesh = mi.Mesh(key, len(vertices), len(faces), props=props, has_vertex_normals=True,
                   has_vertex_texcoords=uvs is not None)
    params = mi.traverse(mesh)
    arrays = {"vertex_positions": np.asarray(vertices, np.float32), "vertex_normals": np.asarray(normals, np.float32),
              "faces": np.asarray(faces, np.uint32)}
    if uvs is not None:
        arrays["vertex_texcoords"] = np.asarray(uvs, np.float32)
    for name, arr in arrays.items():
        # The buffer's own type: dr.scalar.ArrayXf/ArrayXu (scalar_rgb) or mi.Float/UInt32 (llvm_ad_rgb).
        params[name] = type(params[name])(np.ascontiguousarray(arr).ravel())
    params.update()
    return mesh


def _check_supported(scene: Scene, config: FrameConfig) -> None:
    """Refuse, naming it, anything the translation cannot represent (never drop it silently)."""
    for light in config.lights:
        if not isinstance(light, (DirectionalLight, PointLight)):
            kind = getattr(light, "kind", type(light).__name__)
            raise DiviewerError(f"light '{getattr(light, 'name', '?')}' is of type '{kind}', which the Mitsuba "
                                f"reference cannot represent (it supports directional and point lights)",
                                field="lights")
        if min(light.color) < 0.0:
            raise DiviewerError(f"light '{light.name}' has a negative colour {light.color}, which Mitsuba cannot "
                                f"represent", field="lights")
    if min(scene.ambient) < 0.0:
        raise DiviewerError(f"negative ambient radiance {scene.ambient} cannot be represented", field="scene.ambient")
    for obj in config.objects:
        if obj.mesh not in scene.meshes:
            raise DiviewerError(f"object '{obj.name}' uses unknown mesh '{obj.mesh}'", field="objects")
        if obj.material not in scene.materials:
            raise DiviewerError(f"object '{obj.name}' uses unknown material '{obj.material}'", field="objects")
        mat = scene.materials[obj.material]
        if min(mat.albedo) < 0.0 or max(mat.albedo) > 1.0:
            raise DiviewerError(f"material '{mat.name}' has albedo {mat.albedo} outside [0, 1]", field="materials")
        if mat.is_emissive:
            mesh = scene.meshes[obj.mesh]
            if not _is_closed(mesh.vertices, mesh.faces):
                raise DiviewerError(
                    f"object '{obj.name}' has emissive material '{mat.name}' on the open mesh '{obj.mesh}': "
                    f"Mitsuba's area emitters emit from the front side only, while the GL renderer shows "
                    f"emission on both sides; use a closed mesh (a thin box) for emitters", field="materials")


def to_mitsuba_dict(scene: Scene, config: FrameConfig, width: int, height: int, *, spp: int, seed: int,
                    integrator: dict | None = None) -> dict:
    """The frame as a ``mi.load_dict`` dict (meshes are ready ``mi.Mesh`` objects of the current variant).

    Args:
        spp: samples per pixel of the sensor's sampler (``mi.render`` may override it).
        seed: the sampler's seed (``mi.render`` may override it).
        integrator: a Mitsuba integrator dict; default the full path tracer (``DEFAULT_MAX_DEPTH``).

    Raises:
        DiviewerError: for anything Mitsuba cannot represent, naming it.
    """
    if width < 1 or height < 1:
        raise ValueError(f"render size must be at least 1x1, got {width}x{height}")
    mi = import_mitsuba()
    current_variant(mi)
    _check_supported(scene, config)
    c = config.camera
    out: dict = {
        "type": "scene",
        "integrator": integrator or path_integrator(DEFAULT_MAX_DEPTH, masked=has_masks(scene, config)),
        "sensor": {
            "type": "perspective",
            "fov": float(c.fov),
            "fov_axis": "y",
            "near_clip": float(c.near),
            "far_clip": float(c.far),
            "to_world": mi.ScalarTransform4f(camera_to_world(config).tolist()),
            "sampler": {"type": SAMPLER, "sample_count": int(spp), "seed": int(seed)},
            "film": {"type": "hdrfilm", "width": int(width), "height": int(height), "rfilter": {"type": "box"},
                     "pixel_format": "rgb", "component_format": "float32"},
        },
    }
    bsdfs: dict[str, object] = {}
    for i, obj in enumerate(config.objects):
        mat = scene.materials[obj.material]
        mesh = scene.meshes[obj.mesh]
        if obj.material not in bsdfs:
            bsdfs[obj.material] = mi.load_dict(_bsdf(mi, mat))
        m = obj.matrix()
        v = mesh.vertices.astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        n = mesh.normals.astype(np.float64) @ cam.normal_matrix(m).T
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
        faces = mesh.faces
        if np.linalg.det(m[:3, :3]) < 0.0:
            faces = faces[:, ::-1]  # a mirroring pose reverses the winding; keep it consistent with the normals
        uvs = None
        if mesh.uvs is not None:
            uvs = np.stack([mesh.uvs[:, 0], 1.0 - mesh.uvs[:, 1]], axis=1)
        elif mat.texture is not None or mat.emission_texture is not None:
            # GL feeds uv = (0, 0) to meshes without uvs; Mitsuba would use barycentrics instead.
            uvs = np.tile(np.float32([0.0, 1.0]), (len(mesh.vertices), 1))
        emitter = mi.load_dict({"type": "area", "radiance": _radiance(mi, mat)}) if mat.is_emissive else None
        out[f"object_{i}"] = _mesh(mi, obj.name, v, n, faces, uvs, bsdfs[obj.material], emitter)
    for i, light in enumerate(config.lights):
        out[f"light_{i}"] = _emitter(light)
    if max(scene.ambient) > 0.0:
        out["ambient"] = {"type": "constant", "radiance": _rgb(scene.ambient)}
    return out


def _bitmap(mi, data: np.ndarray, filter_type: str = "bilinear") -> dict:
    """A ``bitmap`` texture of raw linear values (top row first), repeating as GL's textures do."""
    return {"type": "bitmap", "data": mi.TensorXf(np.ascontiguousarray(data, dtype=np.float32)), "raw": True,
            "wrap_mode": "repeat", "filter_type": filter_type}


def _bsdf(mi, mat) -> dict:
    """A material's two-sided diffuse BSDF: albedo times its texture, cut out by its alpha mask."""
    # The albedo multiplies the texture; linear scaling commutes with bilinear filtering.
    refl = _rgb(mat.albedo) if mat.texture is None else _bitmap(mi, mat.texture * np.asarray(mat.albedo, np.float32))
    bsdf = {"type": "twosided", "material": {"type": "diffuse", "reflectance": refl}}
    if mat.is_masked:
        # Alpha-tested (glTF MASK): opaque where the alpha passes the cutoff, absent elsewhere.
        # Nearest texels of the binary mask: Mitsuba reads a fractional opacity as partial
        # coverage, GL's test is binary; for a binary mask the edge of GL's test on the bilinear
        # alpha is the texel boundary, where nearest lookup puts it too.
        bsdf = {"type": "mask", "material": bsdf,
                "opacity": _bitmap(mi, (mat.alpha >= mat.alpha_cutoff)[..., None], "nearest")}
    return bsdf


def _radiance(mi, mat) -> dict:
    """An emissive material's radiance: its emission, times its emission texture (raw linear values at the mesh's
    uvs, as the G-buffer samples it) where it has one."""
    if mat.emission_texture is None:
        return _rgb(mat.emission)
    return _bitmap(mi, mat.emission_texture * np.asarray(mat.emission, np.float32))


def _emitter(light) -> dict:
    """A light as a Mitsuba emitter dict (directional: irradiance; point: intensity)."""
    if isinstance(light, DirectionalLight):
        return {"type": "directional", "direction": [float(x) for x in cam.normalize(light.direction)],
                "irradiance": _rgb(np.asarray(light.color) * light.irradiance)}
    return {"type": "point", "position": [float(x) for x in light.position],
            "intensity": _rgb(np.asarray(light.color) * light.intensity)}


def path_integrator(max_depth: int, rr_depth: int | None = None, masked: bool = False) -> dict:
    """Mitsuba's ``path`` integrator; ``max_depth = 2`` is direct light only.

    Args:
        masked: the frame has alpha-masked surfaces. ``path`` lets their shadow rays be blocked by fully
            transparent texels and counts a crossing as a bounce (measured: a quad of opacity 0 above a
            lit floor leaves it black at max_depth 2 and 3); ``volpath``, without media the same
            estimator, passes shadow rays through ``mask`` surfaces and does not count the crossing.
    """
    if max_depth < 1:
        raise ValueError(f"max_depth must be >= 1, got {max_depth}")
    rr = DEFAULT_RR_DEPTH if rr_depth is None else rr_depth
    if rr < 1:
        raise ValueError(f"rr_depth must be >= 1, got {rr}")
    return {"type": "volpath" if masked else "path", "max_depth": int(max_depth), "rr_depth": int(rr),
            "hide_emitters": False}


def has_masks(scene: Scene, config: FrameConfig) -> bool:
    """Whether any object of the frame wears an alpha-masked material."""
    return any(scene.materials[o.material].is_masked for o in config.objects)


SAMPLER = "multijitter"
"""Correlated multi-jittered sampling: at the same time per frame ~3.5 dB less noise than ``independent``
on the Cornell box (128 px, 64 spp, no roulette: 35.4 vs 31.9 dB between seeds), and pixel-footprint
averages of the AOVs within 0.11 % of the pixel centre's value at 16 spp (independent: ~1 %). It rounds some sample counts up (128 -> 132): the
effective count is what renders use and what frame.json records (``effective_spp``)."""
AOV_CHANNELS = "dd:depth,nn:sh_normal,ng:geo_normal,al:albedo"


# --- rendering --------------------------------------------------------------------------------------------------

def effective_spp(spp: int) -> int:
    """The sample count the sampler really takes for ``spp`` (multijitter rounds some counts up)."""
    if int(spp) < 1:
        raise ValueError(f"spp must be >= 1, got {spp}")
    mi = import_mitsuba()
    current_variant(mi)
    logger = mi.logger() if hasattr(mi, "logger") else mi.Thread.thread().logger()
    level = logger.log_level()
    logger.set_log_level(mi.LogLevel.Error)  # the rounding warning; the caller records the count instead
    try:
        return int(mi.load_dict({"type": SAMPLER, "sample_count": int(spp)}).sample_count())
    finally:
        logger.set_log_level(level)


class MitsubaFrame:
    """One frame loaded into Mitsuba once, rendered any number of times (full, direct, AOVs, seeds)."""

    def __init__(self, scene: Scene, config: FrameConfig, width: int, height: int):
        mi = import_mitsuba()
        self.variant = current_variant(mi)
        self.scene, self.config, self.width, self.height = scene, config, width, height
        self.masked = has_masks(scene, config)
        t0 = time.perf_counter()
        self._mi_scene = mi.load_dict(to_mitsuba_dict(scene, config, width, height, spp=1, seed=0))
        self.load_seconds = time.perf_counter() - t0

    def retarget(self, config: FrameConfig) -> bool:
        """Move the loaded scene's camera and lights to ``config`` in place; False (nothing changed) when
        more than that differs (objects, light types, fov or clip planes), which needs a fresh load.

        Geometry, BSDFs and the BVH stay: on Sponza that saves the ~2 s of a load per captured frame.
        Each light's parameters are copied from a Mitsuba emitter built from the same dict a load uses.
        """
        old = self.config
        c0, c1 = old.camera, config.camera
        if (config.objects != old.objects or (c0.fov, c0.near, c0.far) != (c1.fov, c1.near, c1.far)
                or [(type(a), a.name) for a in old.lights] != [(type(b), b.name) for b in config.lights]):
            return False
        mi = import_mitsuba()
        mi.set_variant(self.variant)
        _check_supported(self.scene, config)
        params = mi.traverse(self._mi_scene)
        params["sensor.to_world"] = mi.ScalarTransform4f(camera_to_world(config).tolist())
        for i, light in enumerate(config.lights):
            emitter = mi.traverse(mi.load_dict(_emitter(light)))
            for k in emitter.keys():
                if f"light_{i}.{k}" in params and k != "sampling_weight":
                    params[f"light_{i}.{k}"] = emitter[k]
        params.update()
        self.config = config
        return True

    def _render(self, integrator: dict, spp: int, seed: int) -> np.ndarray:
        mi = import_mitsuba()
        mi.set_variant(self.variant)
        img = mi.render(self._mi_scene, integrator=mi.load_dict(integrator), spp=effective_spp(spp), seed=int(seed))
        return np.array(img, dtype=np.float32)

    def full(self, spp: int, seed: int, max_depth: int = DEFAULT_MAX_DEPTH) -> np.ndarray:
        """Global illumination: (H, W, 3) linear radiance, top row first."""
        return np.ascontiguousarray(self._render(path_integrator(max_depth, masked=self.masked), spp, seed)[..., :3])

    def direct(self, spp: int, seed: int) -> np.ndarray:
        """Direct light and visible emission only (path length 2)."""
        return self.full(spp, seed, max_depth=2)

    def full_and_direct(self, spp: int, seed: int, max_depth: int = DEFAULT_MAX_DEPTH) -> tuple[np.ndarray,
                                                                                                 np.ndarray, str]:
        """`full` and `direct`, each (H, W, 3), and how they were made: in one pass (`split_path`) where the frame's
        lights allow it and the variant is a JIT one (a Python integrator on ``scalar_rgb`` would run per sample),
        else in two with one seed ("two_passes", as every capture before 2026-11-28)."""
        from diviewer.reference import split_path

        if self._one_pass():
            img = self._render_one_pass(spp, seed, max_depth)
            return np.ascontiguousarray(img[..., :3]), np.ascontiguousarray(img[..., 3:6]), split_path.ONE_PASS
        return self.full(spp, seed, max_depth), self.direct(spp, seed), split_path.TWO_PASSES

    def full_light(self, spp: int, seed: int, max_depth: int = DEFAULT_MAX_DEPTH) -> np.ndarray:
        """The full light alone by the truth's estimator: `full_and_direct`'s first image where it takes one pass
        (its direct part comes with it), else `full` (no direct render)."""
        if self._one_pass():
            return np.ascontiguousarray(self._render_one_pass(spp, seed, max_depth)[..., :3])
        return self.full(spp, seed, max_depth)

    def _one_pass(self) -> bool:
        from diviewer.reference import split_path

        return split_path.supports(self.scene, self.config) and self.variant.startswith(("llvm", "cuda"))

    def _render_one_pass(self, spp: int, seed: int, max_depth: int) -> np.ndarray:
        from diviewer.reference import split_path

        mi = import_mitsuba()
        mi.set_variant(self.variant)
        return self._render(split_path.integrator_dict(mi, max_depth, DEFAULT_RR_DEPTH), spp, seed)

    def aovs(self, spp: int = 16, seed: int = 0) -> dict[str, np.ndarray]:
        """depth (H, W) view-space ``-z``, normal (H, W, 3) view space facing the camera, albedo (H, W, 3).

        Pixel values are box-filtered over the pixel (spp samples); background is 0 like the G-buffer.
        """
        if self.masked:  # the aov integrator would stop at cut-out texels
            from diviewer.reference.aovs import trace_aovs

            import_mitsuba().set_variant(self.variant)
            raw = trace_aovs(self._mi_scene, self.width, self.height, effective_spp(spp), seed)
        else:
            raw = self._render({"type": "aov", "aovs": AOV_CHANNELS}, spp, seed)
        dd, nn, ng, al = raw[..., 0], raw[..., 1:4], raw[..., 4:7], raw[..., 7:10]
        c = self.config.camera
        rays = cam.pixel_rays_view(self.width, self.height, c.fov)  # unit -z through pixel centres
        hit = dd > 0.0
        depth = np.where(hit, dd / np.linalg.norm(rays, axis=-1) + c.near, 0.0)
        rot = c.view_matrix()[:3, :3]
        n_view = nn.astype(np.float64) @ rot.T
        g_view = ng.astype(np.float64) @ rot.T
        # Like gl_FrontFacing: the geometric normal decides which side the camera sees.
        facing = np.sum(g_view * -rays, axis=-1) >= 0.0
        n_view = np.where(facing[..., None], n_view, -n_view)
        norm = np.linalg.norm(n_view, axis=-1, keepdims=True)
        n_view = np.where(norm > 1e-12, n_view / np.maximum(norm, 1e-30), 0.0)
        return {"depth": depth.astype(np.float32), "normal": n_view.astype(np.float32),
                "albedo": np.ascontiguousarray(al, dtype=np.float32)}


_cache: tuple | None = None


def load_frame(scene: Scene, config: FrameConfig, width: int, height: int) -> MitsubaFrame:
    """The loaded Mitsuba scene of a frame; the last one is kept, so full/direct/AOV renders share it.

    A frame of the same scene and size that differs only in camera pose and lights reuses the loaded
    scene (``MitsubaFrame.retarget``): the frame returned before then renders the new configuration.
    """
    global _cache
    mi = import_mitsuba()
    key = (id(scene), config, width, height, current_variant(mi))
    if _cache is not None and _cache[0] == key and _cache[1].scene is scene:
        return _cache[1]
    if _cache is not None:
        prev = _cache[1]
        if (prev.scene is scene and (prev.width, prev.height, prev.variant) == (width, height, key[4])
                and prev.retarget(config)):
            _cache = (key, prev)
            return prev
    frame = MitsubaFrame(scene, config, width, height)
    _cache = (key, frame)
    return frame


def render_full(scene: Scene, config: FrameConfig, width: int, height: int, *, spp: int, seed: int,
                max_depth: int = DEFAULT_MAX_DEPTH) -> np.ndarray:
    """Path-traced global illumination, (H, W, 3) float32 linear radiance, top row first."""
    return load_frame(scene, config, width, height).full(spp, seed, max_depth)


def render_direct(scene: Scene, config: FrameConfig, width: int, height: int, *, spp: int, seed: int) -> np.ndarray:
    """The same path tracer with ``max_depth = 2``: direct light (exact shadows) plus visible emission."""
    return load_frame(scene, config, width, height).direct(spp, seed)


def render_aovs(scene: Scene, config: FrameConfig, width: int, height: int, *, spp: int = 16,
                seed: int = 0) -> dict[str, np.ndarray]:
    """depth, normal and albedo in the G-buffer's conventions (see ``MitsubaFrame.aovs``)."""
    return load_frame(scene, config, width, height).aovs(spp, seed)


def noise_floor(scene: Scene, config: FrameConfig, width: int, height: int, spp: int, seeds=(1, 2), *,
                max_depth: int = DEFAULT_MAX_DEPTH, peak: float = 1.0) -> dict:
    """How far the reference is from itself: PSNR and SSIM between two full renders with different seeds.

    No method can be judged closer to the converged image than this (at this spp). Conventions are
    those of diviewer.metrics (linear radiance; ``peak`` for PSNR and SSIM's data range).
    """
    if len(seeds) != 2 or seeds[0] == seeds[1]:
        raise ValueError(f"noise_floor needs two different seeds, got {seeds}")
    frame = load_frame(scene, config, width, height)
    a = frame.full(spp, seeds[0], max_depth)
    b = frame.full(spp, seeds[1], max_depth)
    return compare_renders(a, b, spp=spp, seeds=seeds, peak=peak)


def compare_renders(a: np.ndarray, b: np.ndarray, *, spp: int, seeds, peak: float = 1.0) -> dict:
    """PSNR/SSIM/MSE of two renders of the same frame (the noise-floor record)."""
    from diviewer import metrics

    return {"spp": int(spp), "seeds": [int(s) for s in seeds], "peak": float(peak),
            "mse": metrics.mse(a, b), "psnr": metrics.psnr(a, b, peak=peak),
            "ssim": metrics.ssim(a, b, data_range=peak)}
