"""What a dataset's targets are divided by: each captured frame's light scale (`diviewer.scene.lights.light_scale`)
from its stored configuration and the scene the dataset was captured from (what encoding version 2 divides training
data by, and what `diviewer eval` passes to an encoding-2 model), and the albedo with its floor (``divide_albedo``).
No torch."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from diviewer.data.dataset import Dataset

ALBEDO_FLOOR: float = 0.05
"""With divide_albedo, indirect light is divided by max(albedo, ALBEDO_FLOOR) and multiplied back by
the same: exactly invertible, and dark or background pixels (albedo 0) do not amplify noise."""


def floored_albedo(albedo: np.ndarray) -> np.ndarray:
    """Albedo within [ALBEDO_FLOOR, 1], a NaN taken as black (`diviewer.train.targets`' floor, in numpy)."""
    return np.clip(np.where(np.isnan(albedo), 0.0, albedo), ALBEDO_FLOOR, 1.0)


def dataset_scene(ds: Dataset):
    """The scene a dataset was captured from: its manifest's copy of the scene file (read against the file's
    folder, for the meshes it names), else the scene by file or name as it is now."""
    import tomllib

    from diviewer.errors import DiviewerError
    from diviewer.scene import load_scene
    from diviewer.scene.loader import parse_scene

    m = ds.manifest
    if m.get("scene_toml") and m.get("scene_file"):
        try:
            return parse_scene(tomllib.loads(m["scene_toml"]), path=Path(m["scene_file"]))
        except (DiviewerError, OSError, tomllib.TOMLDecodeError):
            pass  # its meshes moved: the scene as it is now
    for name in (m.get("scene_file"), m.get("scene")):
        if name:
            try:
                return load_scene(name)
            except (DiviewerError, OSError):
                continue
    raise DiviewerError(f"cannot load scene '{m.get('scene')}' of the dataset (its lights and emitters give each "
                        "frame's light scale); train with --no-light-scale, or restore the scene file",
                        path=ds.root / "manifest.json", field="scene")


def light_scales(ds: Dataset, indices: list[int]) -> np.ndarray:
    """Each frame's light scale (`diviewer.scene.lights.light_scale`) from its stored configuration, float32."""
    from diviewer.errors import DiviewerError
    from diviewer.scene import config_from_dict
    from diviewer.scene.lights import light_scale

    scene = dataset_scene(ds)
    by_index = {f["index"]: f for f in ds.frames}
    out = np.empty(len(indices), np.float32)
    for k, i in enumerate(indices):
        config = (by_index.get(i) or {}).get("config")
        if not isinstance(config, dict):
            raise DiviewerError(f"frame {i} has no stored configuration, so no light scale; train with "
                                "--no-light-scale", path=ds.root / "manifest.json", field="frame_list")
        out[k] = light_scale(scene, config_from_dict(scene, config, path=ds.root / "manifest.json"))
    return out
