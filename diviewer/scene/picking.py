"""Picking: which object a pixel shows, by casting a ray against the scene's triangles on the CPU. No GL."""

from __future__ import annotations

import math

import numpy as np

from diviewer.scene import camera as cam
from diviewer.scene.model import Camera, FrameConfig, Scene


def pixel_ray(camera: Camera, x: float, y: float, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """World-space ray (origin, unit direction) through the point (x, y) of an image, x right, y down, in pixels.

    Pixel (i, j)'s centre is (j + 0.5, i + 0.5), as in diviewer.scene.camera.
    """
    t = math.tan(math.radians(camera.fov) / 2.0)
    aspect = width / height
    vx = (x / width * 2.0 - 1.0) * t * aspect
    vy = (1.0 - y / height * 2.0) * t
    to_world = cam.view_to_world(camera.view_matrix())
    d = to_world[:3, :3] @ np.array([vx, vy, -1.0])
    return np.asarray(camera.position, dtype=np.float64), d / np.linalg.norm(d)


def ray_triangles_hit(origin: np.ndarray, d: np.ndarray, tri: np.ndarray) -> tuple[float, int]:
    """(nearest positive ray parameter, index of the triangle hit) over ``tri`` (M, 3, 3), or (inf, -1)
    (Moller-Trumbore)."""
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origin - v0
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ d) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6)
    if not hit.any():
        return math.inf, -1
    k = int(np.argmin(np.where(hit, t, np.inf)))
    return float(t[k]), k


def _ray_box(origin: np.ndarray, d: np.ndarray, box: np.ndarray) -> bool:
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t0, t1 = (box[0] - origin) * inv, (box[1] - origin) * inv
    lo = np.nanmax(np.minimum(t0, t1))
    hi = np.nanmin(np.maximum(t0, t1))
    return bool(hi >= max(lo, 0.0))


def pick_object(scene: Scene, config: FrameConfig, origin, direction) -> tuple[str, float] | None:
    """The object a world-space ray hits first, and the distance along the ray; None for the sky."""
    best: tuple[str, float] | None = None
    o_w, d_w = np.asarray(origin, np.float64), np.asarray(direction, np.float64)
    for obj in config.objects:
        mesh = scene.meshes[obj.mesh]
        inv = np.linalg.inv(obj.matrix())
        # Object-space ray with an unnormalised direction: t stays the world-space parameter.
        o = inv[:3, :3] @ o_w + inv[:3, 3]
        d = inv[:3, :3] @ d_w
        if not _ray_box(o, d, mesh.bounds.astype(np.float64)):
            continue
        t, _ = ray_triangles_hit(o, d, mesh.vertices.astype(np.float64)[mesh.faces])
        if t < math.inf and (best is None or t < best[1]):
            best = (obj.name, t)
    return best
