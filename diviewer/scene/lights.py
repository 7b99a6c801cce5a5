"""Light math shared by the configuration sampler and the viewer: turning a light, its power, its angles. No GL."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from diviewer.scene import camera as cam
from diviewer.scene.model import DirectionalLight, PointLight


def rotate_light(light, axis, angle: float, centre):
    """The light turned by ``angle`` degrees about ``axis`` through ``centre``: a sun's direction turns, a point
    light's position moves about the centre. The sampler and the viewer's animation both use this one."""
    rot = cam.axis_angle(axis, angle)
    if isinstance(light, DirectionalLight):
        d = rot @ np.asarray(light.direction)
        return dataclasses.replace(light, direction=tuple(map(float, d / np.linalg.norm(d))))
    assert isinstance(light, PointLight)
    c = np.asarray(centre)
    p = c + rot @ (np.asarray(light.position) - c)
    return dataclasses.replace(light, position=tuple(map(float, p)))


def power_field(light) -> str:
    """The field that holds a light's power: a sun's irradiance, a point light's intensity."""
    return "irradiance" if isinstance(light, DirectionalLight) else "intensity"


def scale_light(light, factor: float):
    """The light with its power (irradiance or intensity) times ``factor``."""
    f = power_field(light)
    return dataclasses.replace(light, **{f: getattr(light, f) * factor})


def angles_to_vector(azimuth: float, elevation: float) -> np.ndarray:
    """Unit vector (y up) at ``azimuth`` degrees about +y (from +z towards +x), ``elevation`` degrees above the
    horizon."""
    a, e = math.radians(azimuth), math.radians(elevation)
    return np.array([math.cos(e) * math.sin(a), math.sin(e), math.cos(e) * math.cos(a)])


def vector_to_angles(v) -> tuple[float, float]:
    """Inverse of ``angles_to_vector``: (azimuth, elevation) in degrees of a direction."""
    x, y, z = cam.normalize(v)
    return math.degrees(math.atan2(x, z)), math.degrees(math.asin(float(np.clip(y, -1.0, 1.0))))
