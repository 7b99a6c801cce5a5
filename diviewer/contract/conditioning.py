"""A frame's conditioning: what the network takes besides the frame's buffers, derived once from the scene, the
frame's configuration, its size and the model's encoding.

- the light scale (encoding version 2 and later, `diviewer.scene.lights.light_scale`): the graph divides the
  direct light by it and multiplies its output back;
- the camera (version 3 and later, `diviewer.scene.camera.camera_params` of the whole frame): the graph makes
  each pixel's world position and normal from it;
- the lights (version 4, `diviewer.scene.lights.light_params` in the encoding's world box): where each light is.

`conditioning` is the one place the encoding's version decides what a frame's conditioning holds: the runtime
(`NeuralGI.frame_inputs`), the viewer's neural pass, evaluation, training's targets, the bench's int8 calibration
and export's verification frames all call it; `stand_in` is its twin for procedural buffers with no scene behind
them (export's verification frames without a dataset, the runtime's probe). No GL, no torch (training turns the
arrays into tensors).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from diviewer.contract.encoding import Encoding
from diviewer.errors import DiviewerError


@dataclass(frozen=True)
class Conditioning:
    """One frame's conditioning; a field the encoding does not take is None."""

    light_scale: float | None = None
    """How much light enters the frame (encoding 2 and later)."""
    camera: np.ndarray | None = None
    """(CAMERA_PARAMS,) float32: the frame's camera at its size (encoding 3 and later)."""
    lights: np.ndarray | None = None
    """(3 L,) float32: where each of its L lights is (encoding 4)."""

    def inputs(self) -> dict[str, Any]:
        """The keyword arguments of ``NeuralGI.run`` (and of every runtime's ``run``): light_scale, camera, light,
        those the encoding does not take left out."""
        pairs = (("light_scale", self.light_scale), ("camera", self.camera), ("light", self.lights))
        return {k: v for k, v in pairs if v is not None}


def stacked(conds) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """N frames' conditionings (one encoding's) as arrays: (N,) float32 light scales, (N, CAMERA_PARAMS) cameras and
    (N, 3 L) lights, None for a part the encoding does not take."""
    def stack(name):
        parts = [getattr(c, name) for c in conds]
        return None if not parts or parts[0] is None else np.asarray(np.stack(parts), np.float32)

    return stack("light_scale"), stack("camera"), stack("lights")


def as_encoding(encoding: Encoding | Mapping[str, Any]) -> Encoding:
    """``encoding`` as an `Encoding` (a model's metadata or a manifest stores its dict)."""
    return encoding if isinstance(encoding, Encoding) else Encoding.from_dict(encoding)


def needs_scene(encoding: Encoding | Mapping[str, Any]) -> bool:
    """Whether a frame's conditioning under ``encoding`` needs the scene (its light scale does: the materials' and
    the sky's emission)."""
    return as_encoding(encoding).light_scaled


def has_lights_for(config, encoding: Encoding | Mapping[str, Any]) -> bool:
    """Whether a stored configuration (a dataset frame's dict, or None) holds the lights ``encoding`` takes: as many
    as it takes, where it takes any."""
    enc = as_encoding(encoding)
    return not enc.light_inputs or len((config or {}).get("lights") or []) == enc.lights


def _get(obj, key: str):
    return obj[key] if isinstance(obj, Mapping) else getattr(obj, key)


def conditioning(scene, config, size: tuple[int, int], encoding: Encoding | Mapping[str, Any], *,
                 path=None) -> Conditioning:
    """The conditioning of a ``size`` (width, height) frame of ``config`` under ``encoding``.

    ``config``: a `FrameConfig`, or the dict a dataset or an evaluation set stores (`FrameConfig.to_dict`), read
    against ``scene`` for its light scale (``path``: the file it came from, named in its errors). ``scene`` is
    needed only where `needs_scene` says so. A frame without a configuration (None) has a conditioning only under
    encoding 1, which takes none.
    """
    enc = as_encoding(encoding)
    if not enc.light_scaled:
        return Conditioning()
    if config is None:
        raise DiviewerError(f"the frame has no stored configuration, so no light scale, camera or lights for a "
                            f"model of encoding version {enc.version}", path=path, field="config")
    if scene is None:
        raise ValueError(f"encoding version {enc.version}: a frame's light scale needs the scene")
    from diviewer.scene.lights import light_scale

    frame = config
    if isinstance(config, Mapping):
        from diviewer.scene import config_from_dict

        frame = config_from_dict(scene, config, path=path)
    scale = light_scale(scene, frame)
    camera = frame_camera(_get(config, "camera"), size) if enc.world_inputs else None
    lights = frame_lights(_get(config, "lights"), enc) if enc.light_inputs else None
    return Conditioning(scale, camera, lights)


STAND_IN_CAMERA = {"position": [0.0, 1.0, 3.0], "target": [0.0, 1.0, 0.0], "up": [0.0, 1.0, 0.0], "fov": 45.0}
"""`stand_in`'s camera unless given: 3 units in front of the point (0, 1, 0), looking at it."""


def stand_in(encoding: Encoding | Mapping[str, Any], size: tuple[int, int], *, light_scale: float = 1.0,
             camera=STAND_IN_CAMERA, sun=(0.0, -1.0, 0.0)) -> Conditioning:
    """The conditioning under ``encoding`` of a ``size`` (width, height) frame of procedural buffers, with no scene
    or configuration behind it: ``light_scale``, ``camera`` (a scene camera or its dict) over the whole frame, and
    a sun shining along ``sun`` for each light the encoding takes; the parts the encoding does not take left out."""
    enc = as_encoding(encoding)
    suns = [{"type": "directional", "direction": list(sun)}] * (enc.lights or 0)
    return Conditioning(float(light_scale) if enc.light_scaled else None,
                        frame_camera(camera, size) if enc.world_inputs else None,
                        frame_lights(suns, enc) if enc.light_inputs else None)


def frame_camera(camera, size: tuple[int, int]) -> np.ndarray:
    """The camera part of a ``size`` (width, height) frame's conditioning: `camera_params` of a scene camera
    (position, target, up, fov: `diviewer.scene.Camera` or its dict) over the whole frame."""
    from diviewer.scene.camera import camera_params

    return camera_params(_get(camera, "position"), _get(camera, "target"), _get(camera, "up"), _get(camera, "fov"),
                         *size)


def frame_lights(lights, encoding: Encoding | Mapping[str, Any]) -> np.ndarray:
    """The lights part of a frame's conditioning: `light_params` of its lights (the scene's light objects or a
    stored configuration's dicts) in ``encoding``'s world box; ValueError unless there are as many as it takes."""
    from diviewer.scene.lights import light_params

    enc = as_encoding(encoding)
    if len(lights) != enc.lights:
        raise ValueError(f"the model takes {enc.lights} light(s); the frame has {len(lights)}")
    return light_params(lights, enc.world_center, enc.world_half)
