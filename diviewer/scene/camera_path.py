"""Camera paths: keys in time (camera, and where they change lights and objects), interpolated smoothly. Pure data.

A path file is JSON (docs/paths.md)::

    {"format": "diviewer-camera-path", "version": 1, "scene": "sponza", "scene_hash": "<sha256>", "closed": false,
     "keys": [{"time": 0.0, "camera": {"position": [..], "target": [..], "up": [..], "fov": 45.0, "near": .., "far": ..},
               "lights": [...], "objects": [...]}, ...]}

``time`` is in seconds and strictly increasing. ``lights`` and ``objects`` (as a frame.json's ``config`` writes them)
appear on a key where they differ from the key before; a key without them keeps the previous key's, and a path
that never gives them leaves the frame's own lights and objects alone. ``scene_hash`` is the scene's identity
(`diviewer.scene.identity`): a path recorded in another scene, or another version of it, is refused.

Between keys: positions and targets follow a C1 cubic Hermite spline (Catmull-Rom tangents over the keys' times;
at the ends of an open path the first and last keys are repeated one interval out, as the scene file's own
``[ranges.camera]`` walk is drawn by `diviewer.scene.sampler.camera_on_path`), the up vector and light directions
are slerped, object orientations are slerped as quaternions (pyrr), field of view, colours, powers, object positions
and scales are linear, and meshes and materials change at a key. At a key's own time the key comes back exactly.
"""

from __future__ import annotations

import bisect
import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pyrr import matrix33, quaternion

from diviewer.errors import DiviewerError
from diviewer.outputs import CAMERA_PATH_FORMAT
from diviewer.scene import camera as cam
from diviewer.scene.model import Camera, DirectionalLight, FrameConfig, Scene

FORMAT = CAMERA_PATH_FORMAT
VERSION = 1
"""The path file's version; another is refused."""
DEFAULT_FPS = 30.0
"""Frames per second `frame_times` draws when neither a frame count nor a rate is given."""


@dataclass(frozen=True)
class PathKey:
    """One key: its time (seconds), camera and, when the path carries them, all lights and objects."""

    time: float
    camera: Camera
    lights: tuple | None = None
    objects: tuple | None = None


@dataclass(frozen=True)
class CameraPath:
    """Keys in increasing time for one scene (its name and identity hash); ``closed`` paths loop."""

    keys: tuple[PathKey, ...]
    scene: str
    scene_hash: str
    closed: bool = False
    user_meshes: dict = dataclasses.field(default_factory=dict)
    """Mesh files the keys' objects wear (key -> file), as the viewer's screenshots record them."""

    @property
    def start(self) -> float:
        return self.keys[0].time

    @property
    def end(self) -> float:
        return self.keys[-1].time

    @property
    def duration(self) -> float:
        return self.end - self.start

    def wrap(self, t: float) -> float:
        """A time of endless playback onto the path: closed paths loop, open ones go back and forth. Times within
        the path come back unchanged."""
        if self.start <= t <= self.end or self.duration <= 0.0:
            return min(max(t, self.start), self.end)
        u = (t - self.start) / self.duration
        s = u % 1.0 if self.closed else 1.0 - abs(u % 2.0 - 1.0)
        return self.start + s * self.duration

    def _segment(self, t: float) -> tuple[int, float]:
        """(i, u): t lies in [keys[i].time, keys[i+1].time] at fraction u (t clamped to the path)."""
        times = [k.time for k in self.keys]
        if t <= times[0] or len(times) == 1:
            return 0, 0.0
        if t >= times[-1]:
            return len(times) - 2, 1.0
        i = bisect.bisect_right(times, t) - 1
        return i, (t - times[i]) / (times[i + 1] - times[i])

    def _neighbour(self, i: int) -> tuple[np.ndarray, np.ndarray, float]:
        """(position, target, time) of key i, with keys beyond the ends repeated (open) or wrapped (closed)."""
        n, keys = len(self.keys), self.keys
        if 0 <= i < n:
            k = keys[i]
            return np.asarray(k.camera.position, np.float64), np.asarray(k.camera.target, np.float64), k.time
        if self.closed and n > 2:  # the last key repeats the first
            j = i + (n - 1) if i < 0 else i - (n - 1)
            p, q, t = self._neighbour(j)
            return p, q, t + (self.duration if i >= n else -self.duration)
        j = 0 if i < 0 else n - 1
        h = keys[1].time - keys[0].time if i < 0 else keys[-1].time - keys[-2].time
        p, q, _ = self._neighbour(j)
        return p, q, keys[j].time + (h if i >= n else -h)

    def _tangents(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        (p0, q0, t0), (p1, q1, t1) = self._neighbour(i - 1), self._neighbour(i + 1)
        return (p1 - p0) / (t1 - t0), (q1 - q0) / (t1 - t0)

    def camera_at(self, t: float) -> Camera:
        """The camera at time t (clamped to the path)."""
        i, u = self._segment(t)
        a = self.keys[i]
        if u == 0.0 or len(self.keys) == 1:
            return a.camera
        b = self.keys[i + 1]
        if u == 1.0:
            return b.camera
        h = b.time - a.time
        (mpa, mqa), (mpb, mqb) = self._tangents(i), self._tangents(i + 1)
        h00, h10 = 2 * u ** 3 - 3 * u ** 2 + 1, u ** 3 - 2 * u ** 2 + u
        h01, h11 = -2 * u ** 3 + 3 * u ** 2, u ** 3 - u ** 2
        pa, pb = np.asarray(a.camera.position, np.float64), np.asarray(b.camera.position, np.float64)
        qa, qb = np.asarray(a.camera.target, np.float64), np.asarray(b.camera.target, np.float64)
        position = h00 * pa + h10 * h * mpa + h01 * pb + h11 * h * mpb
        target = h00 * qa + h10 * h * mqa + h01 * qb + h11 * h * mqb
        up = slerp_vector(a.camera.up, b.camera.up, u)
        fov = a.camera.fov + (b.camera.fov - a.camera.fov) * u
        return dataclasses.replace(a.camera, position=_vec(position), target=_vec(target), up=_vec(up), fov=float(fov))

    def config_at(self, t: float, base: FrameConfig) -> FrameConfig:
        """``base`` with the path's camera at time t, and its lights and objects where the path carries them."""
        i, u = self._segment(t)
        a = self.keys[i]
        b = self.keys[min(i + 1, len(self.keys) - 1)]
        if u == 1.0:
            a, u = b, 0.0
        camera = self.camera_at(t)
        lights, objects = base.lights, base.objects
        if a.lights is not None:
            lights = a.lights if u == 0.0 else tuple(_lerp_light(x, y, u) for x, y in zip(a.lights, b.lights))
        if a.objects is not None:
            objects = a.objects if u == 0.0 else tuple(_lerp_object(x, y, u) for x, y in zip(a.objects, b.objects))
        return FrameConfig(camera=camera, lights=lights, objects=objects)

    def to_dict(self) -> dict:
        """The path file's content: lights and objects written on the first key and where they change."""
        keys, prev = [], None
        for k in self.keys:
            d = {"time": float(k.time), "camera": FrameConfig(k.camera, (), ()).to_dict()["camera"]}
            full = FrameConfig(k.camera, k.lights or (), k.objects or ()).to_dict()
            if k.lights is not None and (prev is None or prev.lights != k.lights):
                d["lights"] = full["lights"]
            if k.objects is not None and (prev is None or prev.objects != k.objects):
                d["objects"] = full["objects"]
            keys.append(d)
            prev = k
        out = {"format": FORMAT, "version": VERSION, "scene": self.scene, "scene_hash": self.scene_hash,
               "closed": bool(self.closed), "keys": keys}
        if self.user_meshes:
            out["user_meshes"] = dict(self.user_meshes)
        return out


def _vec(v) -> tuple[float, float, float]:
    return tuple(float(x) for x in v)


def slerp_vector(a, b, u: float) -> tuple[float, float, float]:
    """Spherical interpolation of two directions (unit length out; equal directions come back unchanged)."""
    if tuple(a) == tuple(b):
        return _vec(a)
    a, b = cam.normalize(a), cam.normalize(b)
    angle = math.acos(float(np.clip(np.dot(a, b), -1.0, 1.0)))
    if angle < 1e-9:
        return _vec(a + (b - a) * u)
    if math.pi - angle < 1e-6:  # opposite: no unique arc; turn about any axis normal to a
        axis = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return _vec(cam.axis_angle(axis, math.degrees(angle * u)) @ a)
    s = math.sin(angle)
    return _vec((math.sin((1 - u) * angle) * a + math.sin(u * angle) * b) / s)


def slerp_rotation(a_deg, b_deg, u: float) -> tuple[float, float, float]:
    """Euler angles (x, y, z; degrees) of the rotation slerped from ``a_deg`` to ``b_deg`` (quaternions, short arc)."""
    from diviewer.scene.sampler import matrix_to_euler_xyz

    if tuple(a_deg) == tuple(b_deg):
        return _vec(a_deg)
    qa = quaternion.create_from_matrix(cam.euler_xyz(a_deg))
    qb = quaternion.create_from_matrix(cam.euler_xyz(b_deg))
    if float(np.dot(qa, qb)) < 0.0:
        qb = -qb
    q = quaternion.normalize(quaternion.slerp(qa, qb, u))
    return matrix_to_euler_xyz(matrix33.create_from_quaternion(q))


def _lerp(a, b, u: float):
    return _vec(np.asarray(a, np.float64) + (np.asarray(b, np.float64) - np.asarray(a, np.float64)) * u)


def _num(a: float, b: float, u: float) -> float:
    return float(a + (b - a) * u)


def _lerp_light(a, b, u: float):
    if isinstance(a, DirectionalLight):
        return dataclasses.replace(a, direction=slerp_vector(a.direction, b.direction, u), color=_lerp(a.color, b.color, u),
                                   irradiance=_num(a.irradiance, b.irradiance, u))
    return dataclasses.replace(a, position=_lerp(a.position, b.position, u), color=_lerp(a.color, b.color, u),
                               intensity=_num(a.intensity, b.intensity, u))


def _lerp_object(a, b, u: float):
    return dataclasses.replace(a, position=_lerp(a.position, b.position, u), scale=_lerp(a.scale, b.scale, u),
                               rotation=slerp_rotation(a.rotation, b.rotation, u))


# --- the scene file's own walk ---------------------------------------------------------------------------------------

SCENE_PATH_SECONDS = 30.0
"""Seconds the viewer takes to play a scene file's camera path once."""


def scene_camera_path(scene: Scene, seconds: float = SCENE_PATH_SECONDS) -> CameraPath | None:
    """The scene file's ``[ranges.camera]`` walk as a CameraPath (camera only) of ``seconds``; None without one.

    Its keys are the walk's points, evenly spaced in time; at parameter s in [0, 1] it passes where
    `diviewer.scene.sampler.camera_on_path` puts the camera (the sampler itself is unchanged)."""
    walk = scene.ranges.camera
    if walk is None:
        return None
    pairs = list(zip(walk.positions, walk.targets))
    if walk.closed:
        pairs.append(pairs[0])
    base = scene.default.camera
    keys = tuple(PathKey(time=seconds * i / (len(pairs) - 1),
                         camera=dataclasses.replace(base, position=_vec(p), target=_vec(q)))
                 for i, (p, q) in enumerate(pairs))
    return CameraPath(keys=keys, scene=scene.name, scene_hash=scene.file_hash, closed=walk.closed)


# --- thinning a recording -------------------------------------------------------------------------------------------

RECORD_EVERY = 10
"""A recording keeps at least every this many frames as a key."""
RECORD_TOLERANCE = 1e-3
"""...and more wherever the keys kept would miss a frame by more than this (lengths as a fraction of the scene's size,
directions and rotations in radians, the field of view per 90 degrees, powers relative)."""


def _state(key: PathKey, scale: float) -> tuple[np.ndarray, tuple]:
    """A key as numbers (to measure how far two keys are) and the parts that only change at a key."""
    c = key.camera
    nums = [np.divide(c.position, scale), np.divide(c.target, scale), cam.normalize(c.up), [c.fov / 90.0]]
    for light in key.lights or ():
        where = light.direction if isinstance(light, DirectionalLight) else np.divide(light.position, scale)
        power = light.irradiance if isinstance(light, DirectionalLight) else light.intensity
        nums += [where, light.color, [math.log1p(power)]]
    for o in key.objects or ():
        nums += [np.divide(o.position, scale), cam.euler_xyz(o.rotation).ravel(), o.scale]
    fixed = tuple((o.mesh, o.material) for o in key.objects or ()) + tuple(light.name for light in key.lights or ())
    return np.concatenate([np.ravel(np.asarray(n, np.float64)) for n in nums]), fixed


def thin_keys(keys: list[PathKey], scale: float, every: int = RECORD_EVERY,
              tolerance: float | None = RECORD_TOLERANCE) -> list[PathKey]:
    """A recording's keys (one per frame) thinned: the first, the last, every ``every``-th, both sides of a change
    of mesh or material, and wherever the path through the keys kept would miss a dropped frame by more than
    ``tolerance`` (`_state`'s units; ``scale``: the scene's size). ``tolerance`` None keeps every key (a replay then
    gives each recorded frame exactly)."""
    n = len(keys)
    if tolerance is None or n <= 2:
        return list(keys)
    states = [_state(k, scale) for k in keys]
    kept = {0, n - 1, *range(0, n, max(int(every), 1))}
    kept |= {j for i in range(1, n) if states[i][1] != states[i - 1][1] for j in (i - 1, i)}
    base = FrameConfig(keys[0].camera, (), ())
    while True:
        order = sorted(kept)
        path = CameraPath(tuple(keys[i] for i in order), "", "")
        worst: dict[int, tuple[float, int]] = {}
        for i in range(n):
            if i in kept:
                continue
            c = path.config_at(keys[i].time, base)
            err = float(np.max(np.abs(_state(PathKey(keys[i].time, c.camera, c.lights if keys[i].lights is not None
                                                     else None, c.objects if keys[i].objects is not None else None),
                                             scale)[0] - states[i][0])))
            seg = bisect.bisect_left(order, i)
            if err > tolerance and err > worst.get(seg, (0.0, -1))[0]:
                worst[seg] = (err, i)
        if not worst:
            return [keys[i] for i in order]
        kept |= {i for _, i in worst.values()}


# --- frames of a path ------------------------------------------------------------------------------------------------

def frame_times(path: CameraPath, frames: int | None = None, fps: float | None = None) -> list[float]:
    """Times to draw: ``frames`` evenly from the first key to the last (both included), else every 1/fps seconds
    from the first key while within the path (``DEFAULT_FPS`` when neither is given)."""
    if frames is not None:
        if frames == 1 or path.duration == 0.0:
            return [path.start] * frames
        return [path.start + path.duration * i / (frames - 1) for i in range(frames)]
    rate = float(fps or DEFAULT_FPS)
    n = int(math.floor(path.duration * rate + 1e-9)) + 1
    return [path.start + i / rate for i in range(n)]


def frames_per_second(path: CameraPath, frames: int | None = None, fps: float | None = None) -> float:
    """The rate a video of `frame_times` plays at, so that it lasts as long as the path."""
    if frames is None:
        return float(fps or DEFAULT_FPS)
    return (frames - 1) / path.duration if frames > 1 and path.duration > 0 else 1.0


# --- reading and writing ---------------------------------------------------------------------------------------------

def write_path(file: str | Path, path: CameraPath) -> None:
    """Write a path file atomically (a temporary name, then renamed)."""
    from diviewer.imageio import write_text

    write_text(file, json.dumps(path.to_dict(), indent=1))


def _prefixed(fn, file, prefix: str):
    """``fn()``, with the field of a DiviewerError about ``file`` put under ``prefix``."""
    try:
        return fn()
    except DiviewerError as exc:
        if exc.path != file or not exc.field:
            raise
        message = str(exc).split(f"{exc.field}: ", 1)[-1]
        raise DiviewerError(message, path=file, field=f"{prefix}.{exc.field}") from None


def read_path(file: str | Path, scene: Scene) -> tuple[CameraPath, Scene]:
    """A path file checked field by field against ``scene`` (refused with the file and the field named): its
    format and version, the scene's identity, finite numbers, at least one key, strictly increasing times.
    Returns the path and the scene with the mesh files the path's objects wear added."""
    from diviewer.scene.loader import camera_from_table, add_mesh_file, config_from_dict
    from diviewer.scene.toml_table import TomlTable

    file = Path(file)
    try:
        data = json.loads(file.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DiviewerError(f"cannot read the camera path: {exc}", path=file) from exc
    t = TomlTable(data, file, "")
    if t.raw("format") != FORMAT:
        raise t.err("format", f"expected \"{FORMAT}\", got {t.raw('format')!r}: not a camera path file")
    version = t.raw("version")
    if version != VERSION or isinstance(version, bool):
        raise t.err("version", f"version {version!r} is not one this diviewer reads ({VERSION}); record the path "
                               "again or use the diviewer that wrote it")
    name, recorded = t.str("scene"), t.str("scene_hash")
    if recorded != scene.file_hash:
        raise t.err("scene_hash", f"the path was recorded in scene '{name}' ({recorded[:12]}...), not in this "
                                  f"scene '{scene.name}' ({scene.file_hash[:12]}...); record it again in this scene")
    closed = t.bool("closed", False)
    meshes = t.raw("user_meshes", {})
    if not (isinstance(meshes, dict) and all(isinstance(v, str) for v in meshes.values())):
        raise t.err("user_meshes", "expected a table of mesh file names")
    for key, mesh_file in meshes.items():
        scene, _, _ = add_mesh_file(scene, mesh_file, key)
    raw = t.raw("keys")
    if not isinstance(raw, list) or not raw:
        raise t.err("keys", "the path has no keys (expected a non-empty list of keys)")
    t.finish()
    keys, lights, objects = [], None, None
    for i, item in enumerate(raw):
        k = TomlTable(item, file, f"keys[{i}]")
        time = k.num("time")
        if keys and not time > keys[-1].time:
            raise k.err("time", f"times must increase from key to key: {time} follows {keys[-1].time}")
        if not k.has("camera"):
            raise k.err("camera", "missing required field")
        camera = camera_from_table(k.table("camera"))
        lights = k.raw("lights", lights)
        objects = k.raw("objects", objects)
        config = _prefixed(lambda: config_from_dict(scene, {"camera": item["camera"], "lights": lights or [],
                                                            "objects": objects or []}, path=file), file, f"keys[{i}]")
        k.finish()
        for track, first in (("lights", keys[0].lights if keys else None), ("objects", keys[0].objects if keys else None)):
            names = [x.name for x in getattr(config, track)]
            if first is not None and names != [x.name for x in first]:
                raise k.err(track, f"expected the {track} of the first key ({', '.join(x.name for x in first)}), "
                                   f"got {', '.join(names) or 'none'}")
        config = dataclasses.replace(config, lights=tuple(_as_written(l, r) for l, r in zip(config.lights, lights or [])))
        keys.append(PathKey(time=time, camera=camera, lights=config.lights if lights is not None else None,
                            objects=config.objects if objects is not None else None))
    keys = _fill_tracks(keys, scene.default)
    return CameraPath(keys=tuple(keys), scene=name, scene_hash=recorded, closed=closed, user_meshes=dict(meshes)), scene


def _as_written(light, raw: dict):
    """A sun's direction as the file wrote it where that is unit length already: the loader's normalisation would
    change its last bits, and a replay would then differ from the recording."""
    d = raw.get("direction") if isinstance(raw, dict) else None
    if isinstance(light, DirectionalLight) and d is not None and abs(float(np.linalg.norm(d)) - 1.0) < 1e-12:
        return dataclasses.replace(light, direction=_vec(d))
    return light


def _fill_tracks(keys: list[PathKey], default: FrameConfig) -> list[PathKey]:
    """Keys before a track (lights, objects) first appears take the scene's default, so each track is all or none."""
    for track in ("lights", "objects"):
        if any(getattr(k, track) is not None for k in keys):
            keys = [k if getattr(k, track) is not None else dataclasses.replace(k, **{track: getattr(default, track)})
                    for k in keys]
    return keys
