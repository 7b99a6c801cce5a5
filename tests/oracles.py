"""Independent computations the tests check the product against: numpy re-derivations of what the renderer, the
viewer or the path tracer compute another way (kept apart from the package so neither borrows the other's bug)."""

from __future__ import annotations

import numpy as np

from diviewer.scene.camera import look_at, pixel_rays_view, view_to_world


def world_buffers(depth: np.ndarray, normal: np.ndarray, camera: dict, source_size: tuple[int, int],
                  crop_xy: tuple[int, int], center: np.ndarray, half: float) -> tuple[np.ndarray, np.ndarray]:
    """(world position normalised to [-1, 1], world normal), each (H, W, 3) float32, 0 where depth <= 0.

    depth: (H, W) linear view depth (-z); normal: (H, W, 3) view-space normal; camera: position, target,
    up, fov (vertical, degrees); source_size: (width, height) of the render the frame was cropped from;
    crop_xy: the crop's left column and top row in it.
    """
    h, w = depth.shape
    sw, sh = source_size
    x0, y0 = crop_xy
    rays = pixel_rays_view(sw, sh, float(camera["fov"]))[y0:y0 + h, x0:x0 + w]
    inv = view_to_world(look_at(camera["position"], camera["target"], camera["up"]))
    p_view = depth[..., None].astype(np.float64) * rays
    p = p_view @ inv[:3, :3].T + inv[:3, 3]
    n = normal.astype(np.float64) @ inv[:3, :3].T
    geo = (depth > 0)[..., None]
    pos = np.where(geo, np.clip((p - center) / half, -1.0, 1.0), 0.0)
    return pos.astype(np.float32), np.where(geo, n, 0.0).astype(np.float32)


def bilinear(img: np.ndarray, w: int, h: int) -> np.ndarray:
    """GL's LINEAR magnification of an (H, W, C) image to (h, w, C): texel centres, clamped to the edge."""
    H, W = img.shape[:2]
    ys = np.clip((np.arange(h) + 0.5) * H / h - 0.5, 0, H - 1)
    xs = np.clip((np.arange(w) + 0.5) * W / w - 0.5, 0, W - 1)
    y0, x0 = np.floor(ys).astype(int), np.floor(xs).astype(int)
    y1, x1 = np.minimum(y0 + 1, H - 1), np.minimum(x0 + 1, W - 1)
    fy, fx = (ys - y0)[:, None, None], (xs - x0)[None, :, None]
    top = img[y0][:, x0] * (1 - fx) + img[y0][:, x1] * fx
    bottom = img[y1][:, x0] * (1 - fx) + img[y1][:, x1] * fx
    return (top * (1 - fy) + bottom * fy).astype(np.float32)


def centre_depth(scene, config, width: int, height: int) -> np.ndarray:
    """(H, W) view-space depth (-z) of the first surface Mitsuba's rays through the pixel centres stop at,
    passing cut-out texels as the path tracer does; 0 where they miss (as the G-buffer)."""
    import drjit as dr
    import mitsuba as mi

    from diviewer.reference import mitsuba as ref
    from diviewer.reference.aovs import _trace
    from diviewer.scene import camera as cam

    frame = ref.MitsubaFrame(scene, config, width, height)
    mi.set_variant(frame.variant)
    sensor = frame._mi_scene.sensors()[0]
    ys, xs = np.mgrid[0:height, 0:width]
    fx = ((xs + 0.5) / width).ravel().astype(np.float32)
    fy = ((ys + 0.5) / height).ravel().astype(np.float32)
    if mi.variant().startswith("scalar"):
        t = []
        for x, y in zip(fx, fy):
            ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(float(x), float(y)), mi.Point2f(0.5, 0.5))
            t.append(float(_trace(mi, dr, frame._mi_scene, mi.Ray3f(ray), lambda: 0.5)[0]))
        t = np.asarray(t, np.float64).reshape(height, width)
    else:
        ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5), mi.Point2f(mi.Float(fx), mi.Float(fy)),
                                   mi.Point2f(0.5, 0.5))
        # opacity is 0 or 1 (thresholded): any uniform number lets a ray through exactly the cut-out texels
        t = np.asarray(_trace(mi, dr, frame._mi_scene, mi.Ray3f(ray), lambda: mi.Float(0.5))[0],
                       np.float64).reshape(height, width)
    c = config.camera
    rays = cam.pixel_rays_view(width, height, c.fov)
    return np.where(t > 0.0, t / np.linalg.norm(rays, axis=-1) + c.near, 0.0)


def split_path_renders(frame, spp: int, seeds: range, one_pass: bool) -> np.ndarray:
    """(R, 2, H, W, 3): full and direct light per seed, by the one-pass estimator or the two passes it replaces."""
    out = []
    for seed in seeds:
        out.append(np.stack(frame.full_and_direct(spp, seed)[:2] if one_pass else
                            (frame.full(spp, seed), frame.direct(spp, seed))))
    return np.stack(out)


def split_path_compare(a: np.ndarray, b: np.ndarray) -> dict:
    """Per channel (full, direct, indirect): two estimators' frame means, their relative difference and its z over
    the seeds, per-pixel z statistics, and the largest difference at the same seed."""
    out = {}
    for name, x, y in (("full", a[:, 0], b[:, 0]), ("direct", a[:, 1], b[:, 1]),
                       ("indirect", a[:, 0] - a[:, 1], b[:, 0] - b[:, 1])):
        r = len(x)
        mx, my = x.mean(axis=(1, 2, 3)), y.mean(axis=(1, 2, 3))  # per seed
        se = np.sqrt(mx.var(ddof=1) / r + my.var(ddof=1) / r)
        diff = mx.mean() - my.mean()
        px_se = np.sqrt(x.var(axis=0, ddof=1) / r + y.var(axis=0, ddof=1) / r)
        varying = px_se > 1e-4 * max(float(my.mean()), 1e-30)  # above float round-off of the frame's level
        z = (x.mean(axis=0) - y.mean(axis=0))[varying] / px_se[varying]
        out[name] = {"relative_difference": float(diff / my.mean()) if my.mean() > 0 else None,
                     "z": float(diff / se) if se > 0 else None,
                     "pixel_z_mean": float(z.mean()) if z.size else None,
                     "pixel_z_std": float(z.std()) if z.size else None,
                     "same_seed_max_difference": float(np.abs(x - y).max() / max(float(my.mean()), 1e-30))}
    return out
