"""Small scenes built in code for analytic tests (no files needed)."""

from __future__ import annotations

import math

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
