"""Scene data (no GL, no torch): the model, TOML loading, procedural meshes, sampling."""

from diviewer.scene.loader import config_from_dict, load_scene, resolve_scene_path
from diviewer.scene.model import (
    Camera, DirectionalLight, FrameConfig, Material, Mesh, Object, PointLight, Scene,
)
from diviewer.scene.sampler import sample_config

__all__ = [
    "Camera", "DirectionalLight", "FrameConfig", "Material", "Mesh", "Object", "PointLight", "Scene",
    "config_from_dict", "load_scene", "resolve_scene_path", "sample_config",
]
