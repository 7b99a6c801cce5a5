"""The network's channel layout and the encoding of its inputs and outputs, defined once.

Training, ONNX export and the runtime all use these functions, so the exported graph carries the encoding: the
runtime feeds raw linear buffers and receives linear radiance. Every function here is elementwise (plus one
concatenation), written against a small set of array operations (`ArrayOps`: numpy here, torch's in
`diviewer.train.encoding_torch`), and uses only operators the ONNX exporter maps one-to-one (Log, Exp, Abs, Sign,
Where, Clip, IsNaN, IsInf, Concat). It never imports torch: the viewer and the benchmark run without it.

Radiance curve (used for the direct-light input and for the network's output)::

    t = x * exposure                        # exposed linear radiance, NaN -> 0
    y = sign(t) * log1p(min(|t|, R)) / log1p(R)      # R = radiance_max, y in [-1, 1]
    x = sign(y) * expm1(|y| * log1p(R)) / exposure   # the exact inverse

Why this curve:

- Absolute intensity is kept: a fixed function of each pixel, one exposure per dataset (twice the light decodes to
  twice the light; nothing depends on the other pixels).
- It is odd and maps 0 to exactly 0, where tanh is linear and float32 most precise: indirect-light targets can be
  slightly negative (Monte-Carlo noise), and black pixels would otherwise sit at a saturated end of tanh.
- It is linear below |t| ~ 1 and logarithmic above, like a tone curve: dark noise is not amplified (a pure log
  curve would weigh 1e-5 as 1) while highlights up to R are compressed into the top of the range, not clipped.
- Float32: near y = 0 the relative precision of y is that of x, because log1p and expm1 are evaluated with Kahan's
  exact-cancellation trick instead of log(1 + t) (which loses all digits of t below 6e-8, and which is how the
  ONNX exporter lowers log1p; expm1 it does not export at all). Near |y| = 1 the absolute spacing of float32 is
  6e-8, i.e. a relative error of log1p(R) * 6e-8 (7e-7 at R = 1e5) after decoding. Measured float32 round trip:
  relative error below 2e-6 for every |t| in [1e-30, R], 0 exact. tanh reaches 1.0 in float32 (for pre-activations
  above ~9), so R itself is reachable by the network. In float16 the spacing near 1 is 5e-4, a relative error of
  ~0.3 % after decoding: fine for an image, but keep encode/decode in float32 in an fp16 export.
- NaN maps to 0 and +-Inf to +-1 when encoding; decoding clamps y to [-1, 1] first: never NaN or Inf (the
  largest output, radiance_max / exposure, is checked to fit in float32).

Inputs: depth 0 (and NaN, Inf, negative) means no geometry and encodes to -1, while geometry maps into [0, 1]
(depth / depth_scale): background stays distinct even next to the near plane. Normals are in [-1, 1] already
(background (0, 0, 0) stays 0); albedo [0, 1] maps to [-1, 1].
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.provenance import check_known_keys

INPUT_CHANNELS: tuple[tuple[str, int], ...] = (("depth", 1), ("normal", 3), ("albedo", 3), ("direct", 3))
"""Network input buffers and their channel counts, in the order they are stacked."""

INPUT_CHANNEL_COUNT: int = sum(n for _, n in INPUT_CHANNELS)
"""Total number of network input channels (10)."""

WORLD_CHANNELS: tuple[tuple[str, int], ...] = (("world_position", 3), ("world_normal", 3))
"""The planes the graph appends to the encoded buffers under encoding version 3 (`diviewer.train.world`), in order."""

OUTPUT_CHANNELS: int = 3
"""Network output channels: linear RGB radiance (full GI or indirect only), encoded."""

ENCODING_VERSION: int = 4
"""The newest encoding version this diviewer reads and writes; bump it whenever a curve or the layout changes.

1: radiance (the direct-light input and the output) as is, times the dataset exposure.
2: as 1, but divided by the frame's light scale (`diviewer.scene.lights.light_scale`) on the way in and
multiplied by it on the way out, inside the graph (its second input ``light_scale``): the model is linear
in the light by construction (no light gives exactly 0, twice the light exactly twice the output).
3: as 2, plus each pixel's world-space position and normal as six more network inputs, computed inside the graph
from the depth and normal buffers and the frame's camera (its third input ``camera``,
`diviewer.scene.camera.camera_params`), the position normalised by ``world_center`` and ``world_half``
(`diviewer.train.world`).
4: as 3, plus where each of the scene's ``lights`` lights is: three numbers a light (a sun's direction, a point
light's normalised position: `diviewer.scene.lights.light_params`) from the graph's fourth input ``light``,
spread over the frame as constant planes. A network blind to them cannot tell which side of a scene the sun
lights when the frame shows only shade (docs/sponza.md at commit c48f1bc)."""

_FLOAT32_MAX = float(np.finfo(np.float32).max)

# Rec. 709 / sRGB primaries: relative luminance of linear RGB.
_LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


INPUT_NAMES: tuple[str, ...] = tuple(name for name, _ in INPUT_CHANNELS)
"""The input buffers' names in stacking order: what the GL renderer returns and the pack shader writes."""


def channel_slices(channels: Iterable[tuple[str, int]] = INPUT_CHANNELS) -> dict[str, slice]:
    """Where each named buffer lies along the channel axis of a stack of ``channels`` (name, count)."""
    slices: dict[str, slice] = {}
    start = 0
    for name, n in channels:
        slices[name] = slice(start, start + n)
        start += n
    return slices


def input_channel_slices() -> dict[str, slice]:
    """Where each input buffer lies along the channel axis of the stacked network input."""
    return channel_slices(INPUT_CHANNELS)


@dataclass(frozen=True)
class Encoding:
    """Settings of the input/output encoding, fixed per dataset and recorded in every artifact."""

    exposure: float = 1.0
    """Multiplier applied to linear HDR radiance before the curve; fixed per dataset, see
    `fit_exposure`. It sets which radiance lands in the linear part of the curve (~1)."""

    depth_scale: float = 1.0
    """View-space depth (scene units) is divided by this before encoding; use the camera's far
    plane, so all visible geometry maps into [0, 1]."""

    radiance_max: float = 1e5
    """Largest exposed radiance (radiance * exposure) that maps to the top of the network range
    (+-1); brighter values saturate there but stay finite. The default spans 10 orders of
    magnitude above 1e-5 (and float32 keeps relative precision far below that)."""

    version: int = 1
    """Version of the encoding (see `ENCODING_VERSION`): 1 radiance as is, 2 divided by the frame's light
    scale (training chooses with ``TrainConfig.light_scale``), 3 also world-space inputs (``world_inputs``), 4 also
    the lights' directions or positions (``light_inputs``)."""

    world_center: tuple[float, float, float] | None = None
    """Version 3: the world point that encodes to 0 (the centre of the scene's bounds)."""

    world_half: tuple[float, float, float] | None = None
    """Version 3: per axis, the distance from ``world_center`` that encodes to +-1 (half the bounds' size)."""

    lights: int | None = None
    """Version 4: how many lights the ``light`` input describes (the scene's, in the order of its file)."""

    output_gain: float = 1.0
    """The network's output (the target) is encoded at ``exposure * output_gain`` (`output`), its inputs at
    ``exposure``: a sunlit scene's indirect light is a few % of its direct light and would otherwise use 1e-3 of
    the encoded range (`diviewer.train.targets.fit_output_gain`). Any version; 1: as before it existed."""

    def __post_init__(self) -> None:
        for name in ("exposure", "depth_scale", "radiance_max", "output_gain"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise DiviewerError(f"must be a number, got {value!r}", field=f"encoding.{name}")
            if not (math.isfinite(value) and value > 0):
                raise DiviewerError(f"must be finite and > 0, got {value!r}", field=f"encoding.{name}")
        if self.radiance_max / self.exposure > 1e37:
            # decode_radiance returns up to radiance_max / exposure, which must stay finite in float32.
            raise DiviewerError(
                f"radiance_max / exposure = {self.radiance_max / self.exposure:.3g} does not fit "
                "in float32; raise the exposure or lower radiance_max",
                field="encoding.exposure",
            )
        if isinstance(self.version, bool) or not isinstance(self.version, int) or self.version < 1:
            raise DiviewerError(f"must be an integer >= 1, got {self.version!r}", field="encoding.version")
        if self.version > ENCODING_VERSION:
            raise DiviewerError(
                f"encoding version {self.version} is newer than this diviewer understands "
                f"(version {ENCODING_VERSION}); upgrade diviewer to read this data or model",
                field="encoding.version",
            )

        given = [v is not None for v in (self.world_center, self.world_half)]
        if any(given) != all(given) or all(given) != (self.version >= 3):
            raise DiviewerError(f"version {self.version} {'needs' if self.version >= 3 else 'has no'} world_center "
                                "and world_half", field="encoding.world_center")
        for name in ("world_center", "world_half"):
            v = getattr(self, name)
            if v is None:
                continue
            if not (isinstance(v, (list, tuple)) and len(v) == 3 and all(
                    isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)):
                raise DiviewerError(f"must be three finite numbers, got {v!r}", field=f"encoding.{name}")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        if self.world_half is not None and min(self.world_half) <= 0:
            raise DiviewerError(f"must be > 0, got {self.world_half!r}", field="encoding.world_half")
        if (self.lights is not None) != (self.version >= 4):
            raise DiviewerError(f"version {self.version} {'needs' if self.version >= 4 else 'has no'} lights",
                                field="encoding.lights")
        if self.lights is not None and (isinstance(self.lights, bool) or not isinstance(self.lights, int)
                                        or self.lights < 1):
            raise DiviewerError(f"must be an integer >= 1, got {self.lights!r}", field="encoding.lights")

    @property
    def world_inputs(self) -> bool:
        """Whether the network also takes each pixel's world position and normal (version 3)."""
        return self.version >= 3

    @property
    def light_inputs(self) -> bool:
        """Whether the network also takes where each light is (version 4)."""
        return self.version >= 4

    @property
    def input_planes(self) -> int:
        """The network's input planes: the buffers, the world planes (version 3), three a light (version 4)."""
        from diviewer.scene.lights import LIGHT_PARAMS

        return (INPUT_CHANNEL_COUNT + (sum(n for _, n in WORLD_CHANNELS) if self.world_inputs else 0)
                + (LIGHT_PARAMS * self.lights if self.light_inputs else 0))

    @property
    def light_scaled(self) -> bool:
        """Whether radiance is divided by the frame's light scale (version 2 and later)."""
        return self.version >= 2

    def to_dict(self) -> dict[str, Any]:
        """Plain dict for JSON manifests, checkpoints and ONNX metadata (the world fields only from version 3, the
        lights only from version 4, the output gain only where it is not 1)."""
        d = dataclasses.asdict(self)
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()
                if not ((k.startswith("world_") or k == "lights") and v is None) and not (k == "output_gain" and v == 1)}

    def output(self) -> Encoding:
        """The encoding of the network's output: the exposure times ``output_gain`` (``encode_radiance`` of the
        target, ``decode_radiance`` of the prediction)."""
        return self if self.output_gain == 1 else dataclasses.replace(self, exposure=self.exposure * self.output_gain,
                                                                      output_gain=1.0)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Encoding:
        """Rebuild from `to_dict()` output; unknown keys, missing version or a newer version are errors."""
        check_known_keys(cls, data, "encoding", "data written by a newer diviewer? upgrade diviewer")
        if "version" not in data:
            raise DiviewerError("missing 'version'; cannot tell how the data was encoded", field="encoding")
        return cls(**dict(data))


# ---------------------------------------------------------------------------------------------
# Array operations: numpy here; `diviewer.train.encoding_torch` passes torch's (TORCH_OPS), so this
# module never imports torch while training and export run the very same functions on tensors.


class ArrayOps:
    """The few array operations the encodings use, on numpy arrays (subclassed for torch in train/)."""

    abs = staticmethod(np.abs)
    sign = staticmethod(np.sign)
    log = staticmethod(np.log)
    exp = staticmethod(np.exp)
    isnan = staticmethod(np.isnan)
    isinf = staticmethod(np.isinf)

    @staticmethod
    def where(cond: Any, a: Any, b: Any) -> Any:
        return np.where(cond, a, b).astype(np.result_type(a, b), copy=False)

    @staticmethod
    def clip(x: Any, lo: float, hi: float) -> Any:
        return np.clip(x, lo, hi)

    @staticmethod
    def cat(parts: list[Any], axis: int) -> Any:
        return np.concatenate(parts, axis=axis)

    @staticmethod
    def expand_dims(x: Any, axis: int) -> Any:
        return np.expand_dims(x, axis)

    @staticmethod
    def prepare(x: Any, name: str) -> Any:
        """x as a floating-point array; integer buffers are refused (their scale is unknown)."""
        if type(x).__module__.startswith("torch"):
            raise TypeError(f"{name}: torch tensors are encoded by diviewer.train.encoding_torch, not diviewer.contract.encoding")
        if not isinstance(x, np.ndarray):
            return np.asarray(x, dtype=np.float64)  # Python numbers and lists
        if x.dtype.kind != "f":
            raise TypeError(
                f"{name}: expected a floating-point array, got {x.dtype} "
                "(convert to float32 first, e.g. albedo / 255 for 8-bit colour)"
            )
        if x.dtype.itemsize < 4:
            return x.astype(np.float32)  # float16 in, float32 math: see the module docstring
        return x


NUMPY_OPS = ArrayOps()
"""The default operations: numpy arrays."""


def _nan_to_zero(x: Any, ops: ArrayOps) -> Any:
    return ops.where(ops.isnan(x), 0.0, x)


def _log1p(a: Any, ops: ArrayOps) -> Any:
    """log(1 + a) for a >= 0, accurate for tiny a, from Log/Where only (exports to any ONNX opset).

    Goldberg/Kahan: with u = fl(1 + a), log(u) * a / (u - 1) cancels the rounding of 1 + a.
    """
    u = a + 1.0
    d = u - 1.0
    tiny = d == 0
    safe_d = ops.where(tiny, 1.0, d)  # no 0/0 even in the branch that is not taken (NaN gradients)
    return ops.where(tiny, a, ops.log(u) * (a / safe_d))


def _expm1(z: Any, ops: ArrayOps) -> Any:
    """exp(z) - 1 for z >= 0, accurate for tiny z, from Exp/Log/Where only (Kahan's trick)."""
    u = ops.exp(z)
    d = u - 1.0
    tiny = d == 0
    safe_log = ops.where(tiny, 1.0, ops.log(u))
    return ops.where(tiny, z, d * (z / safe_log))


# ---------------------------------------------------------------------------------------------
# Encodings


def inverse_light_scale(s: Any, ops: ArrayOps = NUMPY_OPS) -> Any:
    """1 / s where the light scale s is > 0 (and finite), else 0: a frame without light maps to exactly 0.

    Version 2 multiplies the radiance input by this and the decoded output by s itself, so s = 0 gives
    0 * (finite decoded value) = 0, never 0/0.
    """
    s = ops.prepare(s, "light scale")
    ok = (s > 0) & ~ops.isinf(s)  # NaN compares false
    return ops.where(ok, 1.0 / ops.where(ok, s, 1.0), 0.0)


def encode_radiance(x: Any, enc: Encoding, ops: ArrayOps = NUMPY_OPS) -> Any:
    """Linear HDR radiance (any sign) -> network range [-1, 1], elementwise; see the module docstring.

    NaN maps to 0 and +-Inf (or anything beyond radiance_max once exposed) to +-1.
    """
    x = ops.prepare(x, "radiance")
    t = _nan_to_zero(x * enc.exposure, ops)
    a = ops.clip(ops.abs(t), 0.0, enc.radiance_max)  # also turns +-Inf into radiance_max
    y = ops.sign(t) * (_log1p(a, ops) / math.log1p(enc.radiance_max))
    return ops.clip(y, -1.0, 1.0)  # log1p(R) rounded to float32 may exceed the float64 constant by an ulp


def decode_radiance(y: Any, enc: Encoding, ops: ArrayOps = NUMPY_OPS) -> Any:
    """Network range [-1, 1] -> linear HDR radiance, the inverse of `encode_radiance`; never NaN/Inf.

    Values outside [-1, 1] are clamped and NaN decodes to 0, so a misbehaving network cannot put
    NaN or Inf into the frame.
    """
    y = ops.prepare(y, "encoded radiance")
    y = ops.clip(_nan_to_zero(y, ops), -1.0, 1.0)
    a = _expm1(ops.abs(y) * math.log1p(enc.radiance_max), ops)
    return ops.sign(y) * a * (1.0 / enc.exposure)


def encode_depth(depth: Any, enc: Encoding, ops: ArrayOps = NUMPY_OPS) -> Any:
    """View-space depth -> [0, 1] for geometry (depth / depth_scale, clamped), -1 for no geometry.

    Depth <= 0, NaN and +-Inf all mean "no geometry": background stays distinct from near geometry.
    """
    depth = ops.prepare(depth, "depth")
    d = depth * (1.0 / enc.depth_scale)
    geometry = (d > 0) & ~ops.isinf(d)  # NaN compares false
    return ops.where(geometry, ops.clip(_nan_to_zero(d, ops), 0.0, 1.0), -1.0)


def encode_normal(normal: Any, ops: ArrayOps = NUMPY_OPS) -> Any:
    """Unit normals are already in [-1, 1]; NaN -> 0 and clamping keep the network input bounded."""
    normal = ops.prepare(normal, "normal")
    return ops.clip(_nan_to_zero(normal, ops), -1.0, 1.0)


def encode_albedo(albedo: Any, ops: ArrayOps = NUMPY_OPS) -> Any:
    """Diffuse albedo [0, 1] -> [-1, 1] (NaN -> black)."""
    albedo = ops.prepare(albedo, "albedo")
    return ops.clip(_nan_to_zero(albedo, ops), 0.0, 1.0) * 2.0 - 1.0


def encode_inputs(depth: Any, normal: Any, albedo: Any, direct: Any, enc: Encoding, *, channel_axis: int,
                  ops: ArrayOps = NUMPY_OPS) -> Any:
    """Raw linear G-buffers + direct light -> the stacked network input in [-1, 1].

    Args:
        depth: view-space depth, with a channel axis of size 1 or without one (then it is added).
        normal: view- or world-space unit normals (whichever the dataset uses), 3 channels.
        albedo: diffuse albedo, linear, 3 channels.
        direct: linear direct radiance (unexposed), 3 channels.
        enc: the dataset's encoding.
        channel_axis: where the channels are: -1 for numpy HWC frames, 1 for torch NCHW batches.
        ops: the array operations (numpy; torch through `diviewer.train.encoding_torch`).

    Returns:
        The encoded buffers concatenated along channel_axis in `INPUT_CHANNELS` order (10 channels).
    """
    depth = ops.prepare(depth, "depth")
    normal = ops.prepare(normal, "normal")
    ndim = normal.ndim
    axis = channel_axis % ndim if -ndim <= channel_axis < ndim else None
    if axis is None:
        raise ValueError(f"channel_axis={channel_axis} is out of range for {ndim}-d buffers")
    if depth.ndim == ndim - 1:
        depth = ops.expand_dims(depth, axis)
    buffers = {"depth": depth, "normal": normal, "albedo": albedo, "direct": direct}
    for name, n in INPUT_CHANNELS:
        shape = tuple(buffers[name].shape)
        if len(shape) != ndim or shape[axis] != n:
            raise ValueError(
                f"{name}: expected {ndim}-d with {n} channel(s) on axis {channel_axis}, got shape {shape}"
            )
    parts = [
        encode_depth(depth, enc, ops),
        encode_normal(normal, ops),
        encode_albedo(albedo, ops),
        encode_radiance(direct, enc, ops),
    ]
    return ops.cat(parts, axis)


def fit_exposure(direct_images: Any, *, percentile: float = 99.0, target: float = 1.0, max_samples: int = 1 << 22) -> float:
    """Dataset exposure that maps the given percentile of lit-pixel luminance to `target`.

    Only finite, positive luminances count (shadow, background and NaN pixels are ignored), so the
    exposure describes the light, not the fraction of the frame it covers. An all-black or all-NaN
    dataset gets exposure 1.0.

    Args:
        direct_images: linear direct-light images, RGB on the last axis: one (H, W, 3) array, an
            (N, H, W, 3) array, or a list of such arrays (sizes may differ).
        percentile: which luminance maps to `target`; 99 keeps a few highlights above it.
        target: the exposed luminance that percentile should have (the curve's knee is at ~1).
        max_samples: at most this many pixels are used (a fixed stride), to bound memory.

    Returns:
        The exposure, a finite positive float.
    """
    if isinstance(direct_images, np.ndarray) or type(direct_images).__module__.startswith("torch"):
        images = [np.asarray(direct_images)]
    else:
        images = [np.asarray(im) for im in direct_images]
    total = sum(im.size // 3 for im in images)
    if total == 0:
        return 1.0
    stride = max(1, math.ceil(total / max_samples))
    samples = []
    for im in images:
        if im.ndim < 1 or im.shape[-1] != 3:
            raise ValueError(f"fit_exposure: expected RGB on the last axis, got shape {im.shape}")
        rgb = im.reshape(-1, 3)[::stride].astype(np.float64)
        with np.errstate(invalid="ignore", over="ignore"):
            lum = rgb @ _LUMINANCE_WEIGHTS
        samples.append(lum[np.isfinite(lum) & (lum > 0)])
    lum = np.concatenate(samples)
    if lum.size == 0:
        return 1.0
    level = float(np.percentile(lum, percentile))
    exposure = target / level
    # A level so small or large that the exposure itself is not a usable float32: fall back to 1.
    if not (math.isfinite(exposure) and 0 < exposure < _FLOAT32_MAX):
        return 1.0
    return exposure
