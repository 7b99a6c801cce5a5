"""Camera conventions, defined once: the GL renderer and the Mitsuba translation both call these.

Conventions: right-handed world, column vectors (``p_clip = P @ V @ M @ p``), the camera looks
down its -z axis with +y up and +x to the right (OpenGL). View-space depth is ``-z_view`` (positive
in front of the camera). Pixel (i, j) of an image stored top row first covers the square
``[j, j+1] x [i, i+1]`` and is sampled at its centre ``(j + 0.5, i + 0.5)``. GL's framebuffer rows
run bottom to top; every image this package returns runs top to bottom.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from pyrr import matrix33, matrix44

# pyrr is the camera and transform library. Its matrices act on row vectors (``p @ M``, translation
# in the last row), the transpose of the GL column convention used everywhere in this package, so
# every pyrr matrix is transposed once, here, and nowhere else. pyrr's create_from_{x,y,z}_rotation
# already follow the column convention (the opposite of its create_from_axis_rotation), so only the
# axis form is used, for every rotation. tests/scene/test_loader.py pins each function to its definition.
_F64 = np.float64


def normalize(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=_F64)
    n = np.linalg.norm(v)
    if not np.isfinite(n) or n == 0.0:
        raise ValueError(f"cannot normalise vector {v.tolist()}")
    return v / n


def look_at(eye, target, up) -> np.ndarray:
    """World-to-view matrix (4x4, float64) for a camera at ``eye`` looking at ``target``."""
    eye, target, up = (np.asarray(v, dtype=_F64) for v in (eye, target, up))
    if np.linalg.norm(np.cross(normalize(target - eye), up)) < 1e-9:
        raise ValueError("camera 'up' is parallel to the viewing direction")
    return matrix44.create_look_at(eye, target, up, dtype=_F64).T


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL projection (clip z in [-w, w]) for a vertical field of view in degrees."""
    return matrix44.create_perspective_projection(fov_y_deg, aspect, near, far, dtype=_F64).T


def jittered(proj: np.ndarray, offset: tuple[float, float], width: int, height: int) -> np.ndarray:
    """``proj`` with its image moved by ``offset`` pixels (x right, y up) of a ``width`` x ``height`` target: the
    pixel centred at ``c`` then shows what lay at ``c - offset`` (temporal upsampling's sub-pixel jitter)."""
    out = np.array(proj, np.float64)
    # clip.w = -z_view: adding -2 dx / width to row 0's z column moves NDC x by +2 dx / width, whatever the depth.
    out[0, 2] -= 2.0 * offset[0] / width
    out[1, 2] -= 2.0 * offset[1] / height
    return out


def halton(index: int, base: int) -> float:
    """The ``index``-th (from 1) element of the radical-inverse sequence in ``base``, in [0, 1)."""
    f, r, i = 1.0, 0.0, int(index)
    while i > 0:
        f /= base
        r += f * (i % base)
        i //= base
    return r


def orthographic(half_w: float, half_h: float, near: float, far: float) -> np.ndarray:
    """OpenGL orthographic projection of the box [-half_w, half_w] x [-half_h, half_h] x [-near, -far]."""
    return matrix44.create_orthogonal_projection(-half_w, half_w, -half_h, half_h, near, far, dtype=_F64).T


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


CAMERA_PARAMS = 20
"""Length of `camera_params`' vector: camera-to-world rotation (9, row-major) and translation (3), the pixel-to-ray
affines along x and y (ax, bx, ay, by) and the column and row bounds the rays clamp to (x_lo, x_hi, y_lo, y_hi)."""


def camera_params(position, target, up, fov_y_deg: float, width: int, height: int, *, x0: int = 0, y0: int = 0,
                  source: tuple[int, int] | None = None, pad: tuple[int, int] = (0, 0)) -> np.ndarray:
    """A frame's camera as the (CAMERA_PARAMS,) float32 vector the world-space inputs are computed from.

    The frame is ``width`` x ``height`` pixels cut at (x0, y0) out of a render of ``source`` (width, height;
    default the frame itself), then padded with ``pad`` (left, top) pixels before it (`diviewer.contract.padding`). A
    pixel (column c, row r) of the padded frame sees along the view-space ray ``(ax (c' + 0.5) + bx, ay (r' + 0.5)
    + by, -1)`` with c' = clip(c, x_lo, x_hi) and r' = clip(r, y_lo, y_hi): `pixel_rays_view` of the render at the
    frame's pixels, and on the padding the edge pixel's ray (padding replicates edge pixels; so do their rays).
    The world point is then ``R (depth ray) + t`` and the world normal ``R n`` (R, t: `view_to_world`).
    """
    sw, sh = source if source is not None else (width, height)
    t = math.tan(math.radians(fov_y_deg) / 2.0)
    tx = t * sw / sh
    ax, ay = 2.0 * tx / sw, -2.0 * t / sh
    px, py = pad
    m = view_to_world(look_at(position, target, up))
    return np.array([*m[:3, :3].ravel(), *m[:3, 3],
                     ax, tx * (2.0 * x0 / sw - 1.0) - ax * px, ay, t * (1.0 - 2.0 * y0 / sh) - ay * py,
                     px, px + width - 1, py, py + height - 1], np.float32)


def axis_angle(axis, degrees: float) -> np.ndarray:
    """Rotation matrix (3x3) of ``degrees`` about ``axis`` (right-handed)."""
    return matrix33.create_from_axis_rotation(normalize(axis), math.radians(degrees), dtype=_F64).T


_AXES = np.identity(3)


def euler_xyz(degrees) -> np.ndarray:
    """Rotation matrix (3x3) for rotations about x, then y, then z (degrees), i.e. Rz @ Ry @ Rx."""
    ax, ay, az = (float(a) for a in np.asarray(degrees, dtype=_F64))
    return axis_angle(_AXES[2], az) @ axis_angle(_AXES[1], ay) @ axis_angle(_AXES[0], ax)


def trs(position, rotation_deg, scale) -> np.ndarray:
    """Model matrix: translate @ rotate (euler xyz, degrees) @ scale.

    Memoised on the nine numbers (a copy each call): pyrr's helpers inspect their signature on every call,
    and the viewer asks for every object's matrix every frame (a Sponza frame has 180 objects)."""
    key = tuple(float(v) for v in (*np.ravel(position), *np.ravel(rotation_deg), *np.ravel(scale)))
    if len(key) != 9:
        raise ValueError(f"trs wants three 3-vectors, got {len(key)} numbers")
    return _trs(key).copy()


@functools.lru_cache(maxsize=8192)
def _trs(key: tuple[float, ...]) -> np.ndarray:
    position, rotation_deg, scale = key[0:3], key[3:6], key[6:9]
    t = matrix44.create_from_translation(np.asarray(position, dtype=_F64), dtype=_F64).T
    r = matrix44.create_from_matrix33(euler_xyz(rotation_deg), dtype=_F64)  # 3x3 block only: no transpose issue
    s = matrix44.create_from_scale(np.asarray(scale, dtype=_F64), dtype=_F64)  # diagonal
    return t @ r @ s


def normal_matrix(model: np.ndarray) -> np.ndarray:
    """Inverse transpose of the upper 3x3, for transforming normals."""
    return np.linalg.inv(model[:3, :3]).T
