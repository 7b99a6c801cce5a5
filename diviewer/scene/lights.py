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


def box_sweep(box, phase: float) -> tuple[float, float, float]:
    """A point on a closed curve through a light's position box (``LightRange.position``) at ``phase`` radians: each
    axis swings between its min and max at its own rate (1, 2 and 3 turns a period), so the curve stays inside
    the box and crosses most of it. The viewer's light animation uses it for a point light with a box."""
    lo, hi = np.asarray(box[0], np.float64), np.asarray(box[1], np.float64)
    swing = 0.5 - 0.5 * np.cos(np.array([1.0, 2.0, 3.0]) * phase)
    return tuple(map(float, lo + (hi - lo) * swing))


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


def light_scale(scene, config) -> float:
    """The frame's light scale: how much light enters it, from its light sources (never from an image).

    Sum over the lights of luminance(color) x irradiance (a sun) or x intensity (a point light), plus the
    emission luminance of every emissive material the frame's objects use (a textured emitter's brightest texel
    times its factor: `Material.peak_emission`, so it scales as a uniform one of that radiance), plus the sky's (the scene's
    ambient radiance, an emitter of the path tracer). Encoding version 2 divides the network's radiance
    input by it and multiplies its output back, so GI is linear in the light by construction: zero light
    gives exactly zero, twice the light twice the frame. A camera looking into a shaded corner sees no
    direct light but has GI, which is why the scale comes from the sources and not from the pixels.
    Training, export checks, the runtime and the viewer all call this one function.
    """
    from diviewer.scene.colour import luminance

    s = 0.0
    for l in config.lights:
        s += luminance(l.color) * float(getattr(l, power_field(l)))
    used = {o.material for o in config.objects}
    for name in sorted(used):
        m = scene.materials.get(name)
        if m is not None and m.is_emissive:
            s += luminance(m.peak_emission)
    s += luminance(scene.ambient)
    return s


LIGHT_PARAMS = 3
"""Numbers per light in `light_params`."""


def light_params(lights, center, half) -> np.ndarray:
    """Where each light is, as encoding version 4 gives it to the network: (3 L,) float32, L = len(lights), in
    their order. A sun: the unit direction its light travels. A point light: its position normalised as the world
    planes are, ``clip((p - center) / half, -1, 1)`` (``center``, ``half``: the encoding's world box). What a
    light's strength is stays out: the light scale carries it (encoding 2). ``lights``: the scene's light objects or
    the dicts a dataset's frame configurations store (``type``, ``direction`` or ``position``)."""
    out = []
    c, h = np.asarray(center, np.float64), np.asarray(half, np.float64)
    for light in lights:
        get = (lambda k, x=light: x[k]) if isinstance(light, dict) else (lambda k, x=light: getattr(x, k))
        sun = light.get("type") == "directional" if isinstance(light, dict) else isinstance(light, DirectionalLight)
        if sun:
            d = np.asarray(get("direction"), np.float64)
            n = float(np.linalg.norm(d))
            out.append(d / n if n > 0 and math.isfinite(n) else np.zeros(3))
        else:
            out.append(np.clip((np.asarray(get("position"), np.float64) - c) / h, -1.0, 1.0))
    return np.concatenate(out).astype(np.float32) if out else np.zeros(0, np.float32)
