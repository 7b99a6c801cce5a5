"""A closed procedural room written by tests: box walls, a pedestal, an emissive ceiling panel and a point light.

The room's inside spans x in [-2, 2], y in [0, 3], z in [-2, 2]; its walls are 0.2 thick, so the scene's bounds are
x, z in [-2.2, 2.2], y in [-0.2, 3.2]. The pedestal fills x, z in [-0.4, 0.4], y in [0, 1].
"""

from __future__ import annotations

from pathlib import Path

ROOM_TOML = """[scene]
name = "room"

[camera]
position = [0.0, 1.5, 1.8]
target = [0.0, 1.0, 0.0]
fov = 60.0
near = 0.05
far = 20.0

[materials.wall]
albedo = [0.7, 0.7, 0.7]
[materials.panel]
albedo = [0.8, 0.8, 0.8]
emission = [4.0, 4.0, 4.0]

[meshes.slab]
shape = "box"
size = [4.4, 0.2, 4.4]
[meshes.side]
shape = "box"
size = [0.2, 3.0, 4.0]
[meshes.end]
shape = "box"
size = [4.0, 3.0, 0.2]
[meshes.pedestal]
shape = "box"
size = [0.8, 1.0, 0.8]
[meshes.panel]
shape = "box"
size = [1.0, 0.02, 1.0]

[[objects]]
name = "floor"
mesh = "slab"
material = "wall"
position = [0.0, -0.1, 0.0]
[[objects]]
name = "ceiling"
mesh = "slab"
material = "wall"
position = [0.0, 3.1, 0.0]
[[objects]]
name = "left"
mesh = "side"
material = "wall"
position = [-2.1, 1.5, 0.0]
[[objects]]
name = "right"
mesh = "side"
material = "wall"
position = [2.1, 1.5, 0.0]
[[objects]]
name = "back"
mesh = "end"
material = "wall"
position = [0.0, 1.5, -2.1]
[[objects]]
name = "front"
mesh = "end"
material = "wall"
position = [0.0, 1.5, 2.1]
[[objects]]
name = "pedestal"
mesh = "pedestal"
material = "wall"
position = [0.0, 0.5, 0.0]
[[objects]]
name = "panel"
mesh = "panel"
material = "panel"
position = [0.0, 2.98, 0.0]

[[lights]]
name = "lamp"
type = "point"
position = [1.0, 2.5, 1.0]
intensity = 5.0
"""


def write_room(folder: Path, extra: str = "") -> Path:
    """ROOM_TOML with ``extra`` appended, written as ``folder/room.toml``."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "room.toml"
    path.write_text(ROOM_TOML + extra)
    return path
