"""Whether a frame lies inside what a scene's model was trained on: the scene file's ranges, checked. No GL, no torch.

The capture draws cameras, lights and objects from ``Scene.ranges`` (scene/sampler.py); a frame outside them
is one the network never saw. ``out_of_range`` lists why, one human-readable reason per thing outside, so
the viewer can say so (panel, ``--stats``) instead of leaving a bad frame unexplained.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from diviewer.scene.model import (CameraRange, CameraRegion, DirectionalLight, FrameConfig, LightRange, ObjectRange,
                                  Scene, box_contains)
from diviewer.scene.sampler import catmull_rom, in_test_stretch

ANGLE_TOL = 0.5
"""Degrees of slack on every angle test (a panel slider or float round-off is not a new configuration)."""
REL_TOL = 1e-4
"""Relative slack on intensities, scales and positions."""
PATH_SAMPLES = 2048
"""Points a camera path is sampled at to find the point nearest the camera."""


def _fmt(v) -> str:
    return "(" + ", ".join(f"{float(x):.2f}" for x in v) + ")"


def _angle(a, b) -> float:
    """Degrees between two vectors."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    c = float(a @ b) / max(float(np.linalg.norm(a) * np.linalg.norm(b)), 1e-30)
    return math.degrees(math.acos(min(max(c, -1.0), 1.0)))


def _view_dir(camera) -> np.ndarray:
    d = np.asarray(camera.target, np.float64) - np.asarray(camera.position, np.float64)
    return d / max(float(np.linalg.norm(d)), 1e-30)


def _same_camera(a, b) -> bool:
    return (np.allclose(a.position, b.position, atol=1e-6) and _angle(_view_dir(a), _view_dir(b)) <= ANGLE_TOL
            and abs(a.fov - b.fov) <= ANGLE_TOL)


def camera_region_reasons(region: CameraRegion, camera, default_camera=None) -> list[str]:
    """Why a camera lies outside a free-camera region (empty: inside, or the scene's own camera when the
    region keeps it for a share of the frames)."""
    if default_camera is not None and region.default_share > 0.0 and _same_camera(camera, default_camera):
        return []
    out = []
    p = np.asarray(camera.position, np.float64)
    if not box_contains(region.region, p, margin=1e-6):
        box = f"{_fmt(region.region[0])}-{_fmt(region.region[1])}"
        out.append(f"camera at {_fmt(p)} is outside the trained region {box}")
    elif region.in_test_region(p):
        out.append(f"camera at {_fmt(p)} is in a held-out test region (never in training)")
    to_target = np.asarray(region.target, np.float64) - p
    if np.linalg.norm(to_target) > 1e-9:
        off = _angle(_view_dir(camera), to_target)
        reach = math.degrees(region.max_look_offset(p))
        if off > reach + ANGLE_TOL:
            out.append(f"camera looks {off:.0f} deg away from the scene's target; trained within {reach:.0f} deg "
                       f"from here")
    lo, hi = region.fov
    if not lo - ANGLE_TOL <= camera.fov <= hi + ANGLE_TOL:
        out.append(f"field of view {camera.fov:.0f} deg is outside the trained {lo:.0f}-{hi:.0f} deg")
    return out


@lru_cache(maxsize=8)
def _path_points(path: CameraRange) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The path sampled densely: parameters, positions and unit view directions."""
    s = np.linspace(0.0, 1.0, PATH_SAMPLES)
    pos, tgt = np.asarray(path.positions, np.float64), np.asarray(path.targets, np.float64)
    p = np.array([catmull_rom(pos, float(u), path.closed) for u in s])
    d = np.array([catmull_rom(tgt, float(u), path.closed) for u in s]) - p
    return s, p, d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-30)


def camera_path_reasons(path: CameraRange, camera, default_camera, reach: float, max_turn: float = 30.0) -> list[str]:
    """Why a camera lies off a camera path: farther than ``reach`` (scene units) from it, looking more than
    ``max_turn`` degrees away from the path's view there, another field of view, or on a held-out stretch."""
    if len(path.positions) < 2:
        return []
    s, pts, dirs = _path_points(path)
    p = np.asarray(camera.position, np.float64)
    dist = np.linalg.norm(pts - p, axis=1)
    i = int(np.argmin(dist))
    out = []
    if dist[i] > reach:
        out.append(f"camera is {dist[i]:.1f} from the trained camera path (allowed {reach:.1f})")
    else:
        turn = _angle(_view_dir(camera), dirs[i])
        if turn > max_turn:
            out.append(f"camera looks {turn:.0f} deg away from the path's view here (allowed {max_turn:.0f})")
        if in_test_stretch(path, float(s[i])):
            out.append("camera is on a held-out stretch of the path (never in training)")
    if abs(camera.fov - default_camera.fov) > ANGLE_TOL:
        out.append(f"field of view {camera.fov:.0f} deg; the path was trained at {default_camera.fov:.0f} deg")
    return out


def _signed_angle(a: np.ndarray, b: np.ndarray, axis: np.ndarray) -> float:
    """Degrees from ``a`` to ``b`` about ``axis`` (both projected onto the plane normal to it)."""
    a = a - axis * (a @ axis)
    b = b - axis * (b @ axis)
    return math.degrees(math.atan2(float(axis @ np.cross(a, b)), float(a @ b)))


def _power(light) -> float:
    return float(light.irradiance if isinstance(light, DirectionalLight) else light.intensity)


def light_reasons(light, default, r: LightRange | None, centre) -> list[str]:
    """Why a light lies outside its range: turned off its sweep, another power or colour."""
    name = f"light '{light.name}'"
    if type(light) is not type(default):
        return [f"{name} is a {light.kind} light; the model knows it as a {default.kind} light"]
    r = r or LightRange()
    axis = np.asarray(r.axis, np.float64)
    axis = axis / max(float(np.linalg.norm(axis)), 1e-30)
    if isinstance(light, DirectionalLight):
        v, v0 = np.asarray(light.direction, np.float64), np.asarray(default.direction, np.float64)
    else:
        c = np.asarray(centre, np.float64)
        v, v0 = np.asarray(light.position, np.float64) - c, np.asarray(default.position, np.float64) - c
    out = []
    n, n0 = float(np.linalg.norm(v)), float(np.linalg.norm(v0))
    tilt = _angle(v, axis) - _angle(v0, axis)  # rotating about the axis keeps the angle to it
    if r.position is not None:  # a point light drawn from a box of positions
        size = float(np.linalg.norm(np.subtract(r.position[1], r.position[0])))
        if not box_contains(r.position, light.position, margin=REL_TOL * max(size, 1.0)):
            out.append(f"{name} at {_fmt(light.position)} is outside its trained box "
                       f"{_fmt(r.position[0])}-{_fmt(r.position[1])}")
    elif abs(tilt) > ANGLE_TOL or abs(n - n0) > REL_TOL * max(n0, 1.0):
        what = "direction" if isinstance(light, DirectionalLight) else "position"
        out.append(f"{name}'s {what} leaves its trained sweep about {_fmt(axis)} (tilted {tilt:+.0f} deg)")
    else:
        angle = _signed_angle(v0, v, axis)
        lo, hi = r.angle
        if not any(lo - ANGLE_TOL <= a <= hi + ANGLE_TOL for a in (angle, angle - 360.0, angle + 360.0)):
            out.append(f"{name} is turned {angle:.0f} deg; trained {lo:.0f} to {hi:.0f} deg")
    p0 = _power(default)
    factor = _power(light) / p0 if p0 > 0 else (1.0 if _power(light) == 0 else math.inf)
    lo, hi = r.intensity
    if not lo * (1 - REL_TOL) <= factor <= hi * (1 + REL_TOL):
        out.append(f"{name}'s power is x{factor:.2f} of the scene's; trained x{lo:.2f} to x{hi:.2f}")
    if not np.allclose(light.color, default.color, atol=1e-4):
        out.append(f"{name}'s colour {_fmt(light.color)} differs from the trained {_fmt(default.color)}")
    return out


def _rotation_in_range(rot: np.ndarray, rot0: np.ndarray, r: ObjectRange) -> bool:
    """Whether ``rot`` is ``rot0`` turned as the range allows: none without axes, about the one axis within
    ``angle``, or any rotation with two axes or more (the sampler's composed draws cover all of them)."""
    rel = rot @ rot0.T
    turn = math.degrees(math.acos(min(max((np.trace(rel) - 1.0) / 2.0, -1.0), 1.0)))
    if turn <= ANGLE_TOL:
        return True
    if not r.axes:
        return False
    if len(r.axes) >= 2:
        return True
    lo, hi = r.angle
    if hi - lo >= 360.0 - ANGLE_TOL:
        axis = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
        if np.linalg.norm(axis) < 1e-9:  # a half turn: the axis is the eigenvector of eigenvalue 1
            w, vecs = np.linalg.eig(rel)
            axis = np.real(vecs[:, int(np.argmin(np.abs(w - 1.0)))])
        return _angle(axis, r.axes[0]) <= ANGLE_TOL or _angle(-axis, r.axes[0]) <= ANGLE_TOL
    a = np.asarray(r.axes[0], np.float64)
    a = a / np.linalg.norm(a)
    from diviewer.scene import camera as cam

    # The sampler's rotation: axis_angle(axis, t) @ rot0 for t in [lo, hi]; find t from a vector normal to the axis.
    e = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    t = _signed_angle(e, rel @ e, a)
    if not np.allclose(cam.axis_angle(a, t), rel, atol=1e-4):
        return False
    return any(lo - ANGLE_TOL <= x <= hi + ANGLE_TOL for x in (t, t - 360.0, t + 360.0))


def object_reasons(obj, default, r: ObjectRange | None) -> list[str]:
    """Why an object lies outside its range: another mesh or material, moved, turned or scaled beyond it."""
    from diviewer.scene import camera as cam

    name = f"object '{obj.name}'"
    out = []
    if r is None:
        if obj.mesh != default.mesh:
            out.append(f"{name} wears mesh '{obj.mesh}'; the model saw it only as '{default.mesh}'")
    elif obj.mesh in r.test_meshes:
        out.append(f"{name} wears '{obj.mesh}', a held-out test mesh (never in training)")
    elif obj.mesh not in (r.train_meshes or (default.mesh,)):
        out.append(f"{name} wears mesh '{obj.mesh}', which the model never saw")
    if obj.material != default.material:
        out.append(f"{name} has material '{obj.material}'; trained with '{default.material}'")
    delta = np.asarray(obj.position, np.float64) - np.asarray(default.position, np.float64)
    box = r.offset if r is not None and r.offset is not None else ((0.0,) * 3, (0.0,) * 3)
    if not box_contains(box, delta, margin=REL_TOL):
        out.append(f"{name} moved by {_fmt(delta)}; trained offsets {_fmt(box[0])}-{_fmt(box[1])}")
    if obj.rotation != default.rotation and not _rotation_in_range(
            cam.euler_xyz(obj.rotation), cam.euler_xyz(default.rotation), r or ObjectRange()):
        out.append(f"{name} is turned to {_fmt(obj.rotation)} deg, beyond the trained rotations")
    if not np.allclose(obj.scale, default.scale, rtol=REL_TOL):
        out.append(f"{name} is scaled {_fmt(obj.scale)}; trained at {_fmt(default.scale)}")
    return out


@lru_cache(maxsize=4)
def _default_bounds(scene: Scene) -> tuple[np.ndarray, float]:
    """The scene's default frame's centre and bounding-box diagonal (Scene compares by identity)."""
    b = scene.bounds(scene.default)
    return b.mean(axis=0), float(np.linalg.norm(b[1] - b[0]))


def out_of_range(scene: Scene, config: FrameConfig, path_reach: float | None = None) -> list[str]:
    """Every way ``config`` lies outside what ``scene``'s ranges let the capture draw (empty: all inside).

    Args:
        path_reach: how far (scene units) a camera may stray from a camera path; default 3 % of the scene's
            bounding-box diagonal.
    """
    ranges, default = scene.ranges, scene.default
    out: list[str] = []
    if ranges.camera_region is not None:
        out += camera_region_reasons(ranges.camera_region, config.camera, default.camera)
    elif ranges.camera is not None:
        if path_reach is None:
            path_reach = 0.03 * _default_bounds(scene)[1]
        out += camera_path_reasons(ranges.camera, config.camera, default.camera, path_reach)
    elif not _same_camera(config.camera, default.camera):
        out.append("camera moved; the model was trained at the scene's one camera")
    centre = _default_bounds(scene)[0]
    defaults = {l.name: l for l in default.lights}
    names = {l.name for l in config.lights}
    for light in config.lights:
        if light.name not in defaults:
            out.append(f"light '{light.name}' is not in the scene file")
        else:
            out += light_reasons(light, defaults[light.name], ranges.lights.get(light.name), centre)
    out += [f"light '{n}' is missing" for n in defaults if n not in names]
    objects = {o.name: o for o in default.objects}
    for obj in config.objects:
        if obj.name not in objects:
            out.append(f"object '{obj.name}' is not in the scene file")
        elif obj is not objects[obj.name] and obj != objects[obj.name]:  # the scene's own pose is inside
            out += object_reasons(obj, objects[obj.name], ranges.objects.get(obj.name))
    present = {o.name for o in config.objects}
    out += [f"object '{n}' is missing" for n in objects if n not in present]
    return out
