"""Camera controllers for the viewer: fly (WASD + mouse look) and orbit (drag + zoom). Pure math, no GL.

Angles follow the scene's ``up`` vector: yaw turns about it, pitch tilts towards it. A controller is
built from any Camera (``from_camera``) and gives one back (``camera()``), so switching controllers
keeps the view.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from diviewer.scene import camera as cam
from diviewer.scene.model import Camera

PITCH_LIMIT = 89.0
"""Degrees; keeps the view direction off the up axis (where look_at is undefined)."""


def _frame(up) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(up, forward0, right0): an orthonormal frame with yaw = pitch = 0 looking along forward0."""
    u = cam.normalize(up)
    ref = np.array([0.0, 0.0, -1.0]) if abs(u[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    f0 = ref - np.dot(ref, u) * u
    f0 /= np.linalg.norm(f0)
    r0 = np.cross(f0, u)
    return u, f0, r0


def direction(up, yaw: float, pitch: float) -> np.ndarray:
    """Unit view direction for yaw (degrees, positive turns right) and pitch (degrees, positive looks up)."""
    u, f0, r0 = _frame(up)
    y, p = math.radians(yaw), math.radians(pitch)
    return math.cos(p) * (math.cos(y) * f0 + math.sin(y) * r0) + math.sin(p) * u


def yaw_pitch(up, forward) -> tuple[float, float]:
    """Inverse of ``direction``: the yaw and pitch (degrees) of a view direction."""
    u, f0, r0 = _frame(up)
    f = cam.normalize(forward)
    pitch = math.degrees(math.asin(float(np.clip(np.dot(f, u), -1.0, 1.0))))
    yaw = math.degrees(math.atan2(float(np.dot(f, r0)), float(np.dot(f, f0))))
    return yaw, pitch


def _clamp_pitch(p: float) -> float:
    return float(min(max(p, -PITCH_LIMIT), PITCH_LIMIT))


@dataclass
class FlyController:
    """First-person camera: WASD/QE move, mouse look while the right button is held, scroll sets speed."""

    position: np.ndarray
    yaw: float = 0.0
    pitch: float = 0.0
    up: tuple = (0.0, 1.0, 0.0)
    fov: float = 45.0
    near: float = 0.05
    far: float = 100.0
    speed: float = 1.0
    """Metres per second."""
    focus: float = 1.0
    """Distance to the camera's target (kept so the Camera's target stays meaningful)."""
    look_sensitivity: float = 0.2
    """Degrees per pixel of mouse motion."""
    kind: str = field(default="fly", init=False)

    @classmethod
    def from_camera(cls, camera: Camera, speed: float | None = None) -> "FlyController":
        pos = np.asarray(camera.position, dtype=np.float64)
        d = np.asarray(camera.target, dtype=np.float64) - pos
        yaw, pitch = yaw_pitch(camera.up, d)
        focus = float(np.linalg.norm(d))
        return cls(position=pos, yaw=yaw, pitch=_clamp_pitch(pitch), up=tuple(camera.up), fov=camera.fov,
                   near=camera.near, far=camera.far, speed=speed if speed is not None else max(focus, 0.1) * 0.5,
                   focus=max(focus, 1e-3))

    def forward(self) -> np.ndarray:
        return direction(self.up, self.yaw, self.pitch)

    def right(self) -> np.ndarray:
        r = np.cross(self.forward(), cam.normalize(self.up))
        return r / np.linalg.norm(r)

    def move(self, forward: float, right: float, up: float, dt: float, fast: bool = False) -> None:
        """Move along the view direction, the right vector and world up; each input in [-1, 1]."""
        step = self.speed * dt * (4.0 if fast else 1.0)
        self.position = (self.position + step * (forward * self.forward() + right * self.right()
                                                 + up * cam.normalize(self.up)))

    def look(self, dx: float, dy: float) -> None:
        """Mouse motion in pixels (x right, y down) turns the view."""
        self.yaw = (self.yaw + dx * self.look_sensitivity + 180.0) % 360.0 - 180.0
        self.pitch = _clamp_pitch(self.pitch - dy * self.look_sensitivity)

    def scroll(self, dy: float) -> None:
        """Wheel up makes moving faster, down slower (x1.25 per notch)."""
        self.speed = float(min(max(self.speed * 1.25 ** dy, 1e-3), 1e4))

    def drag(self, dx: float, dy: float) -> None:
        """Left-drag in fly mode also looks around."""
        self.look(dx, dy)

    def camera(self) -> Camera:
        target = self.position + self.focus * self.forward()
        return Camera(position=tuple(map(float, self.position)), target=tuple(map(float, target)), up=tuple(self.up),
                      fov=self.fov, near=self.near, far=self.far)


@dataclass
class OrbitController:
    """Turntable camera about a centre: left-drag rotates, scroll zooms, WASD pans the centre."""

    centre: np.ndarray
    distance: float = 5.0
    yaw: float = 0.0
    pitch: float = 0.0
    """Yaw and pitch of the view direction (from the camera to the centre)."""
    up: tuple = (0.0, 1.0, 0.0)
    fov: float = 45.0
    near: float = 0.05
    far: float = 100.0
    rotate_sensitivity: float = 0.3
    """Degrees per pixel of drag."""
    min_distance: float = 1e-2
    kind: str = field(default="orbit", init=False)

    @classmethod
    def from_camera(cls, camera: Camera, centre=None) -> "OrbitController":
        """Orbit about ``centre`` (default the camera's target), starting from the camera's position."""
        pos = np.asarray(camera.position, dtype=np.float64)
        c = np.asarray(camera.target if centre is None else centre, dtype=np.float64)
        d = c - pos
        dist = float(np.linalg.norm(d))
        if dist < 1e-6:
            d, dist = np.asarray(camera.target, dtype=np.float64) - pos, 1.0
        yaw, pitch = yaw_pitch(camera.up, d)
        return cls(centre=c, distance=max(dist, 1e-2), yaw=yaw, pitch=_clamp_pitch(pitch), up=tuple(camera.up),
                   fov=camera.fov, near=camera.near, far=camera.far)

    def forward(self) -> np.ndarray:
        return direction(self.up, self.yaw, self.pitch)

    def drag(self, dx: float, dy: float) -> None:
        """Drag in pixels (x right, y down) as if grabbing the scene: right turns it right, down tilts its top
        towards you."""
        self.yaw = (self.yaw + dx * self.rotate_sensitivity + 180.0) % 360.0 - 180.0
        self.pitch = _clamp_pitch(self.pitch - dy * self.rotate_sensitivity)

    def look(self, dx: float, dy: float) -> None:
        self.drag(dx, dy)

    def scroll(self, dy: float) -> None:
        """Wheel up zooms in (x0.9 distance per notch)."""
        self.distance = float(max(self.distance * 0.9 ** dy, self.min_distance))

    def move(self, forward: float, right: float, up: float, dt: float, fast: bool = False) -> None:
        """Pan the centre (WASD/QE), at a speed proportional to the distance."""
        step = 0.5 * self.distance * dt * (4.0 if fast else 1.0)
        f = self.forward()
        r = np.cross(f, cam.normalize(self.up))
        r /= np.linalg.norm(r)
        self.centre = self.centre + step * (forward * f + right * r + up * cam.normalize(self.up))

    def camera(self) -> Camera:
        pos = self.centre - self.distance * self.forward()
        return Camera(position=tuple(map(float, pos)), target=tuple(map(float, self.centre)), up=tuple(self.up),
                      fov=self.fov, near=self.near, far=self.far)


Controller = FlyController | OrbitController


def make_controller(kind: str, camera: Camera, centre=None) -> Controller:
    """A controller of ``kind`` ('fly' or 'orbit') showing ``camera``; orbit turns about ``centre``."""
    if kind == "fly":
        return FlyController.from_camera(camera)
    if kind == "orbit":
        return OrbitController.from_camera(camera, centre)
    raise ValueError(f"unknown camera controller {kind!r} (fly, orbit)")


def overview(camera: Camera, bounds, elevation: float = 35.0) -> Camera:
    """``camera`` moved outside the box ``bounds`` (2, 3), above it at ``elevation`` degrees on the side it looks
    from, looking at the box's centre, far enough that the box's bounding sphere fills the view's height."""
    lo, hi = np.asarray(bounds, np.float64)
    c, r = 0.5 * (lo + hi), max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3)
    back = np.asarray(camera.position, np.float64) - np.asarray(camera.target, np.float64)
    back[1] = 0.0
    n = float(np.linalg.norm(back))
    back = back / n if n > 1e-9 else np.array([0.0, 0.0, 1.0])
    e = math.radians(elevation)
    d = 1.05 * r / math.sin(math.radians(camera.fov) / 2.0)
    eye = c + d * (math.cos(e) * back + np.array([0.0, math.sin(e), 0.0]))
    return dataclasses.replace(camera, position=tuple(map(float, eye)), target=tuple(map(float, c)),
                               up=(0.0, 1.0, 0.0), far=max(camera.far, 2.0 * (d + r)))
