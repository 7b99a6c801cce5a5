"""Camera conventions, defined once: the GL renderer and the Mitsuba translation both call these.

Conventions: right-handed world, column vectors (``p_clip = P @ V @ M @ p``), the camera looks
down its -z axis with +y up and +x to the right (OpenGL). View-space depth is ``-z_view`` (positive
in front of the camera). Pixel (i, j) of an image stored top row first covers the square
``[j, j+1] x [i, i+1]`` and is sampled at its centre ``(j + 0.5, i + 0.5)``. GL's framebuffer rows
run bottom to top; every image this package returns runs top to bottom.
"""

from __future__ import annotations

import math

import numpy as np


def normalize(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v)
    if not np.isfinite(n) or n == 0.0:
        raise ValueError(f"cannot normalise vector {v.tolist()}")
    return v / n


def look_at(eye, target, up) -> np.ndarray:
    """World-to-view matrix (4x4, float64) for a camera at ``eye`` looking at ``target``."""
    eye = np.asarray(eye, dtype=np.float64)
    f = normalize(np.asarray(target, dtype=np.float64) - eye)
    s = np.cross(f, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(s) < 1e-9:
        raise ValueError("camera 'up' is parallel to the viewing direction")
    s = s / np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.identity(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL projection (clip z in [-w, w]) for a vertical field of view in degrees."""
    t = 1.0 / math.tan(math.radians(fov_y_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = t / aspect
    m[1, 1] = t
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def orthographic(half_w: float, half_h: float, near: float, far: float) -> np.ndarray:
    """OpenGL orthographic projection of the box [-half_w, half_w] x [-half_h, half_h] x [-near, -far]."""
    m = np.identity(4)
    m[0, 0] = 1.0 / half_w
    m[1, 1] = 1.0 / half_h
    m[2, 2] = -2.0 / (far - near)
    m[2, 3] = -(far + near) / (far - near)
    return m


def pixel_rays_view(width: int, height: int, fov_y_deg: float) -> np.ndarray:
    """View-space ray directions through pixel centres, scaled to unit -z (H, W, 3), top row first.

    A point at view-space depth ``d`` seen through pixel (i, j) is ``d * rays[i, j]``.
    """
    t = math.tan(math.radians(fov_y_deg) / 2.0)
    aspect = width / height
    x = ((np.arange(width) + 0.5) / width * 2.0 - 1.0) * t * aspect
    y = (1.0 - (np.arange(height) + 0.5) / height * 2.0) * t
    rays = np.empty((height, width, 3))
    rays[..., 0] = x[None, :]
    rays[..., 1] = y[:, None]
    rays[..., 2] = -1.0
    return rays


def view_to_world(view: np.ndarray) -> np.ndarray:
    """Camera-to-world matrix (the inverse of a rigid view matrix)."""
    r = view[:3, :3]
    m = np.identity(4)
    m[:3, :3] = r.T
    m[:3, 3] = -r.T @ view[:3, 3]
    return m


def euler_xyz(degrees) -> np.ndarray:
    """Rotation matrix (3x3) for rotations about x, then y, then z (degrees), i.e. Rz @ Ry @ Rx."""
    ax, ay, az = np.radians(np.asarray(degrees, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def axis_angle(axis, degrees: float) -> np.ndarray:
    """Rotation matrix (3x3) of ``degrees`` about ``axis`` (right-handed)."""
    a = normalize(axis)
    th = math.radians(degrees)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.identity(3) + math.sin(th) * k + (1 - math.cos(th)) * (k @ k)


def trs(position, rotation_deg, scale) -> np.ndarray:
    """Model matrix: translate @ rotate (euler xyz, degrees) @ scale."""
    m = np.identity(4)
    m[:3, :3] = euler_xyz(rotation_deg) @ np.diag(np.asarray(scale, dtype=np.float64))
    m[:3, 3] = np.asarray(position, dtype=np.float64)
    return m


def normal_matrix(model: np.ndarray) -> np.ndarray:
    """Inverse transpose of the upper 3x3, for transforming normals."""
    return np.linalg.inv(model[:3, :3]).T
