"""Scene data: frozen dataclasses with no GL and no torch; a frame's state is a FrameConfig."""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Union

import numpy as np

from diviewer.scene import camera as cam
from diviewer.scene.colour import LUMINANCE_WEIGHTS

Vec3 = tuple[float, float, float]


def _vec3(v) -> Vec3:
    return tuple(float(x) for x in v)  # type: ignore[return-value]


@dataclass(frozen=True, eq=False)
class Mesh:
    """Triangle geometry in object space, with per-vertex normals (creases already split)."""

    name: str
    """Key of this mesh in the scene's mesh library."""
    vertices: np.ndarray
    """(N, 3) float32 positions."""
    normals: np.ndarray
    """(N, 3) float32 unit normals."""
    faces: np.ndarray
    """(M, 3) uint32 vertex indices, counter-clockwise seen from outside."""
    uvs: np.ndarray | None = None
    """(N, 2) float32 texture coordinates, or None."""
    source: str = ""
    """Where it came from: a procedural shape name or a file path (for messages and reports)."""

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) object-space bounding box."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])


@dataclass(frozen=True, eq=False)
class Material:
    """A diffuse (Lambertian) material, optionally textured and emissive."""

    name: str
    albedo: Vec3 = (0.8, 0.8, 0.8)
    """Diffuse reflectance (linear RGB, each in [0, 1]); multiplies the texture when there is one."""
    emission: Vec3 = (0.0, 0.0, 0.0)
    """Emitted radiance (linear RGB, W/(m^2 sr)); zero for non-emitters. Multiplies ``emission_texture`` when there
    is one (glTF's emissiveFactor)."""
    texture: np.ndarray | None = None
    """(H, W, 3) float32 linear base-colour texture, top row first, or None."""
    texture_source: str = ""
    """The file the texture came from."""
    alpha: np.ndarray | None = None
    """(H, W) float32 cut-out mask in [0, 1] (the base colour's alpha, same size as ``texture``), or None:
    opaque. Where the filtered alpha is below ``alpha_cutoff`` the surface is not there (glTF MASK)."""
    alpha_cutoff: float = 0.5
    emission_texture: np.ndarray | None = None
    """(H, W, 3) float32 linear emission texture (glTF's emissiveTexture, sRGB-decoded as the base colour is), top
    row first, sampled at the same uvs as ``texture``; or None: the emission is ``emission`` all over."""
    emission_texture_source: str = ""
    """The file the emission texture came from."""
    double_sided: bool = True
    """Both faces are surfaces. False (glTF's ``doubleSided``, false unless said): a back face is the inside of a
    closed surface, which the camera does not see, so the rasterizer's camera pass culls it; shadows, VXGI and the
    path tracer keep both faces (light that meets one still stops there)."""

    @property
    def is_emissive(self) -> bool:
        return max(self.emission) > 0.0

    @functools.cached_property
    def peak_emission(self) -> Vec3:
        """The brightest emitted radiance (linear RGB): of ``emission`` times each texel of the emission texture, the
        one of the highest luminance; ``emission`` itself without a texture."""
        if self.emission_texture is None:
            return self.emission
        texels = self.emission_texture.reshape(-1, 3).astype(np.float64) * np.asarray(self.emission, np.float64)
        return _vec3(texels[int(np.argmax(texels @ LUMINANCE_WEIGHTS))] if len(texels) else np.zeros(3))

    @property
    def is_masked(self) -> bool:
        """Alpha-tested: cut out where the texture's alpha is below the cutoff (leaves, chains)."""
        return self.alpha is not None


@dataclass(frozen=True)
class Camera:
    """A pinhole camera; see diviewer.scene.camera for the conventions."""

    position: Vec3 = (0.0, 0.0, 5.0)
    target: Vec3 = (0.0, 0.0, 0.0)
    up: Vec3 = (0.0, 1.0, 0.0)
    fov: float = 45.0
    """Vertical field of view in degrees, in (0, 180)."""
    near: float = 0.05
    far: float = 100.0

    def view_matrix(self) -> np.ndarray:
        return cam.look_at(self.position, self.target, self.up)

    def projection(self, aspect: float) -> np.ndarray:
        return cam.perspective(self.fov, aspect, self.near, self.far)


@dataclass(frozen=True)
class DirectionalLight:
    """A distant light (the sun): irradiance ``irradiance * color`` on a surface facing it."""

    name: str
    direction: Vec3 = (0.0, -1.0, 0.0)
    """Direction in which the light travels (from the light into the scene), world space."""
    color: Vec3 = (1.0, 1.0, 1.0)
    irradiance: float = 1.0
    """Irradiance (W/m^2) on a surface perpendicular to the light; >= 0."""
    kind: str = field(default="directional", init=False)


@dataclass(frozen=True)
class PointLight:
    """An isotropic point light of radiant intensity ``intensity * color`` (W/sr)."""

    name: str
    position: Vec3 = (0.0, 1.0, 0.0)
    color: Vec3 = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    """Radiant intensity (W/sr); >= 0."""
    kind: str = field(default="point", init=False)


Light = Union[DirectionalLight, PointLight]


@dataclass(frozen=True)
class Object:
    """An instance of a mesh with a material and a pose (translate @ rotate xyz @ scale)."""

    name: str
    mesh: str
    """Key in Scene.meshes."""
    material: str
    """Key in Scene.materials."""
    position: Vec3 = (0.0, 0.0, 0.0)
    rotation: Vec3 = (0.0, 0.0, 0.0)
    """Euler angles in degrees, applied about x, then y, then z."""
    scale: Vec3 = (1.0, 1.0, 1.0)

    def matrix(self) -> np.ndarray:
        return cam.trs(self.position, self.rotation, self.scale)


@dataclass(frozen=True)
class LightRange:
    """How the sampler may move one light."""

    axis: Vec3 = (0.0, 1.0, 0.0)
    """The light's direction (or position, about the scene centre) rotates about this axis."""
    angle: tuple[float, float] = (0.0, 0.0)
    """Rotation range in degrees."""
    intensity: tuple[float, float] = (1.0, 1.0)
    """Multiplier of the light's irradiance/intensity, drawn log-uniformly."""
    position: tuple[Vec3, Vec3] | None = None
    """A point light's box (min, max) of positions, drawn uniformly in place of the rotation; None: rotate."""


@dataclass(frozen=True)
class ObjectRange:
    """How the sampler may move one object and which meshes it may wear."""

    axes: tuple[Vec3, ...] = ()
    """The object rotates about each of these axes by an angle drawn from ``angle``."""
    angle: tuple[float, float] = (0.0, 360.0)
    offset: tuple[Vec3, Vec3] | None = None
    """Box (min, max) of translations added to the object's position, or None."""
    train_meshes: tuple[str, ...] = ()
    """Meshes the object may wear in training and validation frames."""
    test_meshes: tuple[str, ...] = ()
    """Meshes only test frames use: never seen in training."""


@dataclass(frozen=True)
class CameraRange:
    """The camera path (keyframes, interpolated) and which stretches of it are held out for test."""

    positions: tuple[Vec3, ...] = ()
    targets: tuple[Vec3, ...] = ()
    closed: bool = False
    """Whether the path loops back to its first keyframe."""
    test_stretches: tuple[tuple[float, float], ...] = ()
    """Intervals of the path parameter in [0, 1] used only for test frames."""


Box = tuple[Vec3, Vec3]


def box_contains(box: Box, p, margin: float = 0.0) -> bool:
    """Whether point p lies in the axis-aligned box (min, max), grown by ``margin`` on every side."""
    lo, hi = np.asarray(box[0]) - margin, np.asarray(box[1]) + margin
    p = np.asarray(p, dtype=np.float64)
    return bool(np.all(p >= lo) and np.all(p <= hi))


def box_volume(box: Box) -> float:
    return float(np.prod(np.maximum(np.asarray(box[1]) - np.asarray(box[0]), 0.0)))


def box_intersection(a: Box, b: Box) -> Box:
    lo, hi = np.maximum(a[0], b[0]), np.minimum(a[1], b[1])
    return (_vec3(lo), _vec3(np.maximum(lo, hi)))


@dataclass(frozen=True)
class CameraRegion:
    """Where a free camera may be: positions in a box, aimed at a jittered target, a field-of-view range.

    Boxes in ``test_regions`` are held out: test frames put the camera there, training frames never do,
    validation frames anywhere in ``region``.
    """

    region: Box = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    """(min, max) corners of the box the camera position is drawn from (uniformly)."""
    target: Vec3 = (0.0, 0.0, 0.0)
    """Centre of the look-at point."""
    target_jitter: Vec3 = (0.0, 0.0, 0.0)
    """Half-extents of the box around ``target`` the look-at point is drawn from."""
    fov: tuple[float, float] = (45.0, 45.0)
    """Vertical field of view range in degrees."""
    test_regions: tuple[Box, ...] = ()
    """Boxes of camera positions used only by test frames."""
    default_share: float = 0.0
    """Share of training and validation frames that keep the scene file's own camera (the fixed view
    most users start from), so the model stays as sharp there as a fixed-camera model."""

    def in_test_region(self, p) -> bool:
        return any(box_contains(b, p) for b in self.test_regions)

    def max_look_offset(self, position) -> float:
        """Largest angle (radians) between the view direction and the direction to ``target`` that the
        sampler can draw from ``position``: the jitter box seen from there (its corner-most point)."""
        d = np.asarray(self.target, dtype=np.float64) - np.asarray(position, dtype=np.float64)
        dist = float(np.linalg.norm(d))
        reach = float(np.linalg.norm(self.target_jitter))
        if dist <= reach:
            return math.pi
        return math.asin(reach / dist)


@dataclass(frozen=True)
class Ranges:
    """Everything the sampler may vary, declared by the scene file."""

    lights: dict[str, LightRange] = field(default_factory=dict)
    objects: dict[str, ObjectRange] = field(default_factory=dict)
    camera: CameraRange | None = None
    """A camera path (keyframes), or None."""
    camera_region: CameraRegion | None = None
    """A free camera's region, or None (at most one of ``camera`` and ``camera_region`` is set)."""


def _record(obj) -> dict:
    """``dataclasses.asdict`` of a flat record (its fields numbers, strings and tuples of them, immutable): the same
    dict without asdict's recursive deep copy, which took 33 s of the 35 s it takes to plan Sponza's 3,400 frames
    (172 objects a frame). A record holding anything mutable or nested gets asdict's copy."""
    d = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
    if all(_immutable(v) for v in d.values()):
        return d
    return dataclasses.asdict(obj)


def _immutable(v) -> bool:
    return isinstance(v, (str, int, float, bool, type(None))) or (isinstance(v, tuple) and all(map(_immutable, v)))


@dataclass(frozen=True)
class FrameConfig:
    """The state of one frame: camera, lights and object poses. Rendering needs Scene + FrameConfig."""

    camera: Camera
    lights: tuple[Light, ...]
    objects: tuple[Object, ...]

    def to_dict(self) -> dict:
        def light(l):
            d = _record(l)
            d["type"] = d.pop("kind")
            return d

        return {
            "camera": _record(self.camera),
            "lights": [light(l) for l in self.lights],
            "objects": [_record(o) for o in self.objects],
        }

    def replace_light(self, name: str, **changes) -> "FrameConfig":
        return dataclasses.replace(
            self, lights=tuple(dataclasses.replace(l, **changes) if l.name == name else l for l in self.lights)
        )

    def replace_object(self, name: str, **changes) -> "FrameConfig":
        return dataclasses.replace(
            self, objects=tuple(dataclasses.replace(o, **changes) if o.name == name else o for o in self.objects)
        )


@dataclass(frozen=True, eq=False)
class Scene:
    """A loaded scene: the mesh and material libraries, the default frame, and the sampling ranges."""

    name: str
    path: Path | None
    file_hash: str
    """The scene's identity (sha256; models and datasets record it): of its parsed TOML without what only shows it
    (``[camera]``, ``[ranges]``, exposure, shadow size), and the bytes of every file the load reads; comments in the
    scene file are not part of it."""
    meshes: dict[str, Mesh]
    materials: dict[str, Material]
    default: FrameConfig
    ranges: Ranges = field(default_factory=Ranges)
    exposure: float = 0.0
    """Display exposure in stops (EV) used by the composite pass."""
    auto_exposure: bool = False
    """Display: meter the exposure from each frame instead (the viewer starts with its auto exposure on; `render`
    meters its PNGs' exposure from the frame it writes and records it), for a scene whose sunlit and shaded
    frames lie more stops apart than one exposure shows (Sponza)."""
    ambient: Vec3 = (0.0, 0.0, 0.0)
    """Constant background radiance seen where no geometry is (the sky); black by default."""
    shadow_size: int = 2048
    """Texels per side of a directional light's shadow map in the rasterizer (``[scene] shadow_size``): what the
    GL direct light's shadows are resolved to, and so how close they come to the path tracer's exact ones."""

    warnings: tuple[str, ...] = ()
    """What the load could not take as the files say (an unhonoured glTF extension, a default material), one
    sentence each; the CLI prints them, `diviewer inspect` lists them."""

    _bounds_cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    """bounds() per objects tuple: the viewer asks every frame, and only a moved object changes it."""

    def bounds(self, config: FrameConfig | None = None) -> np.ndarray:
        """(2, 3) world-space bounding box of the objects in a frame."""
        config = config or self.default
        try:
            cached = self._bounds_cache.get(config.objects)
        except TypeError:  # an unhashable pose (a list): computed each time
            return objects_bounds(self.meshes, config.objects)
        if cached is None:
            if len(self._bounds_cache) >= 64:
                self._bounds_cache.clear()
            cached = self._bounds_cache[config.objects] = objects_bounds(self.meshes, config.objects)
        return cached.copy()


def objects_bounds(meshes: dict, objects) -> np.ndarray:
    """(2, 3) world-space box of placed objects (each mesh's box corners, transformed)."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for o in objects:
        b = meshes[o.mesh].bounds
        corners = np.array([[b[i, 0], b[j, 1], b[k, 2], 1.0] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        w = (o.matrix() @ corners.T).T[:, :3]
        lo, hi = np.minimum(lo, w.min(axis=0)), np.maximum(hi, w.max(axis=0))
    return np.stack([lo, hi])
