"""The runtime at the extremes: NaN/Inf in each input channel (counted by the runtime, sanitised by the
exported graph's encoding), negative output (clamped), corrupt model metadata and files (one error
naming the field), the shipped model at zero light."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from diviewer.contract.encoding import INPUT_CHANNELS
from diviewer.errors import DiviewerError
from diviewer.contract.runtime import NeuralGI, count_nonfinite, pack_buffers, read_metadata
from onnx_models import base_meta, direct_times

CHANNEL_NAMES = [f"{name}[{k}]" for name, n in INPUT_CHANNELS for k in range(n)]


def buffers(h=16, w=16, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0.1, 1.0, (h, w, 10)).astype(np.float32)
    x[..., 0] = rng.uniform(1.0, 5.0, (h, w))
    return x


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return NeuralGI(direct_times(tmp_path_factory.mktemp("m") / "m.onnx", factor=2.0))


@pytest.mark.parametrize("channel", range(10), ids=CHANNEL_NAMES)
@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_non_finite_input_is_counted_and_stays_where_it_arose(model, channel, value):
    """A toy graph (2 x direct) has no encoding: what it returns non-finite stays at that pixel, counted."""
    x = buffers()
    x[3, 5, channel] = value
    x[7, 1, channel] = value
    y = model.run(x)
    assert model.nonfinite_inputs == 2
    broken = ~np.isfinite(y).all(axis=-1)
    # -inf radiance is clamped to 0 like any negative value; NaN and +inf stay visible
    assert np.argwhere(broken).tolist() == ([[3, 5], [7, 1]] if channel >= 7 and value != -np.inf else [])
    assert model.nonfinite_outputs == (2 if channel >= 7 else 0)
    assert np.all(y[~broken] >= 0)


@pytest.mark.parametrize("value", [1e30, 3e38, -3e38])
def test_huge_finite_input_is_passed_on_uncounted(model, value):
    x = buffers()
    x[0, 0, 0] = value
    model.run(x)
    assert model.nonfinite_inputs == 0


def test_count_of_clean_and_huge_input_is_zero():
    x = buffers()[None]
    assert count_nonfinite(x) == 0
    x[0, 0, 0, :] = 3.4e38  # the float64 sum does not overflow
    assert count_nonfinite(x) == 0


def test_negative_model_output_is_clamped(tmp_path):
    m = NeuralGI(direct_times(tmp_path / "neg.onnx", factor=-3.0))
    y = m.run(buffers())
    assert np.all(y == 0.0)


def test_overflowing_model_output_is_counted(tmp_path):
    m = NeuralGI(direct_times(tmp_path / "big.onnx", factor=1e38))
    x = buffers()
    x[..., 7:10] = 100.0  # 1e40: float32 infinity
    y = m.run(x)
    assert m.nonfinite_outputs == y.size and m.nonfinite_inputs == 0


# --- model metadata: wrong types, missing keys, zero divisors -----------------------------------
@pytest.mark.parametrize("key,value", [
    ("multiple", 0), ("multiple", 3), ("multiple", "16"), ("multiple", -16), ("resolution", [32]),
    ("resolution", "32x32"), ("resolution", [0, 32]), ("K", -1), ("K", 1.5), ("levels", None), ("levels", -2),
    ("target", "everything"), ("encoding", [1]), ("encoding", {"version": "1"}), ("format", "1"),
    ("precision", "int8"), ("scene_hash", 0), ("channels", "depth"),
])
def test_wrong_metadata_is_refused_naming_the_field(tmp_path, key, value):
    meta = base_meta()
    meta[key] = value
    path = direct_times(tmp_path / "m.onnx", meta=meta)
    with pytest.raises(DiviewerError) as exc:
        NeuralGI(path)
    assert f"diviewer.{key}" in str(exc.value) and str(path) in str(exc.value)


@pytest.mark.parametrize("key", ["multiple", "resolution", "scene_hash", "encoding"])
def test_missing_metadata_is_refused(tmp_path, key):
    meta = base_meta()
    del meta[key]
    with pytest.raises(DiviewerError, match=key):
        read_metadata(direct_times(tmp_path / "m.onnx", meta=meta))


def test_metadata_that_is_not_an_object_is_refused(tmp_path):
    import json

    import onnx

    path = direct_times(tmp_path / "m.onnx")
    model = onnx.load(str(path))
    onnx.helper.set_model_props(model, {"diviewer": json.dumps([1, 2])})
    onnx.save(model, str(path))
    with pytest.raises(DiviewerError, match="not a JSON object"):
        read_metadata(path)


# --- model files ---------------------------------------------------------------------------------
@pytest.mark.parametrize("fraction", [0.0, 0.1, 0.5, 0.9, 0.999])
def test_truncated_onnx_is_one_error(tmp_path, fraction):
    src = direct_times(tmp_path / "m.onnx").read_bytes()
    path = tmp_path / "cut.onnx"
    path.write_bytes(src[:int(len(src) * fraction)])
    with pytest.raises(DiviewerError) as exc:
        NeuralGI(path)
    assert str(path) in str(exc.value)


def test_pickle_renamed_onnx_is_refused_without_running_it(tmp_path):
    import pickle

    flag = tmp_path / "ran"

    class Payload:
        def __reduce__(self):
            return (open, (str(flag), "w"))

    path = tmp_path / "evil.onnx"
    path.write_bytes(pickle.dumps(Payload()))
    with pytest.raises(DiviewerError):
        NeuralGI(path)
    assert not flag.exists()


# --- the shipped model ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cornell_frames(gl_context):
    from diviewer.gl.renderer import Renderer
    from diviewer.scene import load_scene

    scene = load_scene("cornell")
    with gl_context:
        r = Renderer(gl_context, scene, 128, 128)
        try:
            out, configs = {}, {}
            for k in (0.0, 1e-8, 1.0, 8.0):
                lights = tuple(dataclasses.replace(l, irradiance=l.irradiance * k) for l in scene.default.lights)
                configs[k] = dataclasses.replace(scene.default, lights=lights)
                out[k] = pack_buffers(r.frame(configs[k]))
        finally:
            r.release()
    return scene, out, configs


def _run_shipped(net, cornell_frames, k, x=None):
    """The shipped model on the frame at light factor k (or ``x``, that frame's buffers altered), with the
    frame's light scale and camera where the model takes them (encodings 2 and 3), as the viewer runs it."""
    frame = cornell_frames[1][k] if x is None else x
    h, w = frame.shape[-3:-1]
    return net.run(frame, **net.frame_inputs(cornell_frames[2][k], w, h))


@pytest.fixture(scope="module")
def shipped(cornell_frames):
    from diviewer.paths import models_dir

    return NeuralGI(models_dir() / "cornell.onnx", scene=cornell_frames[0])


@pytest.mark.parametrize("channel", range(7), ids=CHANNEL_NAMES[:7])
@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf, 1e30])
def test_shipped_model_sanitises_bad_geometry_buffers(cornell_frames, shipped, channel, value):
    """The exported graph's encoding keeps NaN/Inf/1e30 in depth, normal and albedo out of the output."""
    x = cornell_frames[1][1.0].copy()
    x[10:14, 20:30, channel] = value
    y = _run_shipped(shipped, cornell_frames, 1.0, x)
    assert np.all(np.isfinite(y)) and np.all(y >= 0)
    assert shipped.nonfinite_inputs == (0 if value == 1e30 else 40)


@pytest.mark.parametrize("k", [0.0, 1e-8, 1.0, 8.0])
def test_shipped_model_output_is_finite_and_not_negative(cornell_frames, shipped, k):
    y = _run_shipped(shipped, cornell_frames, k)
    assert np.all(np.isfinite(y)) and np.all(y >= 0)


def test_shipped_model_is_darker_without_light(cornell_frames, shipped):
    dark, lit = (float(_run_shipped(shipped, cornell_frames, k).mean()) for k in (0.0, 1.0))
    assert dark < 0.25 * lit
    if shipped.light_scaled:  # linear in the light by construction: no light, no light out
        assert dark == 0.0 < lit


def test_a_light_scaled_model_is_black_at_zero_light_and_linear_in_it(cornell_frames, shipped):
    """Encodings 2 and up make the model linear in the light by construction: at zero light exactly black, at 8x
    the light exactly 8x the frame. The shipped cornell model (encoding 3), on GL frames of cornell, with the
    light scale and camera the viewer gives it."""
    assert shipped.light_scaled and int(shipped.meta["encoding"]["version"]) >= 2
    dark = _run_shipped(shipped, cornell_frames, 0.0)
    lit, bright = (_run_shipped(shipped, cornell_frames, k) for k in (1.0, 8.0))
    assert np.all(dark == 0.0)
    assert lit.mean() > 0 and np.all(np.isfinite(bright))
    np.testing.assert_allclose(bright, 8.0 * lit, rtol=1e-6, atol=0)


def test_count_of_opposite_infinities_warns_nothing():
    """+Inf and -Inf sum to NaN inside the count: both are counted, and numpy says nothing of the NaN it made."""
    import warnings

    x = buffers()[None]
    x[0, 0, 0, 0], x[0, 1, 0, 0] = np.inf, -np.inf
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert count_nonfinite(x) == 2
