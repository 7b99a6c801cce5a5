"""What names a frame outside the renderer: ``WxH`` resolutions and the frame.json record (written and read).

Used by `diviewer render`, `capture`, the CLI and the viewer's screenshots, so none of them imports
another command's module.
"""

from __future__ import annotations

import json
from pathlib import Path

from diviewer.errors import DiviewerError
from diviewer.provenance import versions
from diviewer.scene.loader import add_mesh_file, config_from_dict
from diviewer.scene.model import FrameConfig, Scene


def parse_resolution(text: str, field: str = "--res") -> tuple[int, int]:
    """``256`` (square) or ``320x240`` (width x height)."""
    try:
        parts = [int(p) for p in str(text).lower().split("x")]
    except ValueError:
        parts = []
    if len(parts) == 1:
        parts = parts * 2
    if len(parts) != 2 or min(parts) < 1 or max(parts) > 16384:
        raise DiviewerError(f"resolution must be N or WxH with 1 <= N <= 16384, got '{text}'", field=field)
    return parts[0], parts[1]


def frame_record(scene: Scene, config: FrameConfig, size: tuple[int, int], **extra) -> dict:
    """The frame.json content: enough to render the same frame again."""
    return {
        "scene": scene.name,
        "scene_file": str(scene.path) if scene.path else None,
        "scene_hash": scene.file_hash,
        "resolution": list(size),
        **extra,
        "config": config.to_dict(),
        "versions": versions(),
    }


def load_frame_json(scene: Scene, path: Path) -> FrameConfig:
    """The configuration stored in a frame.json (or a viewer screenshot's JSON).

    ``scene`` must hold the mesh files the frame uses (``scene_for_frame_json`` adds them).
    """
    return config_from_dict(scene, read_frame_json(scene, path)["config"], path=path)


def scene_for_frame_json(scene: Scene, path: Path) -> Scene:
    """The scene with the mesh files a frame.json records (``user_meshes``, from the viewer) added."""
    return with_user_meshes(scene, read_frame_json(scene, path))


def with_user_meshes(scene: Scene, data: dict) -> Scene:
    """The scene with the mesh files a read frame.json records added under their keys."""
    for key, file in (data.get("user_meshes") or {}).items():
        scene, _, _ = add_mesh_file(scene, file, key)
    return scene


def read_frame_json(scene: Scene, path: Path) -> dict:
    """A frame.json's content, checked to hold a configuration made with this version of the scene file."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DiviewerError(f"cannot read frame configuration: {exc}", path=path) from exc
    if not isinstance(data, dict):
        raise DiviewerError(f"expected a JSON object, got {type(data).__name__}", path=path)
    if "config" not in data:
        raise DiviewerError("missing the 'config' table written by diviewer render", path=path, field="config")
    meshes = data.get("user_meshes")
    if meshes is not None and not (isinstance(meshes, dict) and all(isinstance(v, str) for v in meshes.values())):
        raise DiviewerError("expected a table of mesh file names", path=path, field="user_meshes")
    if data.get("scene_hash") and data["scene_hash"] != scene.file_hash:
        raise DiviewerError(f"this frame was made with another version of scene '{data.get('scene')}' "
                            f"(scene file hash differs)", path=path, field="scene_hash")
    return data
