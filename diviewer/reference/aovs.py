"""Mitsuba AOVs (depth, normals, albedo) that see through alpha-masked surfaces, as the G-buffer does.

Mitsuba's ``aov`` integrator stops at the first surface, also where a ``mask`` BSDF is fully transparent,
so a cut-out leaf would show in its albedo where the G-buffer shows what lies behind. This traces the
same camera rays itself: at each hit a masked surface lets the ray through with probability
``1 - opacity`` (the ``mask`` BSDF's null transmission, as the path tracer treats it) and the first
surface that stops the ray is recorded. Samples are stratified in the pixel and box-filtered, like the
``aov`` integrator with the sensor's box filter. Output channels are those of ``AOV_CHANNELS``:
depth from the near plane, shading normal, geometric normal, albedo.
"""

from __future__ import annotations

import math

import numpy as np

MAX_LAYERS = 64
"""Masked surfaces a ray may pass before it is recorded as a miss (Sponza's plants: a handful)."""


def _pixel_samples(width: int, height: int, spp: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Film positions in [0, 1]^2 (row 0 at the top): spp jittered strata per pixel (random if spp is not square)."""
    rng = np.random.default_rng([int(seed), 0xA0])
    n = math.isqrt(spp)
    jitter = rng.random((height, width, spp, 2))
    if n * n == spp:
        k = np.arange(spp)
        jitter = (np.stack([k % n, k // n], axis=-1) + jitter) / n
    x = (np.arange(width)[None, :, None] + jitter[..., 0]) / width
    y = (np.arange(height)[:, None, None] + jitter[..., 1]) / height
    return x.ravel().astype(np.float32), y.ravel().astype(np.float32)


def _trace(mi, dr, scene, ray, u_stream):
    """First non-transmitting hit of each ray: (distance, shading normal, geometric normal, albedo)."""
    active = mi.Bool(True)
    total = mi.Float(0.0)
    out_t = mi.Float(0.0)
    zero = mi.Vector3f(0.0)
    out_sn, out_gn, out_al = zero, zero, mi.Color3f(0.0)
    for _ in range(MAX_LAYERS):
        si = scene.ray_intersect(ray, active)
        hit = active & si.is_valid()
        bsdf = si.bsdf(ray)
        through = hit & (u_stream() < bsdf.eval_null_transmission(si, hit)[0])
        stop = dr.select(through, False, hit)  # hit & ~through; ~ on a Python bool (scalar_rgb) is an int
        out_t = dr.select(stop, total + si.t, out_t)
        out_sn = dr.select(stop, si.sh_frame.n, out_sn)
        out_gn = dr.select(stop, si.n, out_gn)
        out_al = dr.select(stop, bsdf.eval_diffuse_reflectance(si, stop), out_al)
        total = dr.select(through, total + si.t, total)
        ray = dr.select(through, si.spawn_ray(ray.d), ray)
        active = through
        if not dr.any(active):
            break
    return out_t, out_sn, out_gn, out_al


def trace_aovs(mi_scene, width: int, height: int, spp: int, seed: int) -> np.ndarray:
    """(H, W, 10) float32: depth, shading normal, geometric normal, albedo (the ``aov`` integrator's layout)."""
    import drjit as dr
    import mitsuba as mi

    sensor = mi_scene.sensors()[0]
    xs, ys = _pixel_samples(width, height, spp, seed)
    if mi.variant().startswith("scalar"):
        # One ray at a time: the same code on Python scalars (slow; llvm_ad_rgb traces them all at once).
        rng = np.random.default_rng([int(seed), 0xA1])
        rows = []
        for x, y in zip(xs, ys):
            ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(float(x), float(y)), mi.Point2f(0.5, 0.5))
            t, sn, gn, al = _trace(mi, dr, mi_scene, mi.Ray3f(ray), lambda: float(rng.random()))
            rows.append([t, *sn, *gn, *al])
        flat = np.asarray(rows, dtype=np.float32)
    else:
        ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5), mi.Point2f(mi.Float(xs), mi.Float(ys)),
                                   mi.Point2f(0.5, 0.5))
        pcg = mi.PCG32(size=len(xs), initstate=int(seed))
        t, sn, gn, al = _trace(mi, dr, mi_scene, mi.Ray3f(ray), pcg.next_float32)
        channels = (t, sn.x, sn.y, sn.z, gn.x, gn.y, gn.z, al.x, al.y, al.z)
        flat = np.stack([np.asarray(c) for c in channels], axis=-1).astype(np.float32)
    return flat.reshape(height, width, spp, 10).mean(axis=2)
