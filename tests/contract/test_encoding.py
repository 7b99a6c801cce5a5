"""Tests for diviewer.contract.encoding: the radiance curve, the input stack, the settings, the exposure fit."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from diviewer.contract.encoding import (
    ENCODING_VERSION,
    INPUT_CHANNEL_COUNT,
    INPUT_CHANNELS,
    OUTPUT_CHANNELS,
    Encoding,
    decode_radiance,
    encode_inputs,
    encode_radiance,
    fit_exposure,
    input_channel_slices,
)
from diviewer.errors import DiviewerError

# Round-trip tolerances (relative) promised in the module docstring; measured 1.5e-6 and 2.8e-15.
RTOL_F32 = 5e-6
RTOL_F64 = 1e-12

ENC = Encoding(exposure=0.25, depth_scale=50.0)  # a non-trivial exposure, so it is really applied


def _magnitudes(enc: Encoding, dtype: type) -> np.ndarray:
    """0, then exposed radiance from 1e-30 up to exactly radiance_max, both signs (unexposed units)."""
    t = np.concatenate([np.logspace(-30, np.log10(enc.radiance_max), 20001), [enc.radiance_max]])
    x = t / enc.exposure
    return np.concatenate([[0.0], x, -x]).astype(dtype)


def test_layout_constants() -> None:
    assert [name for name, _ in INPUT_CHANNELS] == ["depth", "normal", "albedo", "direct"]
    assert INPUT_CHANNEL_COUNT == 10 and OUTPUT_CHANNELS == 3
    slices = input_channel_slices()
    assert slices["depth"] == slice(0, 1) and slices["direct"] == slice(7, 10)


def test_every_copy_of_the_channel_layout_follows_the_encoding() -> None:
    """The GL renderer's buffers, the pack shader's offsets, the dataset's stored channels and the
    export's slices all come from INPUT_CHANNELS; this fails if one is written out again and drifts.
    (The GPU packing itself is compared bit for bit with the table in tests/test_runtime.py.)"""
    import inspect
    import re

    from diviewer.data.dataset import CHANNELS
    from diviewer.gl.neural import PACK_DEFINES
    from diviewer.gl.renderer import BUFFERS
    from diviewer.paths import shaders_dir
    from diviewer.contract.runtime import pack_buffers

    names = [name for name, _ in INPUT_CHANNELS]
    assert list(BUFFERS) == names
    assert CHANNELS[:len(INPUT_CHANNELS)] == INPUT_CHANNELS and len({n for n, _ in CHANNELS}) == len(CHANNELS)
    slices = input_channel_slices()
    assert PACK_DEFINES == {"IN_CHANNELS": INPUT_CHANNEL_COUNT,
                            **{f"IN_{n.upper()}": slices[n].start for n in names},
                            **{f"IN_{n.upper()}_N": c for n, c in INPUT_CHANNELS}}
    # The shader indexes only through those defines: no channel offset or count written as a number.
    shader = (shaders_dir() / "pack.glsl").read_text()
    indices = re.findall(r"data\[([^\]]*)\]", shader.split("float data[]; };")[1])
    assert indices and all(re.fullmatch(r"base \+ IN_[A-Z]+( \+ [12])?", i) for i in indices), indices
    assert "* IN_CHANNELS" in shader and not re.search(r"\*\s*\d+;", shader)
    # The CPU packing and the export read by name from the same table.
    frame = {n: np.full((2, 3, c), i, np.float32) for i, (n, c) in enumerate(INPUT_CHANNELS)}
    packed = pack_buffers(frame)
    for i, n in enumerate(names):
        assert (packed[..., slices[n]] == i).all()
    from diviewer.train import export  # imports torch only when it exports

    assert not re.search(r"x\[:, \d+:\d+\]", inspect.getsource(export)), "export slices channels by number again"


@pytest.mark.parametrize(("dtype", "rtol"), [(np.float32, RTOL_F32), (np.float64, RTOL_F64)])
def test_radiance_round_trip_whole_range(dtype: type, rtol: float) -> None:
    x = _magnitudes(ENC, dtype)
    y = encode_radiance(x, ENC)
    assert y.dtype == dtype
    assert np.all(np.abs(y) <= 1.0)
    back = decode_radiance(y, ENC)
    assert back[0] == 0.0 and y[0] == 0.0  # 0 is exact
    assert np.all(np.sign(back) == np.sign(x))  # negatives stay negative
    rel = np.abs(back[1:] - x[1:]) / np.abs(x[1:])
    assert rel.max() <= rtol, f"worst relative error {rel.max():.3g} at {x[1:][rel.argmax()]:.3g}"


def test_curve_is_monotonic_and_odd() -> None:
    m = _magnitudes(ENC, np.float64)
    x = m[1 : 1 + (len(m) - 1) // 2]  # the positive half, increasing
    y = encode_radiance(x, ENC)
    assert np.all(np.diff(y) >= 0) and y[-1] == 1.0
    np.testing.assert_array_equal(encode_radiance(-x, ENC), -y)


def test_extreme_inputs_stay_finite() -> None:
    x = np.concatenate([np.logspace(-12, 12, 241), -np.logspace(-12, 12, 241)]).astype(np.float32)
    y = encode_radiance(x, ENC)
    back = decode_radiance(y, ENC)
    assert np.isfinite(y).all() and np.isfinite(back).all()
    assert np.all(np.abs(y) <= 1.0)
    # Beyond radiance_max values saturate at the top of the range and decode to about radiance_max.
    huge = np.abs(x) * ENC.exposure > ENC.radiance_max
    assert np.all(np.abs(y[huge]) == 1.0)
    np.testing.assert_allclose(np.abs(back[huge]), ENC.radiance_max / ENC.exposure, rtol=RTOL_F32)


def test_nan_and_inf() -> None:
    x = np.array([np.nan, np.inf, -np.inf], dtype=np.float32)
    np.testing.assert_array_equal(encode_radiance(x, ENC), [0.0, 1.0, -1.0])
    # A misbehaving network output (NaN, Inf, out of the tanh range) still decodes to finite radiance.
    y = np.array([np.nan, np.inf, -np.inf, 3.0, -3.0, 1.0], dtype=np.float32)
    back = decode_radiance(y, ENC)
    assert np.isfinite(back).all()
    assert back[0] == 0.0
    np.testing.assert_allclose(back[1:], np.array([1, -1, 1, -1, 1]) * ENC.radiance_max / ENC.exposure, rtol=RTOL_F32)


def test_intensity_is_absolute() -> None:
    rng = np.random.default_rng(1)
    image = rng.uniform(0.0, 3.0, (8, 8, 3)).astype(np.float32)
    # Twice the light decodes to twice the light: no per-image normalisation.
    once = decode_radiance(encode_radiance(image, ENC), ENC)
    twice = decode_radiance(encode_radiance(2 * image, ENC), ENC)
    np.testing.assert_allclose(twice, 2 * once, rtol=RTOL_F32)
    assert not np.allclose(encode_radiance(2 * image, ENC), encode_radiance(image, ENC))
    # A pixel encodes the same alone as inside any image.
    np.testing.assert_array_equal(encode_radiance(image[3:4, 5:6], ENC), encode_radiance(image, ENC)[3:4, 5:6])


def random_frame(rng: np.random.Generator, h: int = 6, w: int = 5) -> tuple[np.ndarray, ...]:
    """Random depth (a background row), unit normals, albedo and direct light: the four input buffers."""
    depth = rng.uniform(0.1, 60.0, (h, w)).astype(np.float32)
    depth[0, :] = 0.0  # background row
    normal = rng.normal(size=(h, w, 3)).astype(np.float32)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    normal[0, :] = 0.0
    albedo = rng.uniform(0, 1, (h, w, 3)).astype(np.float32)
    direct = rng.uniform(0, 5, (h, w, 3)).astype(np.float32)
    return depth, normal, albedo, direct


def test_encode_inputs_layout_and_range() -> None:
    depth, normal, albedo, direct = random_frame(np.random.default_rng(2))
    depth[1, 0] = 1e-4  # geometry right at the camera
    depth[1, 1] = np.nan
    albedo[1, 2] = np.nan
    x = encode_inputs(depth, normal, albedo, direct, ENC, channel_axis=-1)
    assert x.shape == (6, 5, INPUT_CHANNEL_COUNT) and x.dtype == np.float32
    assert np.isfinite(x).all() and np.all(np.abs(x) <= 1.0)
    s = input_channel_slices()
    d = x[..., s["depth"]][..., 0]
    assert np.all(d[0] == -1.0)  # background
    assert d[1, 1] == -1.0  # NaN depth counts as background
    assert np.all(d[1:][~np.isnan(depth[1:])] >= 0.0)  # any geometry, even at 1e-4, is >= 0
    np.testing.assert_allclose(d[2:], np.clip(depth[2:] / ENC.depth_scale, 0, 1), rtol=1e-6)
    np.testing.assert_array_equal(x[..., s["normal"]], normal)
    np.testing.assert_allclose(x[..., s["albedo"]][2:], 2 * albedo[2:] - 1, atol=1e-7)
    assert np.all(x[1, 2, s["albedo"]] == -1.0)
    np.testing.assert_array_equal(x[..., s["direct"]], encode_radiance(direct, ENC))
    # A depth buffer that already has its channel axis gives the same result.
    np.testing.assert_array_equal(encode_inputs(depth[..., None], normal, albedo, direct, ENC, channel_axis=-1), x)


def test_encode_inputs_refuses_bad_buffers() -> None:
    depth, normal, albedo, direct = random_frame(np.random.default_rng(5))
    with pytest.raises(ValueError, match="albedo"):
        encode_inputs(depth, normal, albedo[..., :2], direct, ENC, channel_axis=-1)
    with pytest.raises(TypeError, match="albedo"):
        encode_inputs(depth, normal, (albedo * 255).astype(np.uint8), direct, ENC, channel_axis=-1)


def test_module_does_not_import_torch() -> None:
    code = "import sys, diviewer.contract.encoding; sys.exit('torch' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


def test_encoding_dict_round_trip_and_rejections() -> None:
    assert Encoding.from_dict(ENC.to_dict()) == ENC
    assert ENC.to_dict()["version"] == 1 and Encoding(version=2).light_scaled  # 1 unless asked
    world = Encoding(version=3, world_center=[0, 1, 0], world_half=(1.1, 1.2, 1.3))
    assert world.light_scaled and world.world_inputs and not Encoding(version=2).world_inputs
    assert Encoding.from_dict(world.to_dict()) == world and world.world_center == (0.0, 1.0, 0.0)
    assert "world_center" not in Encoding(version=2).to_dict()  # the dicts of versions 1 and 2 are as they were
    assert "lights" not in world.to_dict() and not world.light_inputs  # nor version 3's
    lit = Encoding(version=ENCODING_VERSION, world_center=[0, 1, 0], world_half=(1.1, 1.2, 1.3), lights=2)
    assert ENCODING_VERSION == 4 and lit.light_inputs and lit.world_inputs and lit.to_dict()["lights"] == 2
    assert Encoding.from_dict(lit.to_dict()) == lit
    for bad in (dict(version=4, world_center=(0, 0, 0), world_half=(1, 1, 1)),
                dict(version=3, world_center=(0, 0, 0), world_half=(1, 1, 1), lights=1),
                dict(version=4, world_center=(0, 0, 0), world_half=(1, 1, 1), lights=0),
                dict(version=4, world_center=(0, 0, 0), world_half=(1, 1, 1), lights=True)):
        with pytest.raises(DiviewerError, match="lights"):
            Encoding(**bad)
    for bad in (dict(version=3), dict(version=2, world_center=(0, 0, 0), world_half=(1, 1, 1)),
                dict(version=3, world_center=(0, 0, 0), world_half=(1, 0, 1)),
                dict(version=3, world_center=(0, 0), world_half=(1, 1, 1))):
        with pytest.raises(DiviewerError, match="world"):
            Encoding(**bad)
    gained = Encoding(exposure=2.0, output_gain=8.0)
    assert "output_gain" not in ENC.to_dict() and Encoding.from_dict(gained.to_dict()) == gained  # 1: not written
    assert gained.output() == Encoding(exposure=16.0) and ENC.output() is ENC  # the output's exposure
    for bad in (0.0, -1.0, float("nan"), True):
        with pytest.raises(DiviewerError, match="output_gain"):
            Encoding(output_gain=bad)
    with pytest.raises(DiviewerError, match="unknown key.*gamma"):
        Encoding.from_dict({**ENC.to_dict(), "gamma": 2.2})
    with pytest.raises(DiviewerError, match="newer"):
        Encoding.from_dict({**ENC.to_dict(), "version": ENCODING_VERSION + 1})
    with pytest.raises(DiviewerError, match="version"):
        Encoding.from_dict({"exposure": 1.0})
    with pytest.raises(DiviewerError, match="exposure"):
        Encoding(exposure=0.0)
    with pytest.raises(DiviewerError, match="radiance_max"):
        Encoding(radiance_max=float("inf"))


def test_fit_exposure() -> None:
    rng = np.random.default_rng(7)
    images = [rng.uniform(0, 4.0, (16, 16, 3)).astype(np.float32) for _ in range(3)]
    images[0][:8] = 0.0  # shadow does not pull the exposure up
    images[1][0, 0] = np.nan
    exposure = fit_exposure(images)
    lum = np.concatenate([im.reshape(-1, 3) @ [0.2126, 0.7152, 0.0722] for im in images])
    lum = lum[np.isfinite(lum) & (lum > 0)]
    assert np.isfinite(exposure) and exposure > 0
    np.testing.assert_allclose(np.percentile(lum, 99) * exposure, 1.0, rtol=1e-9)
    # Scale-equivariant: ten times the light, a tenth of the exposure; lists and stacks agree.
    np.testing.assert_allclose(fit_exposure([10 * im for im in images]), exposure / 10, rtol=1e-6)
    np.testing.assert_allclose(fit_exposure(np.stack(images)), exposure, rtol=1e-12)
    # All black or all NaN: nothing to fit, a neutral exposure.
    assert fit_exposure([np.zeros((4, 4, 3), np.float32)]) == 1.0
    assert fit_exposure(np.full((4, 4, 3), np.nan, np.float32)) == 1.0


def test_torch_tensors_are_refused_with_a_pointer_to_train() -> None:
    torch = pytest.importorskip("torch")
    with pytest.raises(TypeError, match="encoding_torch"):
        encode_radiance(torch.zeros(3), ENC)
