"""Tests for diviewer.train.encoding_torch: the encoding on tensors matches numpy's and exports to ONNX."""

from __future__ import annotations

import io
import warnings

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from diviewer.contract import encoding as np_encoding  # noqa: E402
from diviewer.contract.encoding import INPUT_CHANNEL_COUNT, Encoding  # noqa: E402
from diviewer.train.encoding_torch import decode_radiance, encode_inputs, encode_radiance  # noqa: E402
from contract.test_encoding import random_frame  # noqa: E402  (the same random buffers as the numpy tests)

ENC = Encoding(exposure=0.25, depth_scale=50.0)


def _magnitudes(enc: Encoding, dtype: type) -> np.ndarray:
    """0, then exposed radiance from 1e-30 up to exactly radiance_max, both signs (unexposed units)."""
    t = np.concatenate([np.logspace(-30, np.log10(enc.radiance_max), 20001), [enc.radiance_max]])
    x = t / enc.exposure
    return np.concatenate([[0.0], x, -x]).astype(dtype)


def test_numpy_and_torch_agree() -> None:
    x = _magnitudes(ENC, np.float32)
    y_np = np_encoding.encode_radiance(x, ENC)
    y_t = encode_radiance(torch.from_numpy(x), ENC)
    assert isinstance(y_t, torch.Tensor) and y_t.dtype == torch.float32
    # numpy's and torch's log/exp may differ in the last bit.
    np.testing.assert_allclose(y_t.numpy(), y_np, rtol=1e-6, atol=1e-12)
    back_t = decode_radiance(y_t, ENC)
    np.testing.assert_allclose(back_t.numpy(), np_encoding.decode_radiance(y_np, ENC), rtol=4e-6, atol=0)


def test_encode_inputs_torch_nchw_matches_numpy_hwc() -> None:
    frames = [random_frame(np.random.default_rng(seed)) for seed in (3, 4)]
    hwc = np.stack([np_encoding.encode_inputs(*f, ENC, channel_axis=-1) for f in frames])
    depth, normal, albedo, direct = (
        torch.from_numpy(np.stack([f[i] for f in frames])) for i in range(4)
    )
    nchw = encode_inputs(
        depth[:, None], normal.permute(0, 3, 1, 2), albedo.permute(0, 3, 1, 2), direct.permute(0, 3, 1, 2),
        ENC, channel_axis=1,
    )
    assert tuple(nchw.shape) == (2, INPUT_CHANNEL_COUNT, 6, 5)
    np.testing.assert_allclose(nchw.permute(0, 2, 3, 1).numpy(), hwc, rtol=1e-6, atol=1e-7)


def test_onnx_export_matches_numpy() -> None:
    ort = pytest.importorskip("onnxruntime")
    enc = ENC

    class Wrap(torch.nn.Module):
        def forward(self, depth, normal, albedo, direct, y):  # type: ignore[no-untyped-def]
            return encode_inputs(depth, normal, albedo, direct, enc, channel_axis=1), decode_radiance(y, enc)

    depth, normal, albedo, direct = (np.ascontiguousarray(np.moveaxis(a.reshape(6, 5, -1), -1, 0)[None]) for a in random_frame(np.random.default_rng(6)))
    direct[0, 0, 1, :3] = [np.nan, np.inf, 1e-12]
    y = np.linspace(-1.2, 1.2, 3 * 6 * 5, dtype=np.float32).reshape(1, 3, 6, 5)
    y[0, 0, 0, :2] = [np.nan, 1e-9]
    arrays = (depth, normal, albedo, direct, y)
    names = ["depth", "normal", "albedo", "direct", "y"]
    f = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # The TorchScript exporter (no onnxscript needed); it lowers log1p to log(1 + x) and cannot
        # export expm1 at all, which is why the encoding builds both from Log/Exp/Where.
        torch.onnx.export(Wrap(), tuple(torch.from_numpy(a) for a in arrays), f, input_names=names, dynamo=False)
    session = ort.InferenceSession(f.getvalue(), providers=["CPUExecutionProvider"])
    x_onnx, back_onnx = session.run(None, dict(zip(names, arrays)))
    np.testing.assert_allclose(x_onnx, np_encoding.encode_inputs(depth, normal, albedo, direct, enc, channel_axis=1), rtol=1e-6, atol=1e-7)
    assert np.isfinite(back_onnx).all()
    np.testing.assert_allclose(back_onnx, np_encoding.decode_radiance(y, enc), rtol=4e-6, atol=0)


def test_half_precision_tensors_are_encoded_in_float32():
    enc = Encoding(exposure=1.0, depth_scale=10.0)
    x = torch.tensor([1e-4, 0.5, 300.0], dtype=torch.float16)
    y = encode_radiance(x, enc)
    assert y.dtype == torch.float32
    assert decode_radiance(y.half(), enc).dtype == torch.float32
