"""What is in a scene and where a camera can go in it: the report `diviewer inspect` prints. No GL.

The open space is found on a grid over the scene's bounds (`OpenSpaceSettings.cells` along the longest side): a
cell is occupied where a surface passes (points sampled on every placed triangle), open where it is not occupied
and not inside a solid (a pocket of cells the outside cannot reach is a room when rays
from it meet front faces, the inside of a closed object when they meet back faces). The suggested camera region is
the largest box of open cells (no side more than eight times another; where the scene file has a camera, in
the open space connected to it), spanning their centres (so half a cell from any surface); the suggested camera stands at its corner farthest from the scene's centre and looks
at that centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from diviewer.scene.model import DirectionalLight, Scene
from diviewer.scene.picking import ray_triangles_hit

MIN_POCKET = 8
"""Fewer enclosed free cells than this are a gap inside geometry, not a room: never open."""
AXES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)


@dataclass(frozen=True)
class OpenSpaceSettings:
    """How finely the open space is searched."""

    cells: int = 32
    """Grid cells along the bounds' longest side (the others in proportion, at least 3)."""
    samples_per_cell: float = 16.0
    """Surface points sampled per cell-face area of each triangle (more: fewer walls read as holes)."""
    max_points: int = 4_000_000
    """Cap on the sampled surface points (a large scene samples more sparsely)."""
    seed: int = 0
    """Seed of the surface sampling: the same scene gives the same suggestion."""
    max_aspect: float = 8.0
    """The camera region's longest side is at most this many times its shortest: a room, not a corridor or a
    slab along a wall (the largest box by volume alone is often one)."""


def _placed_triangles(scene: Scene, o) -> np.ndarray:
    """(T, 3, 3) float64 world-space triangles of one placed object."""
    mesh, m = scene.meshes[o.mesh], o.matrix()
    return (mesh.vertices.astype(np.float64) @ m[:3, :3].T + m[:3, 3])[mesh.faces]


def world_triangles(scene: Scene, config=None) -> np.ndarray:
    """(T, 3, 3) float64 world-space triangles of a frame's objects, in order."""
    tris = [_placed_triangles(scene, o) for o in (config or scene.default).objects]
    return np.concatenate(tris) if tris else np.zeros((0, 3, 3))


def _areas(tri: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


def emissive_area(scene: Scene, config=None) -> dict[str, float]:
    """World-space area (m^2) of the surfaces each emissive material covers in a frame."""
    config = config or scene.default
    out: dict[str, float] = {}
    for o in config.objects:
        mat = scene.materials[o.material]
        if mat.is_emissive:
            out[o.material] = out.get(o.material, 0.0) + float(_areas(_placed_triangles(scene, o)).sum())
    return out


def _grid(lo: np.ndarray, hi: np.ndarray, cells: int) -> tuple[np.ndarray, float]:
    """Cells per axis and the cell size of a grid over the box (lo, hi)."""
    size = max(float((hi - lo).max()), 1e-9) / cells
    return np.maximum(np.ceil((hi - lo) / size).astype(int), 3), size


def _occupied(tri: np.ndarray, lo: np.ndarray, dims: np.ndarray, size: float, s: OpenSpaceSettings) -> np.ndarray:
    """Cells a surface passes through: vertices and points sampled on each triangle by its area."""
    rng = np.random.default_rng(s.seed)
    n = np.ceil(_areas(tri) / (size * size) * s.samples_per_cell).astype(np.int64) + 1
    if n.sum() > s.max_points:
        n = np.maximum((n * (s.max_points / n.sum())).astype(np.int64), 1)
    idx = np.repeat(np.arange(len(tri)), n)
    a, b = rng.uniform(size=(2, len(idx)))
    flip = a + b > 1.0
    a, b = np.where(flip, 1.0 - a, a), np.where(flip, 1.0 - b, b)
    t = tri[idx]
    points = np.concatenate([t[:, 0] + a[:, None] * (t[:, 1] - t[:, 0]) + b[:, None] * (t[:, 2] - t[:, 0]),
                             tri.reshape(-1, 3)])
    cell = np.clip(((points - lo) / size).astype(np.int64), 0, dims - 1)
    occ = np.zeros(tuple(dims), bool)
    occ[cell[:, 0], cell[:, 1], cell[:, 2]] = True
    return occ


def open_cells(scene: Scene, settings: OpenSpaceSettings = OpenSpaceSettings()):
    """(open mask, grid origin, cell size) over the scene's bounds; see the module's docstring."""
    from scipy import ndimage

    lo, hi = scene.bounds()
    dims, size = _grid(lo, hi, settings.cells)
    tri = world_triangles(scene)
    occ = _occupied(tri, lo, dims, size, settings)
    free = ~occ
    # Pockets of free cells the outside (a one-cell border around the grid) cannot reach: rooms or solids.
    labels, count = ndimage.label(np.pad(free, 1, constant_values=True))
    outside = int(labels[0, 0, 0])
    labels = labels[1:-1, 1:-1, 1:-1]
    centre = lo + (np.indices(tuple(dims)).transpose(1, 2, 3, 0) + 0.5) * size
    open_ = free & np.all(centre <= hi, axis=-1)  # the grid's last cells may reach past the bounds
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    for k in range(1, count + 1):
        if k == outside:
            continue
        pocket = labels == k
        if pocket.sum() < MIN_POCKET:
            open_ &= ~pocket
            continue
        cells = np.argwhere(pocket & open_)
        origin = centre[tuple(cells[len(cells) // 2])]
        back = front = 0
        for d in AXES:
            t, i = ray_triangles_hit(origin, d, tri)
            if i >= 0:
                back, front = (back + 1, front) if float(normals[i] @ d) > 0 else (back, front + 1)
        if back > front:  # inside a closed object, not a room
            open_ &= ~pocket
    return open_, lo, size


def largest_box(mask: np.ndarray, max_aspect: float = math.inf) -> tuple[np.ndarray, np.ndarray] | None:
    """(first, last) cell indices of the largest axis-aligned box of True cells whose longest side is at most
    ``max_aspect`` times its shortest, or None when there is none."""
    nx, ny, nz = mask.shape
    best, found = 0, None
    for x0 in range(nx):
        slab = np.ones((ny, nz), bool)
        for x1 in range(x0, nx):
            slab &= mask[x1]
            if not slab.any():
                break
            for y0 in range(ny):
                cols = np.logical_and.accumulate(slab[y0:], axis=0)  # row k: open through y0..y0+k
                run = np.zeros(len(cols), int)
                longest, end = run.copy(), run.copy()
                for z in range(nz):  # the longest run of open cells along z, every row at once
                    run = np.where(cols[:, z], run + 1, 0)
                    better = run > longest
                    longest, end = np.where(better, run, longest), np.where(better, z, end)
                a, b = x1 - x0 + 1, np.arange(len(cols)) + 1
                side = np.minimum(a, b)
                longest = np.minimum(longest, np.floor(max_aspect * side)).astype(int)  # a shorter run is open too
                fits = np.maximum(a, b) <= max_aspect * np.minimum(side, np.maximum(longest, 1))
                vol = np.where(fits, a * b * longest, 0)
                k = int(np.argmax(vol))
                if vol[k] > best:
                    best = int(vol[k])
                    found = (np.array([x0, y0, end[k] - longest[k] + 1]), np.array([x1, y0 + k, end[k]]))
    return found


def suggest_camera(scene: Scene, settings: OpenSpaceSettings = OpenSpaceSettings(), near=None) -> dict:
    """A camera and a camera region (``[ranges.camera] region``) in the scene's largest open box; with ``near`` (a
    point: the scene file's camera) in the open space connected to it, where the scene's author stands."""
    from scipy import ndimage

    lo, hi = scene.bounds()
    centre, diag = (lo + hi) / 2.0, float(np.linalg.norm(hi - lo))
    mask, origin, size = open_cells(scene, settings)
    at = None if near is None else np.floor((np.asarray(near, np.float64) - origin) / size).astype(int)
    if at is not None and np.all(at >= 0) and np.all(at < mask.shape) and mask[tuple(at)]:
        labels, _ = ndimage.label(mask)
        mask = labels == labels[tuple(at)]
    box = largest_box(mask, settings.max_aspect)
    if box is None:  # no open space inside the bounds: stand outside, in front (+z) and above
        position = centre + np.array([0.0, 0.25, 1.0]) * diag
        region = (position - 0.1 * diag, position + 0.1 * diag)
        cells = 0
    else:
        region = (origin + (box[0] + 0.5) * size, origin + (box[1] + 0.5) * size)  # the cells' centres
        pad = np.where(region[1] - region[0] < 1e-9, 0.25 * size, 0.0)
        region = (region[0] - pad, region[1] + pad)
        corners = np.array([[region[i][0], region[j][1], region[k][2]] for i in (0, 1) for j in (0, 1)
                            for k in (0, 1)])
        position = corners[int(np.argmax(np.linalg.norm(corners - centre, axis=1)))]
        cells = int(np.prod(box[1] - box[0] + 1))
    far = 2.0 * diag
    return {"camera": {"position": _r(position), "target": _r(centre), "up": [0.0, 1.0, 0.0], "fov": 60.0,
                       "near": _r(far / 1e4), "far": _r(far)},
            "camera_region": {"region": [_r(region[0]), _r(region[1])], "target": _r(centre),
                              "target_jitter": _r(0.1 * (hi - lo)), "fov": [50.0, 70.0]},
            "open_cells": int(mask.sum()), "region_cells": cells, "cell_size": _r(size)}


def _r(v):
    """Numbers rounded to 4 significant digits, for a report a person reads and a file they edit."""
    if np.ndim(v) == 0:
        return float(f"{float(v):.4g}")
    return [float(f"{float(x):.4g}") for x in v]


def survey(scene: Scene, settings: OpenSpaceSettings = OpenSpaceSettings(), near=None) -> dict:
    """The scene's bounds, triangles, materials, textures, lights, emitters, warnings and a suggested camera
    (``near``: see `suggest_camera`)."""
    from diviewer.scene.gltf import DEFAULT_MATERIAL

    lo, hi = scene.bounds()
    triangles = sum(len(scene.meshes[o.mesh].faces) for o in scene.default.objects)  # counted: open_cells places them
    used: dict[str, int] = {}
    for o in scene.default.objects:
        used[o.material] = used.get(o.material, 0) + 1
    materials = []
    for name, m in scene.materials.items():
        glow = None if m.emission_texture is None else m.emission_texture_source or "(in memory)"
        materials.append({"name": name, "albedo": _r(m.albedo), "emission": _r(m.emission),
                          "texture": m.texture_source or None, "emission_texture": glow, "masked": m.is_masked,
                          "double_sided": m.double_sided, "default": name == DEFAULT_MATERIAL, "objects": used.get(name, 0)})
    textures = [{"material": name, "source": m.texture_source or "(in memory)",
                 "size": [int(m.texture.shape[1]), int(m.texture.shape[0])]}
                for name, m in scene.materials.items() if m.texture is not None]
    lights = []
    for light in scene.default.lights:
        if isinstance(light, DirectionalLight):
            lights.append({"name": light.name, "type": "directional", "direction": _r(light.direction),
                           "irradiance": light.irradiance, "color": _r(light.color)})
        else:
            lights.append({"name": light.name, "type": "point", "position": _r(light.position),
                           "intensity": light.intensity, "color": _r(light.color)})
    emit = emissive_area(scene)
    return {"scene": scene.name, "file": str(scene.path) if scene.path else None,
            "bounds": {"min": _r(lo), "max": _r(hi), "size": _r(hi - lo)},
            "triangles": int(triangles), "meshes": len(scene.meshes), "objects": len(scene.default.objects),
            "materials": materials, "textures": textures, "lights": lights,
            "emissive": {"area_m2": _r(sum(emit.values())), "materials": {k: _r(v) for k, v in emit.items()}},
            "ambient": _r(scene.ambient), "warnings": list(scene.warnings),
            "suggested": suggest_camera(scene, settings, near)}
