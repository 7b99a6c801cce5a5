"""ONNX export: parity with PyTorch (fp32, fp16), metadata, determinism, refusals, the runtime."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")

from diviewer.cli import main  # noqa: E402
from diviewer.errors import DiviewerError  # noqa: E402
from diviewer.contract.runtime import NeuralGI, read_metadata  # noqa: E402
from diviewer.train.export import INT8_WEIGHTS_TOLERANCE, ExportSettings, export, gi_module, info  # noqa: E402
from diviewer.train.checkpoint import build_generator_from_checkpoint  # noqa: E402
from diviewer.train.trainer import train  # noqa: E402
from train.test_trainer import make_dataset, quiet, tiny  # noqa: E402


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory):
    root = tmp_path_factory.mktemp("export")
    make_dataset(root / "data")
    # one model of each encoding: full radiance as is (1), indirect divided by the light scale (2)
    full = train(tiny(root / "data", root / "full", light_scale=False), log=quiet)
    indirect = train(tiny(root / "data", root / "indirect", target="indirect"), log=quiet)
    assert full and indirect
    return {"full": root / "full" / "best.ckpt", "indirect": root / "indirect" / "best.ckpt", "data": root / "data"}


@pytest.mark.slow
@pytest.mark.parametrize("target", ["full", "indirect"])
def test_fp32_export_matches_torch_and_carries_metadata(checkpoints, tmp_path, target):
    out = tmp_path / f"{target}.onnx"
    card = export(checkpoints[target], out, log=quiet)
    v = card["verification"]
    assert v["max_rel_to_peak"] <= 1e-4 and v["extremes_same_nonfinite"] and v["extremes_max_rel_to_peak"] <= 1e-4
    assert "frames of" in v["frames"], "verified on real dataset frames"
    if target == "indirect":  # encoding 2: checked black at zero light, linear in the light
        assert v["zero_light_max"] == 0.0 and v["twice_light_max_rel_to_peak"] <= 1e-6
    meta = read_metadata(out)
    for key in ("scene", "scene_hash", "dataset_hash", "K", "levels", "target", "encoding", "resolution",
                "channels", "epochs", "validation", "exported_with"):
        assert key in meta, key
    assert meta["target"] == target and meta["precision"] == "fp32"
    assert json.loads(out.with_suffix(".json").read_text()) == meta
    # the recipe: how to capture and train it again (diviewer build's recipe files hold the same)
    recipe = meta["recipe"]
    assert recipe["capture"]["spp"] == 4 and recipe["capture"]["frames"] == 10
    assert recipe["train"]["K"] == 4 and recipe["train"]["target"] == target and "device" not in recipe["train"]
    assert recipe["net"]["K"] == 4
    # the hardware it trained on: the tiny runs train on the CPU in float32
    assert meta["trained_on"]["device"] == "cpu" and meta["trained_on"]["autocast"] == "fp32"
    assert meta["trained_on"]["torch_threads"] >= 1 and "before" not in meta["trained_on"]
    # the runtime's output equals the torch module's on new buffers, at the trained size and larger
    netG, enc, m = build_generator_from_checkpoint(checkpoints[target])
    assert meta["encoding"]["version"] == (2 if target == "indirect" else 1) == enc.version
    module = gi_module(netG, enc, m, lean=False)  # training's own functions
    model = NeuralGI(out)
    assert model.light_scaled == enc.light_scaled
    s = np.array([1.7], np.float32) if enc.light_scaled else None
    rng = np.random.default_rng(1)
    for h, w in [(32, 32), (64, 96)]:
        x = np.concatenate([rng.uniform(1, 5, (1, h, w, 1)), rng.uniform(-1, 1, (1, h, w, 3)),
                            rng.uniform(0, 1, (1, h, w, 3)), rng.uniform(0, 3, (1, h, w, 3))], -1).astype(np.float32)
        with torch.no_grad():
            ref = module(torch.from_numpy(x), None if s is None else torch.from_numpy(s)).numpy()
        got = model.run(x, light_scale=s)
        assert got.shape == (1, h, w, 3)
        np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-5 * np.abs(ref).max())


@pytest.mark.slow
def test_indirect_model_adds_the_exact_direct_light(checkpoints, tmp_path):
    """With the indirect target the graph returns the input's direct light + netG's decoded indirect."""
    from diviewer.train.encoding_torch import decode_radiance, encode_inputs

    out = tmp_path / "i.onnx"
    export(checkpoints["indirect"], out, log=quiet)
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(1, 5, (1, 32, 32, 1)), rng.uniform(-1, 1, (1, 32, 32, 3)),
                        rng.uniform(0, 1, (1, 32, 32, 3)), rng.uniform(0, 3, (1, 32, 32, 3))], -1).astype(np.float32)
    y = NeuralGI(out).run(x, light_scale=1.0)  # encoding 2 at light scale 1: no scaling
    netG, enc, meta = build_generator_from_checkpoint(checkpoints["indirect"])
    t = torch.from_numpy(x).permute(0, 3, 1, 2)
    with torch.no_grad():
        indirect = decode_radiance(netG(encode_inputs(t[:, 0:1], t[:, 1:4], t[:, 4:7], t[:, 7:10], enc, channel_axis=1)),
                                   enc).permute(0, 2, 3, 1).numpy()
    # radiance is clamped at 0 (in the graph and the runtime): an undershooting indirect never darkens below black
    np.testing.assert_allclose(y, np.maximum(x[..., 7:10] + indirect, 0.0), rtol=1e-4, atol=1e-6)


@pytest.mark.slow
def test_fp16_export_is_finite_and_close(checkpoints, tmp_path):
    out = tmp_path / "h.onnx"
    card = export(checkpoints["full"], out, ExportSettings(fp16=True), log=quiet)
    v = card["verification"]
    assert card["precision"] == "fp16" and v["onnx_finite"]
    # Measured 81.5 dB (max error 5.6e-4 of peak) on this tiny model: fp16 ONNX against the fp16 torch
    # module. ~10 dB of margin for other CPUs and onnxruntime builds, no more: a real mismatch is far below.
    assert v["psnr_db"] > 70.0 and v["max_rel_to_peak"] < 5e-3, v
    fp32 = tmp_path / "f.onnx"
    export(checkpoints["full"], fp32, log=quiet)
    assert out.stat().st_size < 0.75 * fp32.stat().st_size, "fp16 weights take about half the space"
    # very bright and very dark inputs (12 orders of magnitude) stay finite in fp16
    x = np.zeros((1, 32, 32, 10), np.float32)
    x[..., 0], x[..., 3], x[..., 4:7] = 2.0, 1.0, 0.5
    for scale in (1e-6, 1.0, 1e6):
        x[..., 7:10] = scale
        assert np.all(np.isfinite(NeuralGI(out).run(x)))


@pytest.mark.slow
def test_half_weights_store_float16_and_run_float32_as_close_as_the_float32_file(checkpoints, tmp_path):
    """--half-weights: the file holds float16 weight tensors (half the bytes), every one cast back to float32 as
    onnxruntime loads it, so the graph's arithmetic is float32 and the output is the float32 file's to within
    the weights' rounding; an fp16 export with half weights is refused."""
    import onnx
    from onnx import TensorProto

    fp32, half = tmp_path / "f.onnx", tmp_path / "h.onnx"
    export(checkpoints["indirect"], fp32, log=quiet)
    card = export(checkpoints["indirect"], half, ExportSettings(half_weights=True), log=quiet)
    assert card["precision"] == "fp32" and card["weights"] == "fp16"
    assert json.loads(fp32.with_suffix(".json").read_text())["weights"] == "fp32"
    assert half.stat().st_size < 0.6 * fp32.stat().st_size, "the weights are most of the file: about half"
    graph = onnx.load(str(half)).graph
    big = [i for i in graph.initializer if np.prod(i.dims) >= 64]
    assert big and all(i.data_type == TensorProto.FLOAT16 for i in big)
    casts = {n.input[0] for n in graph.node if n.op_type == "Cast"}
    assert {i.name for i in big} <= casts, "each float16 weight is cast back to float32 in the graph"
    v = card["verification"]
    assert v["max_rel_to_peak"] <= v["tolerance_rel_to_peak"] and v["psnr_db"] > 70.0, v
    assert v["zero_light_max"] == 0.0, "linear in the light as the float32 file is"
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.uniform(1, 5, (1, 32, 48, 1)), rng.uniform(-1, 1, (1, 32, 48, 3)),
                        rng.uniform(0, 1, (1, 32, 48, 3)), rng.uniform(0, 3, (1, 32, 48, 3))], -1).astype(np.float32)
    a, b = NeuralGI(fp32).run(x, light_scale=1.3), NeuralGI(half).run(x, light_scale=1.3)
    assert b.dtype == np.float32 and np.abs(b - a).max() <= 1e-2 * np.abs(a).max()
    assert not np.array_equal(a, b), "the weights were rounded: not the float32 file by another name"
    with pytest.raises(DiviewerError, match="half_weights"):
        export(checkpoints["indirect"], tmp_path / "x.onnx", ExportSettings(fp16=True, half_weights=True), log=quiet)


@pytest.mark.slow
def test_int8_weights_store_the_inner_convolutions_as_int8_verified_and_run_float32(checkpoints, tmp_path):
    """--int8-weights: the inner convolutions' weights are int8 in the file (the ends float16), verified as written
    against PyTorch within INT8_WEIGHTS_TOLERANCE, run in float32, close to the float32 file; the card says so; not
    with --fp16 or --half-weights."""
    import onnx
    from onnx import TensorProto

    fp32, q = tmp_path / "f.onnx", tmp_path / "q.onnx"
    export(checkpoints["indirect"], fp32, log=quiet)
    card = export(checkpoints["indirect"], q, ExportSettings(int8_weights=True), log=quiet)
    assert card["precision"] == "fp32" and card["weights"] == "int8"
    assert "weights stored int8" in info(q)
    graph = onnx.load(str(q)).graph
    assert sum(i.data_type == TensorProto.INT8 for i in graph.initializer) > 0
    assert q.stat().st_size < fp32.stat().st_size
    v = card["verification"]
    assert v["tolerance_rel_to_peak"] == INT8_WEIGHTS_TOLERANCE and v["max_rel_to_peak"] <= INT8_WEIGHTS_TOLERANCE, v
    assert v["zero_light_max"] == 0.0, "linear in the light as the float32 file is"
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.uniform(1, 5, (1, 32, 48, 1)), rng.uniform(-1, 1, (1, 32, 48, 3)),
                        rng.uniform(0, 1, (1, 32, 48, 3)), rng.uniform(0, 3, (1, 32, 48, 3))], -1).astype(np.float32)
    a, b = NeuralGI(fp32).run(x, light_scale=1.3), NeuralGI(q).run(x, light_scale=1.3)
    assert b.dtype == np.float32 and np.abs(b - a).max() <= INT8_WEIGHTS_TOLERANCE * np.abs(a).max()
    assert not np.array_equal(a, b)
    with pytest.raises(DiviewerError, match="int8_weights"):
        ExportSettings(int8_weights=True, half_weights=True)
    with pytest.raises(DiviewerError, match="int8_weights"):
        ExportSettings(int8_weights=True, fp16=True)


@pytest.mark.slow
def test_export_twice_is_byte_identical(checkpoints, tmp_path):
    a, b = tmp_path / "a.onnx", tmp_path / "b.onnx"
    export(checkpoints["full"], a, log=quiet)
    export(checkpoints["full"], b, log=quiet)
    assert a.read_bytes() == b.read_bytes()


@pytest.mark.slow
def test_cli_export_and_info(checkpoints, tmp_path, capsys):
    out = tmp_path / "m.onnx"
    assert main(["export", str(checkpoints["full"]), "--out", str(out)]) == 0
    assert main(["export", "--info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "K=4" in text and "synthetic" in text and "multiples of" in text
    assert "trained on   cpu" in text and "fp32" in text
    assert info(out).splitlines()[0] == str(out)
    assert "columns a side" not in text  # whole frames, no aspect crops: no column guard


def test_info_names_the_column_guard_of_a_model_trained_on_aspect_crops():
    from diviewer.contract.padding import EDGE_GUARD
    from diviewer.paths import models_dir

    assert f"padded to multiples of 128 with {EDGE_GUARD} columns a side at least" in info(models_dir() / "sponza.onnx")


def test_bad_checkpoint_is_refused(tmp_path, capsys):
    bad = tmp_path / "x.ckpt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(DiviewerError, match=str(bad)):
        export(bad, tmp_path / "x.onnx", log=quiet)
    assert main(["export", str(bad), "--out", str(tmp_path / "y.onnx")]) == 2
    assert not (tmp_path / "y.onnx").exists()


@pytest.mark.slow
def test_eval_of_the_exported_model_reproduces_training_validation(checkpoints, tmp_path, monkeypatch):
    """`diviewer eval` (onnxruntime, torch-free) scores the val split as training's validation did, where it
    tone-maps as training does: without the scene's shipped evaluation set, whose exposure it would take."""
    from diviewer.evaluation.evaluate import evaluate
    from diviewer.train.checkpoint import load_checkpoint

    monkeypatch.setattr("diviewer.evaluation.frames.DEFAULT_EVALSETS", tmp_path / "no_evalsets")

    out = tmp_path / "m.onnx"
    export(checkpoints["indirect"], out, log=quiet)
    result = evaluate(out, checkpoints["data"], split="val", out=tmp_path / "eval.json", log=quiet)
    recorded = load_checkpoint(checkpoints["indirect"])["val"]
    for key in ("psnr", "ssim", "psnr_tm", "ssim_tm"):
        assert result["methods"]["neural"][key]["mean"] == pytest.approx(recorded[key], rel=1e-3), key
    assert set(result["methods"]) == {"neural", "direct"}
    assert json.loads((tmp_path / "eval.json").read_text())["frames"] == 2
    assert main(["eval", "--model", str(out), "--data", str(checkpoints["data"]), "--split", "val"]) == 0


# ---------------------------------------------------------------------------------------------
# Ablation options: every decoder upsampling and normalisation exports and matches PyTorch


def _buffers(rng, n: int, h: int, w: int) -> np.ndarray:
    return np.concatenate([rng.uniform(1, 5, (n, h, w, 1)), rng.uniform(-1, 1, (n, h, w, 3)),
                           rng.uniform(0, 1, (n, h, w, 3)), rng.uniform(0, 3, (n, h, w, 3))], -1).astype(np.float32)


@pytest.mark.slow
@pytest.mark.parametrize("upsample", ["transpose", "resize", "shuffle"])
@pytest.mark.parametrize("norm", ["batch", "instance", "none"])
def test_each_option_exports_and_matches_torch(upsample, norm):
    """Build, train one step, export (legacy exporter, opset 17): onnxruntime equals PyTorch to 1e-4 of
    peak for the full target and for indirect / albedo, whose composition the graph must carry."""
    import onnxruntime as ort

    from diviewer.contract.encoding import Encoding
    from diviewer.train.encoding_torch import decode_radiance, encode_inputs
    from diviewer.train.export import OPSET, onnx_bytes
    from diviewer.train.losses import reconstruction_loss
    from diviewer.train.networks import NetConfig, init_weights
    from diviewer.train.targets import ALBEDO_FLOOR

    torch.manual_seed(0)
    netG = init_weights(NetConfig(K=4, resolution=32, upsample=upsample, norm=norm).build_generator())
    enc = Encoding(exposure=2.0, depth_scale=10.0)
    rng = np.random.default_rng(5)
    train_x = torch.from_numpy(_buffers(rng, 2, 32, 32)).permute(0, 3, 1, 2)
    real_A = encode_inputs(train_x[:, 0:1], train_x[:, 1:4], train_x[:, 4:7], train_x[:, 7:10], enc, channel_axis=1)
    opt = torch.optim.Adam(netG.parameters(), lr=1e-3)
    loss = reconstruction_loss(netG.train()(real_A), torch.rand(2, 3, 32, 32) - 0.5)
    opt.zero_grad()
    loss.backward()
    opt.step()  # weights and batch-norm statistics off their initial values
    netG.eval()

    frames = _buffers(rng, 2, 32, 32)
    wide = _buffers(rng, 1, 64, 96)  # dynamic size: larger and non-square
    for target, divide_albedo in (("full", False), ("indirect", True)):
        module = gi_module(netG, enc, {"target": target, "divide_albedo": divide_albedo})
        session = ort.InferenceSession(onnx_bytes(module, torch.from_numpy(frames[:1])),
                                       providers=["CPUExecutionProvider"])
        for x in (frames, wide):
            with torch.no_grad():
                ref = module(torch.from_numpy(x)).numpy()
            got = session.run(None, {"buffers": x})[0]
            assert got.shape == x.shape[:3] + (3,)
            assert np.abs(got - ref).max() <= 1e-4 * np.abs(ref).max(), (upsample, norm, target, OPSET)
        if divide_albedo:
            # the graph multiplies netG's decoded irradiance by the albedo (floored) and adds direct
            t = torch.from_numpy(frames).permute(0, 3, 1, 2)
            with torch.no_grad():
                irradiance = decode_radiance(netG(encode_inputs(t[:, 0:1], t[:, 1:4], t[:, 4:7], t[:, 7:10], enc,
                                                                channel_axis=1)), enc)
            # ... and clamps at 0: radiance is never negative
            expected = (t[:, 7:10] + irradiance * t[:, 4:7].clamp(min=ALBEDO_FLOOR)).clamp(min=0.0)
            expected = expected.permute(0, 2, 3, 1).numpy()
            got = session.run(None, {"buffers": frames})[0]
            np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-5 * np.abs(expected).max())


def _rewrite_checkpoint(src, dst, upsample=None, norm=None, drop_options=False, divide_albedo=None):
    """A copy of a trained checkpoint whose generator is rebuilt with other options (or whose records
    lack the option keys, as checkpoints written before they existed do)."""
    from diviewer.train.networks import UnetGenerator, init_weights
    from diviewer.train.checkpoint import load_checkpoint

    ckpt = load_checkpoint(src)
    args = dict(ckpt["model_args"])
    if drop_options:
        ckpt.pop("trained_on", None)
        for key in ("upsample", "norm"):
            args.pop(key, None)
            ckpt["net_config"].pop(key, None)
        ckpt["net_config"].pop("norm_D", None)
    else:
        args.update(upsample=upsample, norm=norm)
        ckpt["net_config"].update(upsample=upsample, norm=norm)
        torch.manual_seed(1)
        netG = init_weights(UnetGenerator(**args))
        netG.train()(torch.randn(2, netG.in_channels, 32, 32))  # batch-norm statistics off their start
        ckpt["netG"] = netG.state_dict()
    if divide_albedo is not None:
        ckpt["config"]["divide_albedo"] = divide_albedo
    ckpt["model_args"] = args
    torch.save(ckpt, dst)
    return dst


@pytest.mark.slow
@pytest.mark.parametrize(("upsample", "norm"), [("resize", "instance"), ("shuffle", "none")])
def test_export_of_a_checkpoint_with_options(checkpoints, tmp_path, upsample, norm):
    ckpt = _rewrite_checkpoint(checkpoints["indirect"], tmp_path / "o.ckpt", upsample, norm, divide_albedo=True)
    out = tmp_path / "o.onnx"
    card = export(ckpt, out, log=quiet)
    assert card["verification"]["max_rel_to_peak"] <= 1e-4
    assert (card["upsample"], card["norm"], card["divide_albedo"]) == (upsample, norm, True)
    assert f"upsample={upsample} norm={norm}" in info(out)
    netG, enc, meta = build_generator_from_checkpoint(ckpt)
    x = np.random.default_rng(2).uniform(0.1, 2, (1, 64, 32, 10)).astype(np.float32)
    with torch.no_grad():
        ref = gi_module(netG, enc, meta, lean=False)(torch.from_numpy(x), torch.tensor([0.8])).numpy()
    np.testing.assert_allclose(NeuralGI(out).run(x, light_scale=0.8), ref, rtol=1e-4, atol=1e-5 * np.abs(ref).max())


@pytest.mark.slow
def test_checkpoint_from_before_the_options_exports_the_same_graph(checkpoints, tmp_path):
    import onnx

    old = _rewrite_checkpoint(checkpoints["full"], tmp_path / "old.ckpt", drop_options=True)
    a, b = tmp_path / "new.onnx", tmp_path / "old.onnx"
    export(checkpoints["full"], a, log=quiet)
    card = export(old, b, log=quiet)
    assert (card["upsample"], card["norm"]) == ("transpose", "batch")
    assert card["trained_on"] == {"device": "cpu", "autocast": "fp32", "recorded": False}  # from --device cpu
    assert onnx.load(str(a)).graph.SerializeToString() == onnx.load(str(b)).graph.SerializeToString()


# ---------------------------------------------------------------------------------------------
# Encoding 2 (linear in the light), the lean graph, any frame size


def _frame_of(rng, h=32, w=32):
    return _buffers(rng, 1, h, w)


def test_export_speaks_plainly_and_raises_no_library_warnings(checkpoints, tmp_path):
    """The user sees the verification in words (one line, the light checks in it) and no torch warnings."""
    import warnings

    lines = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        export(checkpoints["indirect"], tmp_path / "w.onnx", ExportSettings(), log=lines.append)
    assert [str(w.message)[:80] for w in caught] == []
    verified = [line for line in lines if line.startswith("verified the fp32 model against PyTorch")]
    assert len(verified) == 1
    assert "no light gives black, twice the light twice the image" in verified[0]
    assert not any("zero light max" in line for line in lines)


@pytest.mark.parametrize("fp16", [False, True])
def test_encoding_2_is_black_without_light_and_linear_in_it(checkpoints, tmp_path, fp16):
    """In onnxruntime: zero light (no direct light, light scale 0) gives exactly 0; twice the light (direct x 2,
    light scale x 2) gives exactly twice the output, in the fp16 export too (the network sees the same input)."""
    out = tmp_path / "lin.onnx"
    export(checkpoints["indirect"], out, ExportSettings(fp16=fp16), log=quiet)
    model = NeuralGI(out)
    x = _frame_of(np.random.default_rng(11))
    dark = x.copy()
    dark[..., 7:10] = 0.0
    assert np.all(model.run(dark, light_scale=0.0) == 0.0)
    once = model.run(x, light_scale=1.3)
    bright = x.copy()
    bright[..., 7:10] *= 2.0
    twice = model.run(bright, light_scale=2.6)
    assert once.max() > 0 and np.array_equal(twice, 2.0 * once)
    with pytest.raises(ValueError, match="light scale"):
        model.run(x)  # an encoding-2 model needs it


def test_lean_graph_equals_training_functions_on_broken_buffers(checkpoints):
    """NaN, +-Inf, +-1e30, 0 and 1e-30 in every channel: the lean graph (If-guarded NaN handling, no Where, Sign
    or per-pixel transpose in the common path) gives what training's encode/decode/compose give."""
    import onnxruntime as ort

    from diviewer.train.checks import extreme_frame
    from diviewer.train.export import onnx_bytes

    netG, enc, meta = build_generator_from_checkpoint(checkpoints["indirect"])
    lean, ref = gi_module(netG, enc, meta), gi_module(netG, enc, meta, lean=False)
    x = extreme_frame(_frame_of(np.random.default_rng(4))[0])[None]
    s = torch.tensor([1.5])
    session = ort.InferenceSession(onnx_bytes(lean, torch.from_numpy(x), s), providers=["CPUExecutionProvider"])
    got = session.run(None, {"buffers": x, "light_scale": s.numpy()})[0]
    with torch.no_grad():
        want = ref(torch.from_numpy(x), s).numpy()
    np.testing.assert_array_equal(np.isfinite(got), np.isfinite(want))
    ok = np.isfinite(want)
    assert np.abs(got[ok] - want[ok]).max() <= 1e-5 * np.abs(want[ok]).max()
    clean = _frame_of(np.random.default_rng(5))
    got = session.run(None, {"buffers": clean, "light_scale": s.numpy()})[0]
    with torch.no_grad():
        want = ref(torch.from_numpy(clean), s).numpy()
    assert np.abs(got - want).max() <= 1e-5 * np.abs(want).max()
    import onnx

    nodes = onnx.load_from_string(onnx_bytes(lean, torch.from_numpy(clean), s)).graph.node
    # the slow ones run only inside the If's rare branch; the one Where of the main graph is 1/s on (N,) scales
    assert "Sign" not in {n.op_type for n in nodes} and sum(n.op_type == "Where" for n in nodes) == 1
    assert "If" in {n.op_type for n in nodes}


def test_nchw_export_and_any_frame_size(checkpoints, tmp_path):
    """An NCHW export runs through the runtime like the NHWC one; any H x W is padded to the stride (as
    training pads, diviewer.contract.padding) and cropped back."""
    from diviewer.contract.padding import crop_nhwc, pad_nhwc

    a, b = tmp_path / "nhwc.onnx", tmp_path / "nchw.onnx"
    export(checkpoints["full"], a, log=quiet)
    card = export(checkpoints["full"], b, ExportSettings(layout="NCHW"), log=quiet)
    assert card["layout"] == "NCHW" and card["multiple"] == 32
    ma, mb = NeuralGI(a), NeuralGI(b)
    netG, enc, meta = build_generator_from_checkpoint(checkpoints["full"])
    ref = gi_module(netG, enc, meta, lean=False)
    rng = np.random.default_rng(8)
    for h, w in [(32, 32), (20, 45), (37, 16)]:
        x = _frame_of(rng, h, w)
        ya, yb = ma.run(x), mb.run(x)
        assert ya.shape == (1, h, w, 3) and np.all(np.isfinite(ya))
        np.testing.assert_allclose(ya, yb, rtol=1e-5, atol=1e-6 * np.abs(ya).max())
        with torch.no_grad():
            want = crop_nhwc(ref(torch.from_numpy(pad_nhwc(x, 32))).numpy(), h, w, 32)
        np.testing.assert_allclose(ya, want, rtol=1e-4, atol=1e-5 * np.abs(want).max())


@pytest.mark.parametrize("upsample", ["transpose", "resize", "shuffle"])
def test_batch_norm_is_folded_into_the_convolutions(upsample):
    """The lean graph has no BatchNormalization: each is folded into the convolution before it (a transposed
    one included), and the folded generator equals the original in eval mode; the original is untouched."""
    import onnx

    from diviewer.contract.encoding import Encoding
    from diviewer.train.export import onnx_bytes
    from diviewer.train.graph import fold_batchnorm
    from diviewer.train.networks import NetConfig, init_weights

    torch.manual_seed(1)
    netG = init_weights(NetConfig(K=4, resolution=32, upsample=upsample, norm="batch").build_generator())
    with torch.no_grad():
        for m in netG.modules():  # statistics and affine terms far from their initial values
            if isinstance(m, torch.nn.BatchNorm2d):
                m.running_mean.uniform_(-0.5, 0.5)
                m.running_var.uniform_(0.05, 4.0)
                m.weight.uniform_(0.5, 1.5)
                m.bias.uniform_(-0.3, 0.3)
    netG.eval()
    before = {k: v.clone() for k, v in netG.state_dict().items()}
    folded = fold_batchnorm(netG)
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in folded.modules())
    assert sum(isinstance(m, torch.nn.BatchNorm2d) for m in netG.modules()) > 0
    for k, v in netG.state_dict().items():
        assert torch.equal(v, before[k]), k
    x = torch.randn(2, 10, 32, 32)
    with torch.no_grad():
        ref, got = netG(x), folded(x)
    assert (got - ref).abs().max() <= 1e-5 * max(1.0, ref.abs().max())

    module = gi_module(netG, Encoding(exposure=2.0, depth_scale=10.0), {"target": "indirect", "divide_albedo": True})
    graph = onnx.load_from_string(onnx_bytes(module, torch.from_numpy(_buffers(np.random.default_rng(0), 1, 32, 32))))
    ops = {n.op_type for n in graph.graph.node}
    assert "BatchNormalization" not in ops and ("ConvTranspose" in ops) == (upsample == "transpose")


def test_the_verification_scores_the_frames_own_pixels_not_the_stride_padding(checkpoints, tmp_path, monkeypatch):
    """Frames of a width off the model's stride (Sponza's 228 at a stride of 256) are padded for the graph; the
    runtime crops the padding off, so the export's tolerance is checked on the frame's own pixels. A graph that
    departs from PyTorch only in the padding columns is written; one that departs inside the frame is refused."""
    import diviewer.train.export as ex
    from diviewer.contract.padding import crop_slice, pad_nhwc

    ck = checkpoints["indirect"]
    netG, enc, meta = build_generator_from_checkpoint(ck)
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(1, 5, (2, 32, 24, 1)), rng.uniform(-1, 1, (2, 32, 24, 3)),
                        rng.uniform(0, 1, (2, 32, 24, 3)), rng.uniform(0, 3, (2, 32, 24, 3))], -1).astype(np.float32)
    multiple = 2 ** int(meta["model_args"]["levels"])
    frames = pad_nhwc(x, multiple)
    assert frames.shape[2] > 24, "the frames must be padded for this test"
    inside = crop_slice(24, multiple)
    real = ex.run_session

    def skewed(where):
        def run(session, f, *args):
            y = real(session, f, *args).copy()
            if f.shape[0] == len(frames):  # the verification frames (not the extreme-buffer one)
                cols = np.zeros(y.shape[2], bool)
                cols[where] = True
                y[:, :, cols] += 0.5 * float(np.abs(y).max())
            return y
        return run

    padding = np.ones(frames.shape[2], bool)
    padding[inside] = False
    settings = ExportSettings(verify_frames=2)
    scales = np.ones(2, np.float32) if enc.light_scaled else None
    args = (lambda: build_generator_from_checkpoint(ck)[0], enc, meta, settings, frames, scales, "test frames",
            tmp_path / "m.onnx", quiet)
    monkeypatch.setattr(ex, "run_session", skewed(padding))
    _, check = ex.verified_onnx(*args, crop=(32, 24, multiple))
    assert check["max_rel_to_peak"] < 1e-4  # the error lies in the padding alone
    with pytest.raises(DiviewerError, match="differs from PyTorch"):
        ex.verified_onnx(*args)  # scored with the padding, as before
    monkeypatch.setattr(ex, "run_session", skewed(np.arange(frames.shape[2]) == inside.start))
    with pytest.raises(DiviewerError, match="differs from PyTorch"):
        ex.verified_onnx(*args, crop=(32, 24, multiple))


def test_both_graphs_decode_the_output_at_the_output_gains_exposure(checkpoints):
    """An encoding's output_gain divides what the network's output decodes to, in the lean graph and in training's
    functions alike (the inputs keep the exposure): the same network at gain 4 adds a quarter of the indirect light."""
    import dataclasses

    netG, enc, meta = build_generator_from_checkpoint(checkpoints["indirect"])
    x = torch.from_numpy(np.random.default_rng(5).uniform(0.1, 2, (1, 64, 32, 10)).astype(np.float32))
    s = torch.tensor([0.8])
    direct = x[..., 7:10].numpy()
    gained = dataclasses.replace(enc, output_gain=4.0)
    with torch.no_grad():
        for lean in (True, False):
            base = gi_module(netG, enc, meta, lean=lean)(x, s).numpy() - direct
            quarter = gi_module(netG, gained, meta, lean=lean)(x, s).numpy() - direct
            live = base > 1e-3  # where ReLU of the composite does not clip
            assert live.mean() > 0.5
            np.testing.assert_allclose(quarter[live], base[live] / 4, rtol=1e-4, atol=1e-6)


def test_procedural_verification_frames_and_their_conditioning_are_pinned():
    """Export's procedural verification frames (no dataset) and their stand-in conditioning draw the same numbers as
    they always did: buffers, light scales (0.5 to 2, drawn after the buffers), the stand-in camera and suns at a few
    directions, pinned at the values they had before the conditioning moved to `diviewer.contract.conditioning`."""
    from diviewer.contract.conditioning import stacked
    from diviewer.contract.encoding import Encoding
    from diviewer.train.export import _verification_frames

    box = {"world_center": (0.0, 1.0, 0.0), "world_half": (1.5, 1.5, 1.5)}
    frames, source, conds = _verification_frames(Encoding(version=4, lights=2, **box), None, 3, (24, 16))
    scales, cams, lights = stacked(conds)
    assert frames.shape == (3, 16, 24, 10) and "3 synthetic frames" in source
    corner = [[3.5997514724731445, 0.0, 0.7071067690849304, 0.7071067690849304],
              [4.363836765289307, 0.0, 0.7071067690849304, 0.7071067690849304],
              [3.5591225624084473, 0.0, 0.7071067690849304, 0.7071067690849304]]
    np.testing.assert_allclose(frames[:, 0, 0, :4], corner, rtol=1e-6)
    far = [[1.5884932279586792, 0.34878847002983093, 0.6443120241165161, 0.6805943250656128],
           [1.0008665323257446, 0.6509829759597778, 0.36239805817604065, 0.666999876499176],
           [1.0027966499328613, 0.5855496525764465, 0.5585649013519287, 0.5874834656715393]]
    np.testing.assert_allclose(frames[:, -1, -1, :4], far, rtol=1e-6)
    np.testing.assert_allclose(frames[2, -1, -1, 7:], [0.0011759098852053285, 0.0007586515857838094,
                                                       0.0006448538042604923], rtol=1e-5)
    np.testing.assert_allclose(frames.sum(axis=(1, 2, 3), dtype=np.float64),
                               [2484.3612984007923, 2388.8165708293673, 2284.045064641221], rtol=1e-6)
    assert scales.dtype == np.float32
    np.testing.assert_array_equal(scales, np.float32([1.7861064672470093, 0.5503783822059631, 1.5944831371307373]))
    camera = [1.0, 0.0, -0.0, -0.0, 1.0, -0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 3.0, 0.0517766959965229, -0.621320366859436,
              -0.0517766959965229, 0.4142135679721832, 0.0, 23.0, 0.0, 15.0]
    np.testing.assert_allclose(cams, [camera] * 3, rtol=1e-6, atol=1e-7)
    suns = [[0.0, -0.7071067690849304, 0.7071067690849304], [0.5950098633766174, -0.7071067690849304,
                                                             0.3820514380931854],
            [0.6429703831672668, -0.7071067690849304, -0.29426026344299316]]
    np.testing.assert_allclose(lights, [s * 2 for s in suns], rtol=1e-6, atol=1e-7)
    for version in (1, 2, 3):  # the same buffers and draws whatever the encoding takes
        enc = Encoding(version=version, **(box if version >= 3 else {}))
        same, _, c = _verification_frames(enc, None, 3, (24, 16))
        np.testing.assert_array_equal(same, frames)
        s, cam, light = stacked(c)
        assert light is None and (cam is None) == (version < 3) and (s is None) == (version < 2)
        if version >= 2:
            np.testing.assert_array_equal(s, scales)


def test_dataset_verification_frames_take_each_frames_stored_configuration(tmp_path):
    """Export's verification frames from a dataset carry each frame's light scale, camera and lights as its stored
    configuration gives them; a dataset whose frames have another number of lights than the model takes leaves
    procedural frames."""
    from diviewer.contract.conditioning import stacked
    from diviewer.contract.encoding import Encoding
    from diviewer.data.scales import light_scales
    from diviewer.scene.camera import camera_params
    from diviewer.scene.lights import light_params
    from diviewer.train.export import _verification_frames
    from tiny_datasets import tiny_capture

    ds = tiny_capture(tmp_path / "cap", frames=3)
    box = {"world_center": (0.0, 1.0, 0.0), "world_half": (1.5, 1.5, 1.5)}
    frames, source, conds = _verification_frames(Encoding(version=4, lights=1, **box), str(ds.root), 2, (24, 16))
    idx = (ds.indices("val") or ds.indices())[:2]
    assert "frames of" in source and frames.shape == (len(idx), 16, 16, 10)
    scales, cams, lights = stacked(conds)
    np.testing.assert_array_equal(scales, light_scales(ds, idx))
    configs = [next(f["config"] for f in ds.frames if f["index"] == i) for i in idx]
    c = [x["camera"] for x in configs]
    np.testing.assert_array_equal(cams, [camera_params(k["position"], k["target"], k["up"], k["fov"], 16, 16)
                                         for k in c])
    np.testing.assert_array_equal(lights, [light_params(x["lights"], box["world_center"], box["world_half"])
                                           for x in configs])
    _, other, _ = _verification_frames(Encoding(version=4, lights=2, **box), str(ds.root), 2, (24, 16))
    assert "synthetic frames" in other
