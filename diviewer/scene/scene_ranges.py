"""A scene file's [ranges]: where lights, objects and the camera may go, each range checked (min <= max,
non-zero axes, test stretches and regions that leave training a share)."""

from __future__ import annotations

import numpy as np

from diviewer.scene.model import (
    Camera, CameraRange, CameraRegion, FrameConfig, LightRange, ObjectRange, PointLight, Ranges, box_intersection,
    box_volume, objects_bounds,
)
from diviewer.scene.toml_table import entries, f32, TomlTable


def parse_ranges(t: TomlTable, default: FrameConfig, meshes) -> Ranges:
    """The ranges table of a scene file, checked against its default configuration and meshes."""
    lights, objects, camera = {}, {}, None
    known_lights = {l.name for l in default.lights}
    for key, r in entries(t.table("lights"), lambda k: None if k in known_lights else
                           f"no light named '{k}'; lights: {', '.join(sorted(known_lights)) or 'none'}"):
        angle = _interval(r, "angle", (0.0, 0.0))
        inten = _interval(r, "intensity", (1.0, 1.0), lo=0.0)
        if inten[0] <= 0.0:
            raise r.err("intensity", "the intensity multiplier range must be positive (drawn log-uniformly)")
        light = next(l for l in default.lights if l.name == key)
        peak = max(light.color) * getattr(light, "irradiance", getattr(light, "intensity", 1.0)) * inten[1]
        if not f32(peak):
            raise r.err("intensity", f"the brightest drawn light ({peak:.3g}) is outside float32's range (+-3.4e38)")
        lights[key] = LightRange(axis=_axis(r, "axis", (0.0, 1.0, 0.0)), angle=angle, intensity=inten,
                                 position=_light_box(r, light, angle, default, meshes))
    known_objects = {o.name for o in default.objects}
    for key, r in entries(t.table("objects"), lambda k: None if k in known_objects else
                           f"no object named '{k}'; objects: {', '.join(sorted(known_objects))}"):
        train, test = r.strs("train_meshes"), r.strs("test_meshes")
        for field_name, lst in (("train_meshes", train), ("test_meshes", test)):
            for m in lst:
                if m not in meshes:
                    raise r.err(field_name, f"unknown mesh '{m}'")
        if set(train) & set(test):
            raise r.err("test_meshes", f"meshes in both train and test: {sorted(set(train) & set(test))}")
        offset = r.vecs("offset", 3) if r.has("offset") else None
        if offset is not None and len(offset) != 2:
            raise r.err("offset", "expected [[min x, y, z], [max x, y, z]]")
        if offset is not None and not all(a <= b for a, b in zip(*offset)):
            raise r.err("offset", f"each min must be <= its max, got {[list(offset[0]), list(offset[1])]}")
        axes = r.vecs("axes", 3, [])
        for k, a in enumerate(axes):
            if np.linalg.norm(a) < 1e-9:
                raise r.err(f"axes[{k}]", "a rotation axis must be non-zero")
        objects[key] = ObjectRange(axes=axes, angle=_interval(r, "angle", (0.0, 360.0)),
                                   offset=offset, train_meshes=train, test_meshes=test)
    camera_region = None
    if t.has("camera") and t.table("camera").has("region"):
        camera_region = _camera_region(t.table("camera"), default.camera)
    elif t.has("camera"):
        r = t.table("camera")
        positions, targets = r.vecs("positions", 3), r.vecs("targets", 3)
        if len(positions) < 2 or len(positions) != len(targets):
            raise r.err("positions", "a camera path needs at least 2 keyframes and as many targets as positions")
        for k, (p, q) in enumerate(zip(positions, targets)):
            if np.linalg.norm(np.subtract(q, p)) < 1e-9:
                raise r.err("targets", f"keyframe {k}'s target equals its position: the camera would look nowhere")
        stretches = r.vecs("test_stretches", 2, [])
        for a, b in stretches:
            if not 0.0 <= a < b <= 1.0:
                raise r.err("test_stretches", f"each stretch is [start, end] with 0 <= start < end <= 1, got {[a, b]}")
        if train_length(stretches) <= 1e-6:
            raise r.err("test_stretches", "the test stretches cover the whole path: training needs a stretch of its own")
        camera = CameraRange(positions=positions, targets=targets, closed=bool(r.raw("closed", False)),
                             test_stretches=stretches)
        r.finish()
    t.finish()
    return Ranges(lights=lights, objects=objects, camera=camera, camera_region=camera_region)


def train_length(stretches) -> float:
    """The length of the path parameter [0, 1] outside the test stretches (what training draws from)."""
    covered, start = 0.0, 0.0
    for a, b in sorted(stretches):
        a = max(a, start)
        if b > a:
            covered, start = covered + (b - a), b
    return 1.0 - covered


def _interval(r: TomlTable, key: str, default, lo=None) -> tuple[float, float]:
    """A [min, max] pair with min <= max."""
    v = r.vec(key, 2, default, lo=lo)
    if v[0] > v[1]:
        raise r.err(key, f"a range is [min, max] with min <= max, got {list(v)}")
    return v


def _axis(r: TomlTable, key: str, default) -> tuple:
    v = r.vec(key, 3, default)
    if np.linalg.norm(v) < 1e-9:
        raise r.err(key, f"a rotation axis must be non-zero, got {list(v)}")
    return v


def _box(r: TomlTable, key: str, value=None) -> tuple:
    """[[min x, y, z], [max x, y, z]] with min < max on every axis."""
    sub = r if value is None else TomlTable({key: value}, r.path, r.where)
    box = sub.vecs(key, 3)
    if len(box) != 2:
        raise r.err(key, "expected [[min x, y, z], [max x, y, z]]")
    if not all(a < b for a, b in zip(*box)):
        raise r.err(key, f"each min must be below its max, got {[list(box[0]), list(box[1])]}")
    return box


def _light_box(r: TomlTable, light, angle, default: FrameConfig, meshes):
    """A point light's ``position`` box: inside the scene's bounds, and instead of a rotation; None if not given."""
    if not r.has("position"):
        r.raw("position")
        return None
    if not isinstance(light, PointLight):
        raise r.err("position", f"light '{light.name}' is a sun (directional): it has no position; vary its "
                                f"direction with axis and angle")
    if angle != (0.0, 0.0) or r.has("axis"):
        raise r.err("position", "a point light either moves in a 'position' box or turns with 'axis' and 'angle', "
                                "not both")
    box = r.vecs("position", 3)  # min == max on an axis is allowed: a lamp that slides along the ceiling
    if len(box) != 2 or not all(a <= b for a, b in zip(*box)):
        raise r.err("position", f"expected [[min x, y, z], [max x, y, z]] with each min <= its max, got "
                                f"{[list(x) for x in box]}")
    lo, hi = objects_bounds(meshes, default.objects)
    if not (np.all(np.asarray(box[0]) >= lo) and np.all(np.asarray(box[1]) <= hi)):
        raise r.err("position", f"the box {[list(box[0]), list(box[1])]} leaves the scene's bounds "
                                f"{[round(float(x), 4) for x in lo]} to {[round(float(x), 4) for x in hi]}: a light "
                                f"outside would sit beyond the walls; keep it inside (diviewer inspect shows the bounds)")
    return box


def _camera_region(r: TomlTable, camera: Camera) -> CameraRegion:
    """A free camera's ranges: a box of positions, a jittered look-at target, a field-of-view range."""
    region = _box(r, "region")
    target = r.vec("target", 3, camera.target)
    jitter = r.vec("target_jitter", 3, (0.0, 0.0, 0.0), lo=0.0)
    fov = r.vec("fov", 2, (camera.fov, camera.fov), lo=1.0, hi=170.0)
    if fov[0] > fov[1]:
        raise r.err("fov", f"a range is [min, max] with min <= max, got {list(fov)}")
    raw = r.raw("test_regions", [])
    if not isinstance(raw, list):
        raise r.err("test_regions", "expected a list of [[min x, y, z], [max x, y, z]] boxes")
    tests = tuple(_box(r, f"test_regions[{i}]", b) for i, b in enumerate(raw))
    share = r.num("default_share", 0.0, lo=0.0, hi=1.0)
    result = CameraRegion(region=region, target=target, target_jitter=jitter, fov=fov, test_regions=tests,
                          default_share=share)
    inside = [box_volume(box_intersection(region, b)) for b in tests]
    for i, v in enumerate(inside):
        if v <= 0.0:
            raise r.err("test_regions", f"test region {i} does not overlap 'region': no test camera could be drawn there")
    # Overlapping test boxes count twice here, so this only refuses a region that is (nearly) all held out.
    if tests and sum(inside) >= 0.9 * box_volume(region):
        raise r.err("test_regions", "the test regions cover (almost) all of 'region': training needs the rest")
    for p in (np.asarray(region[0]), np.asarray(region[1])):
        if np.linalg.norm(np.asarray(target) - p) <= 1e-6:
            raise r.err("target", "the look-at target is a corner of the camera region")
    r.finish()
    return result
