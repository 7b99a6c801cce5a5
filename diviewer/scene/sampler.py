"""Seeded configuration sampling from the ranges a scene file declares, and camera paths."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from diviewer.scene import camera as cam
from diviewer.scene.lights import rotate_light, scale_light
from diviewer.scene.model import CameraRange, FrameConfig, Scene, box_intersection, box_volume

SPLITS = ("train", "val", "test")


# pyrr builds rotations (scene.camera) but has no inverse for this Euler order, hence this one.
def matrix_to_euler_xyz(r: np.ndarray) -> tuple[float, float, float]:
    """Euler angles (degrees) with ``euler_xyz(angles) == r`` for a rotation matrix r = Rz Ry Rx."""
    sy = -float(np.clip(r[2, 0], -1.0, 1.0))
    ay = math.asin(sy)
    if abs(sy) < 1.0 - 1e-9:
        ax = math.atan2(r[2, 1], r[2, 2])
        az = math.atan2(r[1, 0], r[0, 0])
    else:  # gimbal lock: put all of the remaining rotation into x
        az = 0.0
        ax = math.atan2(-r[1, 2], r[1, 1])
    return (math.degrees(ax), math.degrees(ay), math.degrees(az))


def catmull_rom(points: np.ndarray, s: float, closed: bool) -> np.ndarray:
    """Point at parameter s in [0, 1] on a uniform Catmull-Rom spline through ``points``."""
    n = len(points)
    segments = n if closed else n - 1
    x = min(max(s, 0.0), 1.0) * segments
    i = min(int(x), segments - 1)
    t = x - i

    def p(k):
        return points[k % n] if closed else points[min(max(k, 0), n - 1)]

    p0, p1, p2, p3 = p(i - 1), p(i), p(i + 1), p(i + 2)
    return 0.5 * ((2 * p1) + (-p0 + p2) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t * t + (-p0 + 3 * p1 - 3 * p2 + p3) * t ** 3)


def camera_on_path(scene: Scene, s: float):
    """The default camera moved to parameter s in [0, 1] of the scene's camera path."""
    path = scene.ranges.camera
    if path is None:
        return scene.default.camera
    pos = catmull_rom(np.asarray(path.positions), s, path.closed)
    tgt = catmull_rom(np.asarray(path.targets), s, path.closed)
    return dataclasses.replace(scene.default.camera, position=tuple(map(float, pos)), target=tuple(map(float, tgt)))


def in_test_stretch(path: CameraRange, s: float) -> bool:
    return any(a <= s <= b for a, b in path.test_stretches)


def _draw_path_parameter(rng: np.random.Generator, path: CameraRange, split: str) -> float:
    """Train frames avoid the test stretches, test frames lie inside them, validation uses both."""
    if split == "val" or not path.test_stretches:
        return float(rng.uniform(0.0, 1.0))
    test = path.test_stretches
    if split == "test":
        lengths = np.array([b - a for a, b in test])
        k = rng.choice(len(test), p=lengths / lengths.sum())
        return float(rng.uniform(*test[k]))
    # train: the complement of the test stretches
    edges = sorted(test)
    gaps, start = [], 0.0
    for a, b in edges:
        if a > start:
            gaps.append((start, a))
        start = max(start, b)
    if start < 1.0:
        gaps.append((start, 1.0))
    lengths = np.array([b - a for a, b in gaps])
    k = rng.choice(len(gaps), p=lengths / lengths.sum())
    a, b = gaps[k]
    # open interval: the test stretch's end points belong to test
    return float(a + (b - a) * rng.uniform(1e-6, 1.0 - 1e-6))


CAMERA_MODES = ("sampled", "default")


def sample_config(scene: Scene, seed: int, split: str = "train", camera: str = "sampled") -> FrameConfig:
    """One configuration drawn from the scene's ranges; the same (scene, seed, split) gives the same one.

    ``camera="default"`` keeps the scene file's camera (the paper's fixed-camera protocol); lights and
    objects are the same either way, since the camera is drawn from a stream of its own.
    """
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if camera not in CAMERA_MODES:
        raise ValueError(f"camera must be one of {CAMERA_MODES}, got {camera!r}")
    rng = np.random.default_rng([int(seed), SPLITS.index(split)])
    config = scene.default
    centre = scene.bounds().mean(axis=0)

    lights = []
    for light in config.lights:
        r = scene.ranges.lights.get(light.name)
        if r is None:
            lights.append(light)
            continue
        angle = float(rng.uniform(*r.angle))
        scale = float(math.exp(rng.uniform(math.log(r.intensity[0]), math.log(r.intensity[1]))))
        if r.position is not None:  # a point light anywhere in its box (drawn only where a box is given)
            moved = dataclasses.replace(light, position=tuple(map(float, _uniform_in(rng, r.position))))
        else:
            moved = rotate_light(light, r.axis, angle, centre)
        lights.append(scale_light(moved, scale))

    objects = []
    for obj in config.objects:
        r = scene.ranges.objects.get(obj.name)
        if r is None:
            objects.append(obj)
            continue
        choices = r.test_meshes if (split == "test" and r.test_meshes) else r.train_meshes
        mesh = str(rng.choice(choices)) if choices else obj.mesh
        rot = cam.euler_xyz(obj.rotation)
        for axis in r.axes:
            rot = cam.axis_angle(axis, float(rng.uniform(*r.angle))) @ rot
        pos = np.asarray(obj.position)
        if r.offset is not None:
            pos = pos + rng.uniform(r.offset[0], r.offset[1])
        objects.append(dataclasses.replace(obj, mesh=mesh, rotation=matrix_to_euler_xyz(rot),
                                           position=tuple(map(float, pos))))

    if camera == "default":
        cam_out = config.camera
    elif scene.ranges.camera_region is not None:
        cam_out = _region_camera(scene, seed, split)
    else:
        s = path_parameter(scene, seed, split)
        cam_out = config.camera if s is None else camera_on_path(scene, s)
    return FrameConfig(camera=cam_out, lights=tuple(lights), objects=tuple(objects))


def _uniform_in(rng: np.random.Generator, box) -> np.ndarray:
    return rng.uniform(np.asarray(box[0], dtype=np.float64), np.asarray(box[1], dtype=np.float64))


def _region_camera(scene: Scene, seed: int, split: str):
    """A free camera in the scene's region: train avoids the test boxes, test lies in them, val anywhere."""
    region = scene.ranges.camera_region
    # A stream of its own (as the path parameter's), so lights and objects do not depend on the camera.
    rng = np.random.default_rng([int(seed), SPLITS.index(split), 2])
    if split != "test" and rng.uniform() < region.default_share:
        return scene.default.camera
    if split == "test" and region.test_regions:
        boxes = [box_intersection(region.region, b) for b in region.test_regions]
        vol = np.array([box_volume(b) for b in boxes])
        position = _uniform_in(rng, boxes[int(rng.choice(len(boxes), p=vol / vol.sum()))])
    else:
        for _ in range(10_000):  # the loader refuses test boxes covering >= 90 % of the region
            position = _uniform_in(rng, region.region)
            if split == "val" or not region.in_test_region(position):
                break
        else:
            raise RuntimeError("no training camera position found outside the test regions")
    target = np.asarray(region.target) + rng.uniform(-1.0, 1.0, 3) * np.asarray(region.target_jitter)
    if np.linalg.norm(target - position) < 1e-3:  # measure zero; keep look_at well defined
        target = target + np.array([0.0, 0.0, -1e-2])
    fov = float(rng.uniform(*region.fov))
    return dataclasses.replace(scene.default.camera, position=tuple(map(float, position)),
                               target=tuple(map(float, target)), fov=fov)


def path_parameter(scene: Scene, seed: int, split: str = "train") -> float | None:
    """Where on the camera path sample_config(scene, seed, split) puts the camera (None: no path)."""
    if scene.ranges.camera is None:
        return None
    # A stream of its own, so the path parameter can be recomputed without drawing the rest.
    rng = np.random.default_rng([int(seed), SPLITS.index(split), 1])
    return _draw_path_parameter(rng, scene.ranges.camera, split)
