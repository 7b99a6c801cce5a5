"""Meshes: procedural shapes (trimesh.creation) and mesh files, turned into validated Mesh data."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import trimesh

from diviewer.errors import DiviewerError
from diviewer.scene.model import Mesh
from diviewer.scene.reads import note_read
from diviewer.scene.textures import MAX_TEXTURE_SIDE, decode

CREASE_ANGLE_DEG = 30.0
"""Edges sharper than this get split normals (a box stays faceted, a sphere stays smooth)."""


def _torus_knot(p: int = 2, q: int = 3, radius: float = 0.5, tube: float = 0.12,
                segments: int = 256, sides: int = 16) -> trimesh.Trimesh:
    """A (p, q) torus knot as a tube swept along the knot curve (parallel-transport frames)."""
    t = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False)
    r = radius * (0.6 + 0.4 * np.cos(q * t))
    c = np.stack([r * np.cos(p * t), r * np.sin(p * t), -0.4 * radius * np.sin(q * t)], axis=1)
    tangent = np.roll(c, -1, axis=0) - np.roll(c, 1, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.cross(tangent, np.array([0.0, 0.0, 1.0]))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    binormal = np.cross(tangent, normal)
    a = np.linspace(0.0, 2.0 * math.pi, sides, endpoint=False)
    ring = np.cos(a)[None, :, None] * normal[:, None, :] + np.sin(a)[None, :, None] * binormal[:, None, :]
    verts = (c[:, None, :] + tube * ring).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(segments), np.arange(sides), indexing="ij")
    i2, j2 = (i + 1) % segments, (j + 1) % sides
    v00, v10, v01, v11 = i * sides + j, i2 * sides + j, i * sides + j2, i2 * sides + j2
    faces = np.concatenate([np.stack([v00, v10, v11], -1).reshape(-1, 3), np.stack([v00, v11, v01], -1).reshape(-1, 3)])
    m = trimesh.Trimesh(verts, faces, process=True)
    if m.volume < 0:
        m.invert()
    return m


def _plane(size) -> trimesh.Trimesh:
    """A single-sided square in the xz plane facing +y."""
    sx, sz = (float(size[0]) / 2, float(size[1]) / 2) if np.ndim(size) else (float(size) / 2,) * 2
    v = np.array([[-sx, 0, -sz], [sx, 0, -sz], [sx, 0, sz], [-sx, 0, sz]], dtype=np.float64)
    return trimesh.Trimesh(v, np.array([[0, 2, 1], [0, 3, 2]]), process=False)


def _capsule_cluster(count: int = 3, radius: float = 0.12, height: float = 0.5) -> trimesh.Trimesh:
    """Capsules leaning in different directions, fused into one mesh (a held-out test shape)."""
    parts = []
    for k in range(count):
        c = trimesh.creation.capsule(height=height, radius=radius, count=[24, 12])
        rot = trimesh.transformations.rotation_matrix(math.radians(40), [math.cos(2 * math.pi * k / count), 0, math.sin(2 * math.pi * k / count)])
        c.apply_transform(rot)
        parts.append(c)
    return trimesh.util.concatenate(parts)


def _pipe(radius: float, inner_radius: float, height: float, sections: int) -> trimesh.Trimesh:
    """A hollow cylinder, open at both ends: a hole through it and a concave inside (genus 1, not a torus)."""
    return trimesh.creation.annulus(r_min=inner_radius, r_max=radius, height=height, sections=int(sections))


def _frame(size: float, thickness: float, depth: float) -> trimesh.Trimesh:
    """A square picture frame: four bars around a square hole (genus 1, flat sides and sharp inner corners)."""
    half, bar = size / 2.0, min(thickness, size / 2.0)
    parts = []
    for axis in (0, 1):
        for sign in (-1.0, 1.0):
            extents = [size, size, depth]
            extents[axis] = bar
            b = trimesh.creation.box(extents=extents)
            offset = [0.0, 0.0, 0.0]
            offset[axis] = sign * (half - bar / 2.0)
            b.apply_translation(offset)
            parts.append(b)
    return trimesh.util.concatenate(parts)


def _box_cluster(count: int, size: float) -> trimesh.Trimesh:
    """Boxes tilted in different directions around a common centre, fused into one mesh: several parts that
    shade each other, with concave crevices between them (a training shape; capsule_cluster is held out)."""
    parts = []
    for k in range(count):
        b = trimesh.creation.box(extents=[size, 2.0 * size, size])
        a = 2.0 * math.pi * k / count
        b.apply_translation([0.0, size, 0.0])
        b.apply_transform(trimesh.transformations.rotation_matrix(math.radians(50), [math.cos(a), 0.0, math.sin(a)]))
        parts.append(b)
    return trimesh.util.concatenate(parts)


# shape name -> (builder, {parameter: default}); parameters come from the scene file's mesh table.
SHAPES = {
    "box": (lambda size: trimesh.creation.box(extents=np.broadcast_to(np.asarray(size, dtype=np.float64), 3)), {"size": (1.0, 1.0, 1.0)}),
    "sphere": (lambda radius, subdivisions: trimesh.creation.icosphere(subdivisions=int(subdivisions), radius=radius),
               {"radius": 0.5, "subdivisions": 3}),
    "cylinder": (lambda radius, height, sections: trimesh.creation.cylinder(radius=radius, height=height, sections=int(sections)),
                 {"radius": 0.5, "height": 1.0, "sections": 32}),
    "capsule": (lambda radius, height: trimesh.creation.capsule(height=height, radius=radius, count=[32, 16]),
                {"radius": 0.25, "height": 0.5}),
    "cone": (lambda radius, height, sections: trimesh.creation.cone(radius=radius, height=height, sections=int(sections)),
             {"radius": 0.5, "height": 1.0, "sections": 32}),
    "torus": (lambda major_radius, minor_radius: trimesh.creation.torus(major_radius=major_radius, minor_radius=minor_radius,
                                                                        major_sections=48, minor_sections=24),
              {"major_radius": 0.4, "minor_radius": 0.15}),
    "plane": (lambda size: _plane(size), {"size": (1.0, 1.0)}),
    "torus_knot": (lambda p, q, radius, tube: _torus_knot(int(p), int(q), radius, tube),
                   {"p": 2, "q": 3, "radius": 0.5, "tube": 0.12}),
    "capsule_cluster": (lambda count, radius, height: _capsule_cluster(int(count), radius, height),
                        {"count": 3, "radius": 0.12, "height": 0.5}),
    "pipe": (_pipe, {"radius": 0.35, "inner_radius": 0.25, "height": 0.6, "sections": 48}),
    "frame": (_frame, {"size": 0.7, "thickness": 0.15, "depth": 0.2}),
    "box_cluster": (lambda count, size: _box_cluster(int(count), size), {"count": 3, "size": 0.2}),
}


# Integer parameters and their allowed ranges. The upper bounds keep a mesh within what a frame can
# afford: an icosphere has 20 * 4**subdivisions faces (7: 328k; 10: 21M, minutes and out of memory).
INTEGER_PARAMS = {
    ("sphere", "subdivisions"): (0, 7),
    ("cylinder", "sections"): (3, 4096),
    ("cone", "sections"): (3, 4096),
    ("torus_knot", "p"): (1, 64),
    ("torus_knot", "q"): (1, 64),
    ("capsule_cluster", "count"): (1, 64),
    ("pipe", "sections"): (3, 4096),
    ("box_cluster", "count"): (1, 64),
}
MAX_EXTENT = 1e6
"""Largest size or radius of a procedural shape (scene units); float32 vertices keep 0.06 units of
precision there, and the shadow maps are fitted to the scene's bounds."""


def _check_param(shape: str, key: str, v, path, field: str) -> None:
    where = f"{field}.{key}"
    if (shape, key) in INTEGER_PARAMS:
        lo, hi = INTEGER_PARAMS[(shape, key)]
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise DiviewerError(f"expected a whole number from {lo} to {hi}, got {v!r}", path=path, field=where)
        if not lo <= v <= hi:
            raise DiviewerError(f"must be from {lo} to {hi}, got {v}", path=path, field=where)
        return
    flat = v if isinstance(v, (list, tuple)) else [v]
    if not flat or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in flat):
        raise DiviewerError(f"expected a number or a list of numbers, got {v!r}", path=path, field=where)
    vals = np.asarray(flat, dtype=np.float64)
    if not np.all(np.isfinite(vals)) or np.any(vals <= 0):
        raise DiviewerError(f"must be positive and finite, got {v}", path=path, field=where)
    if np.any(vals > MAX_EXTENT):
        raise DiviewerError(f"must be at most {MAX_EXTENT:g}, got {v}", path=path, field=where)


def procedural(name: str, shape: str, params: dict, *, path=None, field: str = "") -> Mesh:
    """Build a procedural shape; ``params`` must be a subset of the shape's parameters."""
    if shape not in SHAPES:
        raise DiviewerError(f"unknown shape '{shape}'; known shapes: {', '.join(sorted(SHAPES))}", path=path, field=field + ".shape")
    builder, defaults = SHAPES[shape]
    unknown = set(params) - set(defaults)
    if unknown:
        raise DiviewerError(f"unknown key(s) {sorted(unknown)} for shape '{shape}'; allowed: {sorted(defaults)}",
                            path=path, field=field)
    args = {**defaults, **params}
    for k, v in args.items():
        _check_param(shape, k, v, path, field)
    if shape in ("box",) and np.ndim(args["size"]) and len(args["size"]) != 3:
        raise DiviewerError(f"expected 3 numbers, got {args['size']}", path=path, field=f"{field}.size")
    if shape == "plane" and np.ndim(args["size"]) and len(args["size"]) != 2:
        raise DiviewerError(f"expected 2 numbers, got {args['size']}", path=path, field=f"{field}.size")
    if shape == "pipe" and args["inner_radius"] >= args["radius"]:
        raise DiviewerError(f"inner_radius ({args['inner_radius']}) must be less than radius ({args['radius']})",
                            path=path, field=f"{field}.inner_radius")
    if shape == "torus" and args["minor_radius"] >= args["major_radius"]:
        raise DiviewerError(f"minor_radius ({args['minor_radius']}) must be less than major_radius "
                            f"({args['major_radius']})", path=path, field=f"{field}.minor_radius")
    return from_trimesh(name, builder(**args), source=shape, path=path, field=field, strict=False)


def from_trimesh(name: str, tm: trimesh.Trimesh, *, source: str, path=None, field: str = "", strict: bool = True,
                 crease_angle_deg: float = CREASE_ANGLE_DEG) -> Mesh:
    """Validate a trimesh and compute crease-split vertex normals.

    Args:
        strict: refuse zero-area faces (a user's file) instead of dropping them (our own shapes).
    """
    v = np.asarray(tm.vertices, dtype=np.float64)
    f = np.asarray(tm.faces, dtype=np.int64)
    if len(v) == 0 or len(f) == 0:
        raise DiviewerError("mesh has no triangles", path=path, field=field)
    if not np.all(np.isfinite(v)):
        bad = int((~np.isfinite(v)).any(axis=1).sum())
        raise DiviewerError(f"mesh '{source}' has {bad} vertices with NaN or infinite coordinates", path=path, field=field)
    area = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1) / 2
    scale = max(float(np.ptp(v, axis=0).max()), 1e-30)
    degenerate = area <= 1e-12 * scale * scale
    if degenerate.any():
        if strict:
            raise DiviewerError(f"mesh '{source}' has {int(degenerate.sum())} zero-area faces (first: face "
                                f"{int(np.argmax(degenerate))}); clean the mesh", path=path, field=field)
        tm = trimesh.Trimesh(v, f[~degenerate], process=False)
    uv = None
    visual = getattr(tm, "visual", None)
    if visual is not None and getattr(visual, "kind", None) == "texture" and getattr(visual, "uv", None) is not None:
        uv = np.asarray(visual.uv, dtype=np.float64)
    if uv is not None and len(uv) == len(tm.vertices):
        # Textured meshes keep their vertices as the file has them (merging would break uv seams)
        # and the file's own normals, which glTF/OBJ exporters write with their creases split.
        verts, faces = tm.vertices, tm.faces
        normals = np.asarray(tm.vertex_normals, dtype=np.float64)
    else:
        base = trimesh.Trimesh(tm.vertices, tm.faces, process=True)
        sm = trimesh.graph.smooth_shade(base, angle=np.radians(crease_angle_deg), facet_minarea=None)
        verts, faces = sm.vertices, sm.faces
        normals = np.asarray(sm.vertex_normals, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(norm > 1e-12, n / np.maximum(norm, 1e-30), np.array([0.0, 1.0, 0.0]))
    return Mesh(
        name=name,
        vertices=np.ascontiguousarray(verts, dtype=np.float32),
        normals=np.ascontiguousarray(n, dtype=np.float32),
        faces=np.ascontiguousarray(faces, dtype=np.uint32),
        uvs=None if uv is None else np.ascontiguousarray(uv, dtype=np.float32),
        source=source,
    )


class _RecordingResolver(trimesh.resolvers.FilePathResolver):
    """trimesh's resolver next to a mesh file, recording every file it reads (an OBJ's .mtl and textures,
    a glTF's buffers): the scene's identity covers them (diviewer.scene.loader.scene_identity)."""

    def get(self, name: str):
        data = super().get(name)
        for candidate in (name.strip(), name.strip().lstrip("/"), os.path.split(name)[-1]):  # as the parent's get
            try:
                found = Path(self.absolute(candidate))
            except ValueError:
                continue
            if found.is_file():
                note_read(found)
                break
        return data


def load_file(name: str, file: Path, *, path=None, field: str = "") -> tuple[Mesh, tuple | None, np.ndarray | None]:
    """Load a mesh file (OBJ, PLY, GLB/glTF, ...) through trimesh.

    Returns:
        The mesh, the file's base-colour factor (RGB) or None, and its base-colour texture
        (H, W, 3 float32 linear, top row first) or None.
    """
    if not file.is_file():
        raise DiviewerError(f"mesh file not found: {file}", path=path, field=field + ".file")
    note_read(file)
    try:
        loaded = trimesh.load(file, force="mesh", process=False, resolver=_RecordingResolver(file))
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise DiviewerError(f"cannot read mesh file {file}: {exc}", path=path, field=field + ".file") from exc
    if not isinstance(loaded, trimesh.Trimesh):
        raise DiviewerError(f"{file} holds no triangle mesh", path=path, field=field + ".file")
    base_color, texture = None, None
    material = getattr(getattr(loaded, "visual", None), "material", None)
    if material is not None:
        factor = getattr(material, "baseColorFactor", None)
        if factor is not None:
            base_color = tuple(float(c) / 255.0 if np.asarray(factor).dtype == np.uint8 else float(c) for c in factor[:3])
        image = getattr(material, "baseColorTexture", None) or getattr(material, "image", None)
        if image is not None:
            if max(image.size) > MAX_TEXTURE_SIDE:
                raise DiviewerError(f"the texture of {file} is {image.size[0]}x{image.size[1]}, larger than "
                                    f"{MAX_TEXTURE_SIDE} px on a side; downscale it", path=path, field=field + ".file")
            texture = decode(image, file, path=path, field=field + ".file")[0]
    mesh = from_trimesh(name, loaded, source=str(file), path=path, field=field, strict=True)
    return mesh, base_color, texture

