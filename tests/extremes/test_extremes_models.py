"""Broken models are refused (issue 29 item 4): export of non-finite, negative-variance, dead or fp16-overflowing
checkpoints, and a runtime model whose graph yields NaN/Inf on a probe frame."""

from __future__ import annotations

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.contract.runtime import NeuralGI, probe_frame
from onnx_models import direct_times

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")

from diviewer.train.checks import FP16_MAX, FP16_TOLERANCE, check_outputs  # noqa: E402
from diviewer.train.checkpoint import load_checkpoint  # noqa: E402
from diviewer.train.export import ExportSettings, export  # noqa: E402
from diviewer.train.trainer import train  # noqa: E402
from train.test_trainer import make_dataset, quiet, tiny  # noqa: E402


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("models")
    make_dataset(root / "data")
    torch.set_num_threads(1)
    assert train(tiny(root / "data", root / "run"), log=quiet)
    return root / "run" / "best.ckpt"


def _edited(src, dst, edit):
    """A copy of checkpoint ``src`` with ``edit(netG state dict)`` applied."""
    ckpt = load_checkpoint(src)
    state = {k: v.clone() for k, v in ckpt["netG"].items()}
    edit(state)
    ckpt["netG"] = state
    torch.save(ckpt, dst)
    return dst


def _first(state, suffix):
    return next(k for k in state if k.endswith(suffix))


def _set_nan(state):
    state[_first(state, ".weight")].view(-1)[0] = float("nan")


def _set_inf(state):
    state[_first(state, ".bias")].view(-1)[-1] = float("inf")


def _negative_var(state):
    state[_first(state, "running_var")].view(-1)[0] = -0.5


def _dead(state):
    for k, v in state.items():  # every weight and bias zero: the output is tanh(0), the same everywhere
        if v.is_floating_point() and not k.endswith(("running_var", "running_mean")):
            v.zero_()


@pytest.mark.slow
@pytest.mark.parametrize("edit,words", [(_set_nan, "NaN/Inf"), (_set_inf, "NaN/Inf"),
                                        (_negative_var, "negative variance"), (_dead, "constant")])
def test_export_refuses_a_broken_checkpoint(trained, tmp_path, edit, words):
    ckpt = _edited(trained, tmp_path / "broken.ckpt", edit)
    out = tmp_path / "m.onnx"
    with pytest.raises(DiviewerError, match=words) as exc:
        export(ckpt, out, log=quiet)
    assert str(ckpt) in str(exc.value)
    assert not out.exists() and not out.with_suffix(".json").exists(), "nothing written"


@pytest.mark.slow
def test_fp16_export_refuses_weights_beyond_float16(trained, tmp_path):
    def huge(state):
        state[_first(state, ".weight")].view(-1)[0] = 2 * FP16_MAX
    ckpt = _edited(trained, tmp_path / "huge.ckpt", huge)
    with pytest.raises(DiviewerError, match="float16") as exc:
        export(ckpt, tmp_path / "m16.onnx", ExportSettings(fp16=True), log=quiet)
    assert "--fp16" in str(exc.value) and "export without them" in str(exc.value)
    assert not (tmp_path / "m16.onnx").exists()


@pytest.mark.slow
def test_sound_exports_state_their_tolerance(trained, tmp_path):
    card32 = export(trained, tmp_path / "a.onnx", log=quiet)
    card16 = export(trained, tmp_path / "b.onnx", ExportSettings(fp16=True), log=quiet)
    assert card32["verification"]["tolerance_rel_to_peak"] == 1e-4
    assert card16["verification"]["tolerance_rel_to_peak"] == FP16_TOLERANCE
    assert card16["verification"]["max_rel_to_peak"] <= FP16_TOLERANCE
    assert np.isfinite(card16["verification"]["psnr_db"]), "a sound model's verification is a finite PSNR"
    NeuralGI(tmp_path / "b.onnx")  # passes the runtime's probe


def test_constant_or_non_finite_outputs_are_refused(tmp_path):
    ok = np.random.default_rng(0).uniform(0, 1, (2, 8, 8, 3))
    check_outputs(ok, ok, 2, tmp_path / "c.ckpt")
    for net, words in [(np.zeros((2, 8, 8, 3)), "constant"), (np.full((2, 8, 8, 3), 0.7), "constant"),
                       (np.where(ok > 0.5, np.nan, ok), "NaN/Inf")]:
        with pytest.raises(DiviewerError, match=words):
            check_outputs(net, ok, 2, tmp_path / "c.ckpt")
    with pytest.raises(DiviewerError, match="radiance has"):
        check_outputs(ok, np.full_like(ok, np.inf), 2, tmp_path / "c.ckpt")


@pytest.mark.parametrize("factor", [float("nan"), float("inf"), -float("inf")])
def test_runtime_refuses_a_graph_that_yields_non_finite_on_the_probe(tmp_path, factor):
    path = direct_times(tmp_path / "bad.onnx", factor=factor)
    with pytest.raises(DiviewerError, match="probe frame") as exc:
        NeuralGI(path)
    assert str(path) in str(exc.value)


def test_probe_frame_is_plausible():
    f = probe_frame(16, 32)
    assert f.shape == (1, 16, 32, 10) and np.all(np.isfinite(f))
    np.testing.assert_allclose(np.linalg.norm(f[..., 1:4], axis=-1), 1.0, rtol=1e-5)
    assert f[..., 7:10].max() > 0.1, "the probe lights the frame, so a graph scaling direct light shows its NaN"
