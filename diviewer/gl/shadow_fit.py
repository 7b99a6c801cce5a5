"""The light-space projections of the shadow maps: a directional light's orthographic fit to the scene's
bounds, a point light's six cube faces. The shadow pass renders with them and direct.glsl looks up with
the same matrices."""

from __future__ import annotations

import numpy as np

from diviewer.scene import camera as cam


def fit_directional(bounds: np.ndarray, direction) -> tuple[np.ndarray, float, float]:
    """Light view-projection covering the scene's bounding sphere; also the texel-free extents."""
    centre = bounds.mean(axis=0)
    radius = max(float(np.linalg.norm(bounds[1] - bounds[0])) / 2.0, 1e-6)
    d = cam.normalize(direction)
    up = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.99 else np.array([1.0, 0.0, 0.0])
    eye = centre - d * 2.0 * radius
    view = cam.look_at(eye, centre, up)
    near, far = 0.5 * radius, 3.5 * radius
    return cam.orthographic(radius, radius, near, far) @ view, 2.0 * radius, far - near


# Cube-face (forward, up) pairs for point-light shadows; the lookup uses the same matrices.
FACES = (((1, 0, 0), (0, -1, 0)), ((-1, 0, 0), (0, -1, 0)), ((0, 1, 0), (0, 0, 1)),
         ((0, -1, 0), (0, 0, -1)), ((0, 0, 1), (0, -1, 0)), ((0, 0, -1), (0, -1, 0)))


def point_faces(position, bounds: np.ndarray) -> np.ndarray:
    """World -> clip matrices (6, 4, 4) of a point light's cube faces, far enough to reach every corner
    of the scene's bounds."""
    p = np.asarray(position, dtype=np.float64)
    corners = np.array([[bounds[i, 0], bounds[j, 1], bounds[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    far = float(np.linalg.norm(corners - p, axis=1).max()) * 1.01 + 1e-3
    near = max(far * 1e-4, 1e-4)
    proj = cam.perspective(90.0, 1.0, near, far)
    return np.stack([proj @ cam.look_at(p, p + np.array(f), u) for f, u in FACES])
