"""The shadow maps' settings and light-space projections: a directional light's orthographic fit to the scene's
bounds, a point light's six cube faces. The shadow pass renders with them and direct.glsl looks up with
the same matrices (`light_uniforms`)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from diviewer.gl.culling import box_corners, frustum_planes
from diviewer.gl.resources import set_uniform
from diviewer.scene import camera as cam
from diviewer.scene.model import DirectionalLight, PointLight


MOVING_SHADOW_SIZE = 2048
"""A sun's map size while it moves, in the viewer (and the bench's timed frames, whose sun moves every frame)."""


@dataclass(frozen=True)
class RenderSettings:
    """Settings of the GL renderer (recorded with every capture and benchmark)."""

    shadows: bool = True
    """Shadow-map the lights; off gives unshadowed Lambert."""
    shadow_size: int | None = None
    """Directional shadow map resolution (texels per side; None: the scene's ``[scene] shadow_size``, 2048 unless
    it says otherwise); point lights use this per cube face / 2."""
    pcf_radius: int = 1
    """PCF kernel radius: (2r+1)^2 taps."""
    bias: float = 0.5
    """Constant depth bias, in shadow-map texels."""
    slope_bias: float = 1.0
    """Slope-scaled bias, in texels per unit tan(theta) (theta: angle of incidence)."""
    normal_offset: float = 1.5
    """Offset of the lookup point along the surface normal, in shadow-map texels."""

    def for_scene(self, scene) -> "RenderSettings":
        """These settings as ``scene`` renders with them: its shadow map size where they name none."""
        return self if self.shadow_size is not None else replace(self, shadow_size=int(scene.shadow_size))


def fit_directional(bounds: np.ndarray, direction) -> tuple[np.ndarray, float, float]:
    """Light view-projection of the smallest light-aligned box around the scene's bounds (its eight corners seen
    along the light), and that box's larger side across the map and its depth range, in world units.

    The map spends its texels on the bounds' own outline, not on their bounding sphere's square: Sponza's
    51 x 21 x 31 m bounds seen from the noon sun take 55 x 31 m of the map instead of 64 x 64 m. At one map size
    that gains its sunlit frames' direct light 0.3-0.5 dB against the path tracer; the map's size does the rest
    (``[scene] shadow_size``, docs/sponza.md at commit c48f1bc). The texels are then not square; a texel's larger side sets the
    lookup's biases."""
    b = np.asarray(bounds, dtype=np.float64)
    centre = b.mean(axis=0)
    radius = max(float(np.linalg.norm(b[1] - b[0])) / 2.0, 1e-6)
    d = cam.normalize(direction)
    up = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.99 else np.array([1.0, 0.0, 0.0])
    view = cam.look_at(centre - d * 2.0 * radius, centre, up)
    p = box_corners(b) @ view[:3, :3].T + view[:3, 3]
    lo, hi = p.min(axis=0), p.max(axis=0)
    pad = 1e-3 * radius  # geometry on the bounds' faces stays inside the map and the depth range
    half = (hi[:2] - lo[:2]) / 2.0 + pad
    shift = np.identity(4)
    shift[:2, 3] = -(lo[:2] + hi[:2]) / 2.0
    near, far = -hi[2] - pad, -lo[2] + pad  # the eye is 2 radii out: every corner lies 1-3 radii ahead of it
    return cam.orthographic(half[0], half[1], near, far) @ shift @ view, 2.0 * float(half.max()), far - near


CUBE_EDGES = tuple((a, a | bit) for a in range(8) for bit in (4, 2, 1) if not a & bit)
"""The 12 edges of a box's corners as `box_corners` lists them: index pairs one bit apart."""
NDC_CUBE = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])


def _edge_crossings(corners: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Where the edges of a hexahedron (its corners as `box_corners` lists them) cross the planes (P, 4)."""
    p0, p1 = corners[[e[0] for e in CUBE_EDGES]], corners[[e[1] for e in CUBE_EDGES]]
    s0, s1 = p0 @ planes[:, :3].T + planes[:, 3], p1 @ planes[:, :3].T + planes[:, 3]  # (12, P)
    cross = s0 * s1 < 0.0  # the ends on either side: s0 - s1 is not 0
    t = np.where(cross, s0 / np.where(cross, s0 - s1, 1.0), 0.0)
    return (p0[:, None, :] + t[..., None] * (p1 - p0)[:, None, :])[cross]


def view_in_bounds(clip: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """The corners (M, 3) of the part of the scene's ``bounds`` that the camera of ``clip`` (world to clip) sees: the
    frustum's corners inside the box, the box's inside the frustum, and where the edges of each cross the other's
    faces (the convex hull of these is that part); (0, 3) when the view holds none of the box."""
    b = np.asarray(bounds, np.float64)
    h = np.c_[box_corners(NDC_CUBE), np.ones(8)] @ np.linalg.inv(np.asarray(clip, np.float64)).T
    frustum, box = h[:, :3] / h[:, 3:], box_corners(b)
    view_planes = frustum_planes(clip)
    box_planes = np.concatenate([np.c_[np.eye(3), -b[0]], np.c_[-np.eye(3), b[1]]])  # n . p + d >= 0 inside
    p = np.concatenate([frustum, box, _edge_crossings(frustum, box_planes), _edge_crossings(box, view_planes)])
    tol = 1e-6 * (1.0 + float(np.abs(b).max()))
    inside = np.all(p @ view_planes[:, :3].T + view_planes[:, 3] >= -tol, axis=1)
    return p[inside & np.all(p @ box_planes[:, :3].T + box_planes[:, 3] >= -tol, axis=1)]


def footprint_rect(m_light: np.ndarray, points: np.ndarray, size: int, margin: float) -> tuple[int, int, int, int]:
    """The texels (x, y, width, height) of a ``size`` map of ``m_light`` over which ``points`` (M, 3) lie, widened by
    ``margin`` texels a side and clamped to the map; (0, 0, 0, 0) for no points."""
    if len(points) == 0:
        return (0, 0, 0, 0)
    q = np.c_[points, np.ones(len(points))] @ np.asarray(m_light, np.float64).T
    t = (q[:, :2] / q[:, 3:] * 0.5 + 0.5) * size
    lo = np.clip(np.floor(t.min(axis=0) - margin), 0, size).astype(int)
    hi = np.clip(np.ceil(t.max(axis=0) + margin), 0, size).astype(int)
    return (int(lo[0]), int(lo[1]), int(hi[0] - lo[0]), int(hi[1] - lo[1]))


def sun_footprint(camera_clip: np.ndarray, light, bounds: np.ndarray, m_light: np.ndarray, extent: float, size: int,
                  s: RenderSettings) -> tuple[tuple, tuple[int, int, int, int]]:
    """What a moving sun's map needs to hold for the camera of ``camera_clip`` alone: `culling.shadow_casters`'
    arguments after the boxes (the casters whose shadow can reach the view) and the map's scissor rectangle (the
    texels over the part of the scene in view). A visible point's lookup reads up to its normal offset plus the
    filter's radius plus one texel beside it: both are widened by that and a texel more. Texels and casters left
    out are ones no visible point's lookup reads, so the frame is the same (tests/gl/test_renderer.py)."""
    margin = s.normal_offset + s.pcf_radius + 2.0
    rect = footprint_rect(m_light, view_in_bounds(camera_clip, bounds), size, margin)
    return (camera_clip, light.direction, bounds, margin * extent / size), rect


# Cube-face (forward, up) pairs for point-light shadows; the lookup uses the same matrices.
FACES = (((1, 0, 0), (0, -1, 0)), ((-1, 0, 0), (0, -1, 0)), ((0, 1, 0), (0, 0, 1)),
         ((0, -1, 0), (0, 0, -1)), ((0, 0, 1), (0, -1, 0)), ((0, 0, -1), (0, -1, 0)))


def point_faces(position, bounds: np.ndarray) -> np.ndarray:
    """World -> clip matrices (6, 4, 4) of a point light's cube faces, far enough to reach every corner
    of the scene's bounds."""
    p = np.asarray(position, dtype=np.float64)
    far = float(np.linalg.norm(box_corners(bounds) - p, axis=1).max()) * 1.01 + 1e-3
    near = max(far * 1e-4, 1e-4)
    proj = cam.perspective(90.0, 1.0, near, far)
    return np.stack([proj @ cam.look_at(p, p + np.array(f), u) for f, u in FACES])


def light_defines(light) -> dict[str, int]:
    """direct.glsl's defines for one light's term (none: no light)."""
    if light is None:
        return {}
    return {"DIRECTIONAL": 1} if isinstance(light, DirectionalLight) else {"POINT_LIGHT": 1}


def light_uniforms(prog, light, shadow, s: RenderSettings) -> None:
    """One light's radiometry and shadow-lookup uniforms for direct.glsl's code; ``shadow`` is this frame's map of
    the light (`diviewer.gl.shadows`: it binds its own lookup; None: shadows off)."""
    set_uniform(prog, "u_shadows", shadow is not None)
    set_uniform(prog, "u_pcf_radius", int(s.pcf_radius))
    set_uniform(prog, "u_bias", float(s.bias))
    set_uniform(prog, "u_slope_bias", float(s.slope_bias))
    set_uniform(prog, "u_normal_offset", float(s.normal_offset))
    sun = isinstance(light, DirectionalLight)
    assert sun or isinstance(light, PointLight)
    power = light.irradiance if sun else light.intensity
    set_uniform(prog, "u_light_color", tuple(float(c) * power for c in light.color))
    name, where = ("u_light_dir", light.direction) if sun else ("u_light_pos", light.position)
    set_uniform(prog, name, tuple(float(x) for x in where))
    if shadow is not None:
        shadow.bind(prog)
