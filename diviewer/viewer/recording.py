"""Recording a flight in the viewer as a camera path (`diviewer.scene.camera_path`). Pure data: no GL.

Each frame drawn while recording becomes a key at the viewer's clock (seconds since the recording began, the sum
of the frames' time steps: the wall clock, or ``--fixed-step``); when the recording stops the keys are thinned
(`thin_keys`: at least every tenth frame, and more where the motion bends) and written atomically. With a fixed
step every frame is kept, so a replay with the same step draws each recorded frame exactly.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diviewer.scene.camera_path import RECORD_TOLERANCE, CameraPath, PathKey, thin_keys, write_path
from diviewer.scene.model import FrameConfig, Scene


def free_name(scene: Scene, folder: Path = Path(".")) -> Path:
    """``diviewer_<scene>_path.json`` in ``folder``, numbered (``_2``, ``_3`` ...) past files already there."""
    n = 1
    while True:
        name = folder / (f"diviewer_{scene.name}_path.json" if n == 1 else f"diviewer_{scene.name}_path_{n}.json")
        if not name.exists():
            return name
        n += 1


class Recorder:
    """The keys of one recording; ``file`` None picks a free name when it is written."""

    def __init__(self, scene: Scene, file: str | Path | None = None, exact: bool = False):
        self.scene, self.file, self.exact = scene, Path(file) if file is not None else None, exact
        self.keys: list[PathKey] = []
        self.time = 0.0

    def add(self, dt: float, config: FrameConfig) -> None:
        """The frame drawn ``dt`` seconds after the last one recorded (the first is at time 0)."""
        if self.keys:
            self.time += dt
        self.keys.append(PathKey(self.time, config.camera, config.lights, config.objects))

    def path(self, scene: Scene) -> CameraPath:
        """The recording as a path of ``scene`` (the viewer's scene, with the mesh files it loaded)."""
        size = float(np.linalg.norm(np.ptp(self.scene.bounds(), axis=0))) or 1.0
        keys = thin_keys(self.keys, scale=size, tolerance=None if self.exact else RECORD_TOLERANCE)
        return CameraPath(tuple(keys), scene.name, scene.file_hash)

    def write(self, scene: Scene, user_meshes: dict | None = None) -> Path | None:
        """Write the recording (nothing when no frame was recorded); returns the file."""
        if not self.keys:
            return None
        path = self.path(scene)
        if user_meshes:
            path = CameraPath(path.keys, path.scene, path.scene_hash, path.closed, dict(user_meshes))
        file = self.file or free_name(self.scene)
        write_path(file, path)
        return file
