"""ONNX export: parity with PyTorch (fp32, fp16), metadata, determinism, refusals, the runtime."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")

from diviewer.cli import main  # noqa: E402
from diviewer.errors import DiviewerError  # noqa: E402
from diviewer.runtime import NeuralGI, read_metadata  # noqa: E402
from diviewer.train.export import ExportSettings, export, gi_module, info  # noqa: E402
from diviewer.train.checkpoint import build_generator_from_checkpoint  # noqa: E402
from diviewer.train.trainer import train  # noqa: E402
from test_train import make_dataset, quiet, tiny  # noqa: E402


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory):
    root = tmp_path_factory.mktemp("export")
    make_dataset(root / "data")
    full = train(tiny(root / "data", root / "full"), log=quiet)
    indirect = train(tiny(root / "data", root / "indirect", target="indirect"), log=quiet)
    assert full and indirect
    return {"full": root / "full" / "best.ckpt", "indirect": root / "indirect" / "best.ckpt", "data": root / "data"}


@pytest.mark.parametrize("target", ["full", "indirect"])
def test_fp32_export_matches_torch_and_carries_metadata(checkpoints, tmp_path, target):
    out = tmp_path / f"{target}.onnx"
    card = export(checkpoints[target], out, log=quiet)
    assert card["verification"]["max_rel_to_peak"] <= 1e-4
    assert "frames of" in card["verification"]["frames"], "verified on real dataset frames"
    meta = read_metadata(out)
    for key in ("scene", "scene_hash", "dataset_hash", "K", "levels", "target", "encoding", "resolution",
                "channels", "epochs", "validation", "exported_with"):
        assert key in meta, key
    assert meta["target"] == target and meta["precision"] == "fp32"
    assert json.loads(out.with_suffix(".json").read_text()) == meta
    # the recipe: how to capture and train it again (tools/build_shipped_model.py reads it)
    recipe = meta["recipe"]
    assert recipe["capture"]["spp"] == 4 and recipe["capture"]["frames"] == 10
    assert recipe["train"]["K"] == 4 and recipe["train"]["target"] == target and "device" not in recipe["train"]
    assert recipe["net"]["K"] == 4
    # the runtime's output equals the torch module's on new buffers, at the trained size and larger
    netG, enc, m = build_generator_from_checkpoint(checkpoints[target])
    module = gi_module(netG, enc, m)
    model = NeuralGI(out)
    rng = np.random.default_rng(1)
    for h, w in [(32, 32), (64, 96)]:
        x = np.concatenate([rng.uniform(1, 5, (1, h, w, 1)), rng.uniform(-1, 1, (1, h, w, 3)),
                            rng.uniform(0, 1, (1, h, w, 3)), rng.uniform(0, 3, (1, h, w, 3))], -1).astype(np.float32)
        with torch.no_grad():
            ref = module(torch.from_numpy(x)).numpy()
        got = model.run(x)
        assert got.shape == (1, h, w, 3)
        np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-5 * np.abs(ref).max())


def test_indirect_model_adds_the_exact_direct_light(checkpoints, tmp_path):
    """With the indirect target the graph returns the input's direct light + netG's decoded indirect."""
    from diviewer.train.encoding_torch import decode_radiance, encode_inputs

    out = tmp_path / "i.onnx"
    export(checkpoints["indirect"], out, log=quiet)
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(1, 5, (1, 32, 32, 1)), rng.uniform(-1, 1, (1, 32, 32, 3)),
                        rng.uniform(0, 1, (1, 32, 32, 3)), rng.uniform(0, 3, (1, 32, 32, 3))], -1).astype(np.float32)
    y = NeuralGI(out).run(x)
    netG, enc, meta = build_generator_from_checkpoint(checkpoints["indirect"])
    t = torch.from_numpy(x).permute(0, 3, 1, 2)
    with torch.no_grad():
        indirect = decode_radiance(netG(encode_inputs(t[:, 0:1], t[:, 1:4], t[:, 4:7], t[:, 7:10], enc, channel_axis=1)),
                                   enc).permute(0, 2, 3, 1).numpy()
    np.testing.assert_allclose(y, x[..., 7:10] + indirect, rtol=1e-4, atol=1e-6)


def test_fp16_export_is_finite_and_close(checkpoints, tmp_path):
    out = tmp_path / "h.onnx"
    card = export(checkpoints["full"], out, ExportSettings(fp16=True), log=quiet)
    v = card["verification"]
    assert card["precision"] == "fp16" and v["onnx_finite"]
    assert v["psnr_db"] > 30.0, v  # measured ~50 dB on the tiny model; fp16 must not be far off
    fp32 = tmp_path / "f.onnx"
    export(checkpoints["full"], fp32, log=quiet)
    assert out.stat().st_size < 0.75 * fp32.stat().st_size, "fp16 weights take about half the space"
    # very bright and very dark inputs (12 orders of magnitude) stay finite in fp16
    x = np.zeros((1, 32, 32, 10), np.float32)
    x[..., 0], x[..., 3], x[..., 4:7] = 2.0, 1.0, 0.5
    for scale in (1e-6, 1.0, 1e6):
        x[..., 7:10] = scale
        assert np.all(np.isfinite(NeuralGI(out).run(x)))


def test_export_twice_is_byte_identical(checkpoints, tmp_path):
    a, b = tmp_path / "a.onnx", tmp_path / "b.onnx"
    export(checkpoints["full"], a, log=quiet)
    export(checkpoints["full"], b, log=quiet)
    assert a.read_bytes() == b.read_bytes()


def test_cli_export_and_info(checkpoints, tmp_path, capsys):
    out = tmp_path / "m.onnx"
    assert main(["export", str(checkpoints["full"]), "--out", str(out)]) == 0
    assert main(["export", "--info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "K=4" in text and "synthetic" in text and "multiples of" in text
    assert info(out).splitlines()[0] == str(out)


def test_bad_checkpoint_is_refused(tmp_path, capsys):
    bad = tmp_path / "x.ckpt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(DiviewerError, match=str(bad)):
        export(bad, tmp_path / "x.onnx", log=quiet)
    assert main(["export", str(bad), "--out", str(tmp_path / "y.onnx")]) == 2
    assert not (tmp_path / "y.onnx").exists()


def test_eval_of_the_exported_model_reproduces_training_validation(checkpoints, tmp_path):
    """`diviewer eval` (onnxruntime, torch-free) scores the val split as training's validation did."""
    from diviewer.evaluate import evaluate
    from diviewer.train.checkpoint import load_checkpoint

    out = tmp_path / "m.onnx"
    export(checkpoints["indirect"], out, log=quiet)
    result = evaluate(out, checkpoints["data"], split="val", out=tmp_path / "eval.json", log=quiet)
    recorded = load_checkpoint(checkpoints["indirect"])["val"]
    for key in ("psnr", "ssim", "psnr_tm", "ssim_tm"):
        assert result["methods"]["neural"][key]["mean"] == pytest.approx(recorded[key], rel=1e-3), key
    assert set(result["methods"]) == {"neural", "direct"}
    assert json.loads((tmp_path / "eval.json").read_text())["frames"] == 2
    assert main(["eval", "--model", str(out), "--data", str(checkpoints["data"]), "--split", "val"]) == 0
