"""The linear-regression baseline: exact on data it can represent, the same in ONNX as in numpy, runs as a model."""

from __future__ import annotations

import json

import numpy as np
import pytest

from diviewer.evaluation.baseline import FEATURES, KIND, build_baseline, fit, predict
from diviewer.cli import main
from diviewer.data.capture import open_or_create
from diviewer.data.dataset import CHANNELS, FORMAT, FORMAT_VERSION, Dataset, write_frame
from diviewer.contract.runtime import NeuralGI, pack_buffers
from diviewer.scene import load_scene

pytest.importorskip("onnx")
N = len(FEATURES)


def quiet(*_):
    pass


def _weights(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.normal(0, 0.1, (N, 3)), rng.normal(0, 0.3, (N, 3))


def _frame(rng, h: int, w: int) -> dict[str, np.ndarray]:
    normal = rng.normal(size=(h, w, 3))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    return {"depth": rng.uniform(1.0, 5.0, (h, w)), "normal": normal, "albedo": rng.uniform(0.0, 1.0, (h, w, 3)),
            "direct": rng.uniform(0.0, 2.0, (h, w, 3))}


def synthetic_dataset(root, A, B, frames: int = 5, h: int = 16, w: int = 16, noise: float = 0.0,
                      direct_area: dict | None = None) -> Dataset:
    """A dataset whose ground truth is the baseline's own form (plus optional noise): the fit must find A, B.
    ``direct_area``: the manifest's record of a direct light over each pixel's area (`diviewer data area-direct`)."""
    scene = load_scene("cornell")
    manifest = {"format": FORMAT, "format_version": FORMAT_VERSION, "scene": "cornell", "scene_hash": scene.file_hash,
                "resolution": [w, h], "channels": [list(c) for c in CHANNELS], "dtype": "float32", "gt": "pt",
                "spp": 1, "max_depth": 2, "seed": 0, "frames": frames, "split_fractions": [1, 0, 0],
                "render_settings": {}, "frame_list": [{"index": i, "split": "train" if i < frames - 1 else "val",
                                                       "seed": i, "config": {"camera": {"far": 10.0}}}
                                                      for i in range(frames)]}
    if direct_area is not None:
        manifest["direct_area"] = direct_area
    ds = open_or_create(root, manifest)
    rng = np.random.default_rng(7)
    for i in range(frames):
        f = _frame(rng, h, w)
        pt = predict(A, B, f["depth"], f["normal"], f["albedo"], f["direct"], 10.0) + noise * rng.normal(size=(h, w, 3))
        arr = np.concatenate([f["depth"][..., None], f["normal"], f["albedo"], f["direct"], pt, f["direct"]], -1)
        write_frame(ds, i, arr.astype(np.float32), {"index": i})
    return Dataset(root)


def test_fit_recovers_weights_it_can_represent(tmp_path):
    A, B = _weights(0)
    ds = synthetic_dataset(tmp_path / "ds", A, B)
    r = fit(ds, log=quiet)
    assert r["frames"] == 4 and r["depth_scale"] == 10.0
    np.testing.assert_allclose(r["A"], A, atol=2e-5)  # the data are float32
    np.testing.assert_allclose(r["B"], B, atol=2e-5)
    assert r["train_rmse"] < 1e-4


def test_fit_is_least_squares_under_noise(tmp_path):
    A, B = _weights(1)
    ds = synthetic_dataset(tmp_path / "ds", A, B, frames=9, noise=0.05)
    r = fit(ds, log=quiet)
    assert r["train_rmse"] == pytest.approx(0.05, rel=0.1)  # what is left is the noise
    # the same solution as numpy's least squares on the stacked design matrix
    from diviewer.evaluation.baseline import features

    frames = [ds.load(i) for i in ds.indices("train")]
    for c in range(3):
        x = np.concatenate([np.concatenate([features(f["depth"], f["normal"], f["direct"], 10.0).reshape(-1, N),
                                            f["albedo"][..., c].reshape(-1, 1) * features(
                                                f["depth"], f["normal"], f["direct"], 10.0).reshape(-1, N)], 1)
                            for f in frames])
        y = np.concatenate([(f["pt"] - f["direct"])[..., c].reshape(-1) for f in frames])
        w = np.linalg.lstsq(x, y, rcond=None)[0]
        np.testing.assert_allclose(np.concatenate([r["A"][:, c], r["B"][:, c]]), w, atol=1e-6)


def test_onnx_model_matches_numpy_and_follows_the_runtime_contract(tmp_path):
    A, B = _weights(2)
    ds = synthetic_dataset(tmp_path / "ds", A, B)
    out = tmp_path / "lin.onnx"
    card = build_baseline(ds.root, out, log=quiet)
    assert card["kind"] == KIND and card["parameters"] == 2 * N * 3 <= 60
    net = NeuralGI(out, scene=load_scene("cornell"))  # the runtime's checks accept it
    assert net.meta["kind"] == KIND and "linear" in net.meta["description"]
    f = ds.load(ds.indices("val")[0])
    y = net.run(pack_buffers(f))
    expected = predict(np.array(card["weights"]["A"]), np.array(card["weights"]["B"]), f["depth"], f["normal"],
                       f["albedo"], f["direct"], 10.0)
    # the runtime clamps radiance at 0 (diviewer.contract.runtime); the synthetic truth may dip below it
    np.testing.assert_allclose(y, np.maximum(expected, 0.0), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(y, np.maximum(f["pt"], 0.0), atol=1e-3)  # and the truth, which this data lets it represent
    assert json.loads(out.with_suffix(".json").read_text())["fit"]["frames"] == 4
    assert card["direct_samples"] == net.direct_samples == 1  # fitted on the pixel centre's light
    batch = net.run(np.stack([pack_buffers(f)] * 2))  # any batch and size (multiple 1)
    assert batch.shape == (2, 16, 16, 3)


def test_cli_baseline_then_eval_on_a_dataset_split(tmp_path, capsys):
    A, B = _weights(3)
    ds = synthetic_dataset(tmp_path / "ds", A, B)
    out = tmp_path / "lin.onnx"
    assert main(["baseline", "--data", str(ds.root), "--out", str(out)]) == 0
    assert main(["eval", "--model", str(out), "--data", str(ds.root), "--split", "val"]) == 0
    assert "direct light only" in capsys.readouterr().out
    assert main(["baseline", "--data", str(tmp_path / "nowhere"), "--out", str(out)]) == 2


def test_a_baseline_fitted_on_the_areas_direct_light_asks_the_runtime_for_that_light(tmp_path):
    """A capture of the direct light over each pixel's area (4x4): the card says so, so eval, bench and the viewer
    feed it the light it was fitted on, not the pixel centre's."""
    A, B = _weights(4)
    ds = synthetic_dataset(tmp_path / "ds", A, B, direct_area={"samples": 4, "how": "test"})
    out = tmp_path / "lin.onnx"
    card = build_baseline(ds.root, out, log=quiet)
    assert card["direct_samples"] == 4 == NeuralGI(out).direct_samples
