"""Small scenes built in code for analytic tests (no files needed)."""

from __future__ import annotations

import math
from pathlib import Path

from diviewer.scene.loader import parse_scene


def facing_plane(distance: float = 3.0, albedo=(0.5, 0.25, 0.75), lights=(), fov: float = 40.0,
                 near: float = 0.1, far: float = 100.0, extra_objects=(), extra_meshes=None):
    """A camera at the origin looking down -z at a big square facing it at ``distance``."""
    # Just larger than the view: the directional shadow map is fitted to the scene's bounds.
    size = 2.4 * distance * math.tan(math.radians(fov) / 2) + 1.0
    data = {
        "scene": {"name": "plane"},
        "camera": {"position": [0, 0, 0], "target": [0, 0, -1], "up": [0, 1, 0], "fov": fov, "near": near, "far": far},
        "materials": {"m": {"albedo": list(albedo)}, "occ": {"albedo": [0.5, 0.5, 0.5]}},
        "meshes": {"wall": {"shape": "box", "size": [size, size, 0.5]}, **(extra_meshes or {})},
        "objects": [{"name": "wall", "mesh": "wall", "material": "m", "position": [0, 0, -distance - 0.25]},
                    *extra_objects],
        "lights": list(lights),
    }
    return parse_scene(data)


TINY_SCENE_TOML = """
[scene]
name = "tiny"

[camera]
position = [0.0, 1.0, 3.0]
target = [0.0, 0.6, 0.0]
up = [0.0, 1.0, 0.0]
fov = 45.0
near = 0.1
far = 10.0

[materials.white]
albedo = [0.7, 0.7, 0.7]
[materials.red]
albedo = [0.6, 0.1, 0.1]

[meshes.floor]
shape = "box"
size = [3.0, 0.1, 3.0]
[meshes.wall]
shape = "box"
size = [3.0, 2.0, 0.1]
[meshes.cube]
shape = "box"
size = [0.6, 0.6, 0.6]
[meshes.sphere]
shape = "sphere"
radius = 0.35

[[objects]]
name = "floor"
mesh = "floor"
material = "white"
position = [0.0, -0.05, 0.0]
[[objects]]
name = "back"
mesh = "wall"
material = "red"
position = [0.0, 1.0, -1.0]
[[objects]]
name = "center"
mesh = "cube"
material = "white"
position = [0.0, 0.4, 0.0]

[[lights]]
name = "sun"
type = "directional"
direction = [0.3, -0.8, -0.5]
color = [1.0, 1.0, 1.0]
irradiance = 3.0

[ranges.lights.sun]
axis = [0.0, 1.0, 0.0]
angle = [-60.0, 60.0]

[ranges.objects.center]
axes = [[0.0, 1.0, 0.0]]
angle = [0.0, 360.0]
train_meshes = ["cube"]
test_meshes = ["sphere"]
"""
"""A procedural scene small enough to capture, train and evaluate end to end in seconds (`write_tiny_scene`)."""


def write_tiny_scene(folder) -> Path:
    """Write the tiny scene as folder/tiny.toml (a scene file, as `diviewer build --scene` takes one)."""

    path = Path(folder) / "tiny.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(TINY_SCENE_TOML)
    return path


def emissive_tile(emission=(2.0, 1.0, 0.5), albedo=(0.0, 0.0, 0.0)):
    """A thin closed slab (2 x 2 x 0.02, closed: Mitsuba's area emitters need it) facing a camera 2.5 away, its
    material emitting ``emission`` times a 16 x 8 texture whose left half is 1 and right half 0.25, on a grey wall.

    Every vertex's uv follows its x and y: u from the first texel's centre (x = -1) to the last's (x = 1), v from 0
    (bottom) to 1 (top); so each face glows by its x alone, the texture never wraps, and the seam is at x = 0.
    """
    import dataclasses

    import numpy as np

    from diviewer.scene.model import Mesh, Object

    corners = np.array([[x, y, z] for z in (0.01, -0.01) for y in (-1, 1) for x in (-1, 1)], np.float32)
    quads = [((0, 1, 3, 2), (0, 0, 1)), ((5, 4, 6, 7), (0, 0, -1)), ((4, 0, 2, 6), (-1, 0, 0)),
             ((1, 5, 7, 3), (1, 0, 0)), ((2, 3, 7, 6), (0, 1, 0)), ((4, 5, 1, 0), (0, -1, 0))]
    verts = np.array([corners[i] for quad, _ in quads for i in quad], np.float32)
    normals = np.repeat(np.array([n for _, n in quads], np.float32), 4, axis=0)
    uvs = np.stack([1 / 32 + (verts[:, 0] + 1) / 2 * 15 / 16, (verts[:, 1] + 1) / 2], axis=1).astype(np.float32)
    faces = np.array([(4 * k + a, 4 * k + b, 4 * k + c) for k in range(6) for a, b, c in ((0, 1, 2), (0, 2, 3))],
                     np.uint32)
    tile = Mesh("tile", verts, normals, faces, uvs=uvs)
    texture = np.full((8, 16, 3), 0.25, np.float32)
    texture[:, :8] = 1.0
    scene = parse_scene({
        "camera": {"position": [0, 0, 2.5], "target": [0, 0, 0], "fov": 60},
        "materials": {"glow": {"albedo": list(albedo), "emission": list(emission)}, "grey": {"albedo": [0.5] * 3}},
        "meshes": {"wall": {"shape": "box", "size": [8, 8, 0.1]}},
        "objects": [{"name": "wall", "mesh": "wall", "material": "grey", "position": [0, 0, -1]}]})
    glow = dataclasses.replace(scene.materials["glow"], emission_texture=texture)
    default = dataclasses.replace(scene.default, objects=(*scene.default.objects, Object("tile", "tile", "glow")))
    return dataclasses.replace(scene, meshes={**scene.meshes, "tile": tile}, materials={**scene.materials, "glow": glow},
                               default=default)
