"""`diviewer bench`: the FLOP count, the equal-time / equal-error logic on synthetic tables, and a --quick run (torch blocked) whose JSON has every row, stage and metric."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from diviewer.bench.frontier import (equal_error, equal_time, smallest_sufficient_k, spp_in_time,
                                     temporal_stability)
from diviewer.bench.onnx_tools import generator_flops

from onnx_models import random_buffers


# --- cost model ----------------------------------------------------------------------------------------------------


def test_flops_of_a_two_level_generator_match_a_hand_count():
    """K=2, 2 levels, 4x4 input, 10 -> 3 channels; widths 2, 4. Multiply-adds by hand:
    down0 Conv 10->2, 4x4/2 -> 2x2 output: 4 px * 2 * 10 * 16 = 1280
    down1 Conv 2->4 -> 1x1:                1 px * 4 * 2 * 16  = 128
    up0 ConvT 4->2 -> 2x2 (4 of 16 taps per output pixel): 4 px * 4 * 2 * 4 = 128
    up1 ConvT (2+2)->3 -> 4x4:             16 px * 4 * 3 * 4  = 768
    total 2304 MACs = 4608 FLOPs."""
    f = generator_flops(K=2, levels=2, width=4, height=4)
    assert dict(f["layers"]) == {"down0": 1280, "down1": 128, "up0": 128, "up1": 768}
    assert f["macs"] == 2304 and f["flops"] == 4608
    # resize decoders: nearest x2 then Conv 3x3 at the output: 9 taps instead of 4.
    r = generator_flops(K=2, levels=2, width=4, height=4, upsample="resize")
    assert r["macs"] == 1280 + 128 + 4 * 4 * 2 * 9 + 16 * 4 * 3 * 9
    with pytest.raises(ValueError):
        generator_flops(K=2, levels=3, width=4, height=4)


def test_a_cards_first_layer_counts_its_world_light_and_fourier_planes():
    """The FLOPs of a model row take the planes its first layer reads: 10 buffers, + 6 world planes (encoding 3),
    + 3 a light (encoding 4), + 6 an octave of Fourier features; a card without an encoding reads the 10."""
    from diviewer.bench.onnx_tools import network_inputs

    v4 = {"version": 4, "exposure": 1.0, "depth_scale": 10.0, "lights": 1, "world_center": [0, 0, 0],
          "world_half": [1, 1, 1]}
    assert network_inputs({}) == 10
    assert network_inputs({"encoding": {**v4, "version": 3, "lights": None}}) == 16
    assert network_inputs({"encoding": v4}) == 19
    assert network_inputs({"encoding": v4, "world_frequencies": 6}) == 19 + 36
    assert (generator_flops(K=2, levels=2, width=4, height=4, in_channels=19)["layers"][0]
            == ("down0", 4 * 2 * 19 * 16))


def test_untrained_generator_runs_and_matches_the_torch_unet_in_size():
    """The torch-free U-Net has pix2pix's layer shapes (as many convolution weights as UnetGenerator), and
    onnxruntime runs it under the runtime's contract."""
    import onnx
    import onnxruntime as ort
    from onnx import numpy_helper

    from diviewer.bench.onnx_tools import untrained_generator
    from diviewer.scene import load_scene

    model = untrained_generator(4, 3, load_scene("cornell"), 16)
    sess = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    x = np.random.default_rng(0).random((1, 16, 16, 10), dtype=np.float32)
    (y,) = sess.run(None, {"buffers": x})
    assert y.shape == (1, 16, 16, 3) and np.all(np.isfinite(y))
    weights = {i.name: numpy_helper.to_array(i) for i in model.graph.initializer if i.name.endswith(".w")}
    assert [w.shape for k, w in weights.items() if k.startswith("down")] == [(4, 10, 4, 4), (8, 4, 4, 4), (16, 8, 4, 4)]
    assert [w.shape for k, w in weights.items() if k.startswith("up")] == [(16, 8, 4, 4), (16, 4, 4, 4), (8, 3, 4, 4)]
    torch = pytest.importorskip("torch")
    from diviewer.train.networks import UnetGenerator

    net = UnetGenerator(K=4, levels=3)
    conv_weights = sum(m.weight.numel() for m in net.modules() if isinstance(m, (torch.nn.Conv2d, torch.nn.ConvTranspose2d)))
    assert conv_weights == sum(w.size for w in weights.values())
    assert onnx.checker.check_model(model) is None


# --- equal time, equal error, smallest K, temporal stability ---------------------------------------------------------

LADDER = [1, 4, 16, 64, 256]
MS = [10.0 * n for n in LADDER]          # the path tracer: 10 ms per sample per pixel
ERR = [1.0 / n for n in LADDER]          # its error falls as 1 / spp


def test_equal_time_on_a_synthetic_ladder():
    r = equal_time(LADDER, MS, ERR, 80.0)  # 80 ms buys 8 spp, whose error is 1/8
    assert r["bound"] == "=" and r["spp"] == pytest.approx(8.0) and r["error"] == pytest.approx(1 / 8)
    assert equal_time(LADDER, MS, ERR, 10.0)["spp"] == pytest.approx(1.0)
    below = equal_time(LADDER, MS, ERR, 5.0)  # not even one sample in time
    assert below["bound"] == "<" and below["error"] is None
    above = equal_time(LADDER, MS, ERR, 10000.0)
    assert above["bound"] == ">=" and above["spp"] == 256 and above["error"] == pytest.approx(1 / 256)
    # A ladder whose time grows as spp^0.5 interpolates in log-log exactly.
    assert spp_in_time([1, 16], [4.0, 16.0], 8.0)["spp"] == pytest.approx(4.0)


def test_equal_error_gives_the_path_tracers_time_and_the_speed_up():
    r = equal_error(LADDER, MS, ERR, error=1 / 32, ms=4.0)  # a method as good as 32 spp, in 4 ms
    assert r["bound"] == "=" and r["spp"] == pytest.approx(32.0)
    assert r["pt_ms"] == pytest.approx(320.0) and r["speedup"] == pytest.approx(80.0)
    better = equal_error(LADDER, MS, ERR, error=1e-4, ms=4.0)
    assert better["bound"] == ">=" and better["pt_ms"] == pytest.approx(2560.0)  # a lower bound on the speed-up
    worse = equal_error(LADDER, MS, ERR, error=2.0, ms=4.0)
    assert worse["bound"] == "<"


def test_smallest_sufficient_k():
    s = smallest_sufficient_k({8: 25.0, 16: 26.7, 32: 27.0, 64: 26.9})
    assert s["K"] == 16 and s["best_K"] == 32
    assert smallest_sufficient_k({8: 25.0, 16: 26.0})["K"] == 16
    assert smallest_sufficient_k({}) is None


def test_temporal_stability_sees_flicker_the_reference_does_not_have():
    ramp = [np.full((4, 4), 0.1 * t) for t in range(5)]
    same = temporal_stability(ramp, ramp)
    assert same["ratio"] == pytest.approx(1.0) and same["excess"] == 0.0
    flicker = [r + (0.05 if t % 2 else 0.0) for t, r in enumerate(ramp)]
    f = temporal_stability(flicker, ramp)
    # changes alternate 0.15, 0.05: mean 0.1 like the reference, but each differs from it by 0.05
    assert f["excess"] == pytest.approx(0.05) and f["change"] == pytest.approx(0.1)
    still = [np.zeros((4, 4))] * 5
    assert temporal_stability(flicker, still)["ratio"] == math.inf


# --- the --quick run -------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def tiny_bench_inputs(tmp_path_factory):
    """A 32x32 evaluation set of one frame per split (16 spp, ladder 1/4) and a small model that runs at 32 and 16."""
    pytest.importorskip("mitsuba", reason="the evaluation set and the path-tracer rows need the train extra")
    import onnx

    from diviewer.bench.onnx_tools import get_meta, set_meta, untrained_generator
    from diviewer.evaluation.evalset import EvalSetSettings, build_evalset
    from diviewer.scene import load_scene

    root = tmp_path_factory.mktemp("bench")
    build_evalset("cornell", root / "es", EvalSetSettings(frames_per_split=1, width=32, height=32, spp=16,
                                                           ladder=(1, 4), thumbs=0), log=lambda *_: None)
    model = untrained_generator(4, 3, load_scene("cornell"), 32)
    meta = get_meta(model)
    meta.update(kind="neural", dataset_hash="test")  # stands for a trained model: scored like one
    set_meta(model, meta)
    onnx.save(model, str(root / "small.onnx"))
    return root


@pytest.mark.mitsuba
@pytest.mark.slow
def test_quick_bench_without_torch_writes_every_row_stage_and_metric(gl_context, tiny_bench_inputs):
    root = tiny_bench_inputs
    code = (
        "import sys\n"
        "sys.modules['torch'] = None\n"
        "from diviewer.cli import main\n"
        f"rc = main(['bench', '--quick', '--models', {str(root / 'small.onnx')!r}, '--evalset', {str(root / 'es')!r},"
        f" '--json', {str(root / 'b.json')!r}, '--plot', {str(root / 'b.png')!r}])\n"
        "assert rc == 0, rc\n"
        "assert 'torch' not in [m for m in sys.modules if sys.modules[m] is not None]\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "method" in r.stdout and "path traced 4 spp" in r.stdout and "stages (median ms)" in r.stdout
    result = json.loads((root / "b.json").read_text())  # strict JSON: no NaN/Infinity tokens
    assert (root / "b.png").stat().st_size > 10_000
    rows = result["rows"]
    labels = [row["label"] for row in rows]
    kinds = {(row["kind"], row.get("precision"), row["gi_resolution"][0]) for row in rows}
    assert {("direct", None, 32), ("neural", "fp32", 32), ("neural", "fp16", 32), ("neural", "int8", 32),
            ("neural", "fp32", 16), ("untrained", "fp32", 32), ("path_tracer", None, 32), ("vxgi", None, 16)} <= kinds, labels
    assert [row["grid"] for row in rows if row["kind"] == "vxgi"] == [16]  # --quick: one small grid
    assert [row["K"] for row in rows if row["kind"] == "untrained"] == [8, 16]
    assert [row["spp"] for row in rows if row["kind"] == "path_tracer"] == [1, 4]
    gl_stages = {"shadows", "gbuffer", "direct", "composite"}
    for row in rows:
        t = row["timing"]
        stages = set(t["stages"])
        if row["kind"] == "path_tracer":
            assert stages == {"path_trace"}
        elif row["kind"] == "direct":
            assert stages == gl_stages
        elif row["kind"] == "vxgi":  # voxelize, inject and mip run in the frames whose configuration changed
            from diviewer.gl.vxgi import STAGES as VXGI_STAGES

            every_frame = {"vxgi_inject", "vxgi_mip", "vxgi_trace", "vxgi_upsample", "vxgi_composite"}
            assert gl_stages | every_frame <= stages <= gl_stages | set(VXGI_STAGES), stages
        else:  # one light: the direct light is computed inside the pack and the upsample, as in the viewer
            assert stages == gl_stages - {"direct"} | {"readback", "inference", "upload", "upsample"}
        for s in [t["frame"], *t["stages"].values()]:
            assert all(math.isfinite(s[k]) and s[k] > 0 for k in ("median", "p95", "max")), (row["label"], s)
            assert s["median"] <= s["p95"] <= s["max"]
        assert t["fps"] > 0 and 0 <= t["overhead_fraction"] <= 1
        if row.get("untrained"):
            assert row["accuracy"] is None and row["flops"] > 0 and row["achieved_flops_per_s"] > 0
            continue
        a = row["accuracy"]
        assert a is not None and all(a[k] is not None and math.isfinite(a[k]) for k in
                                     ("psnr", "ssim", "psnr_tm", "ssim_tm", "flip_hdr", "flip_ldr")), row["label"]
        assert row["equivalent_spp"]["psnr_tm"]["spp"] > 0
        if row["kind"] != "path_tracer":
            assert row["equal_time"]["spp"] > 0 and row["equal_error"]["pt_ms"] > 0
        if row.get("step", 1) == 1:
            assert row["temporal"]["change"] >= 0 and row["temporal"]["reference_change"] > 0
    int8 = next(row for row in rows if row.get("precision") == "int8")
    assert math.isfinite(int8["int8"]["drop_db"]) and isinstance(int8["int8"]["kept"], bool)
    assert result["cost_model"]["smallest_sufficient_K"]["K"] == 4
    env = result["environment"]
    assert env["gl_renderer"] and "CPUExecutionProvider" in env["onnxruntime_available_providers"]
    assert "timer queries" in env["gl_timing"] or "glFinish" in env["gl_timing"]


@pytest.mark.mitsuba
def test_temporal_rows_stop_at_temporal_max_spp(ctx, tiny_bench_inputs):
    """The temporal sequence renders the path tracer's ladder up to ``temporal_max_spp`` only (--quick: its
    reference's 4 spp, so the 16-256 spp rungs at the set's size no longer take most of a quick bench); None
    keeps every rung."""
    from diviewer.bench.core import QUICK, BenchSettings, _open_evalset
    from diviewer.bench.runner import gl_timing_mode, temporal_rows
    from diviewer.scene import load_scene

    scene = load_scene("cornell")
    ds = _open_evalset(BenchSettings(evalset=str(tiny_bench_inputs / "es")), scene, [])
    base = BenchSettings(temporal_frames=2, temporal_spp=2, vxgi_grids=())
    mode = gl_timing_mode(ctx, "sync")
    got = {}
    for cap in (None, 1):
        t = temporal_rows(ctx, dataclasses.replace(base, temporal_max_spp=cap), scene, ds, [], None, mode, [],
                      lambda *_: None)
        got[cap] = sorted(k for k in t["methods"] if k.startswith("pt_spp"))
    assert got == {None: ["pt_spp1", "pt_spp4"], 1: ["pt_spp1"]}  # the set's ladder is 1, 4
    assert QUICK["temporal_max_spp"] == QUICK["temporal_spp"]


@pytest.mark.mitsuba
def test_temporal_rows_run_a_model_whose_stride_the_sequence_does_not_fill(ctx, tiny_bench_inputs):
    """The runtime pads any size to the model's stride, so the temporal sequence (32x32 here) runs a model of
    stride 64 as well: its row is there, with the frame-to-frame change of images it really drew."""
    import onnx

    from diviewer.bench.core import BenchSettings, _open_evalset
    from diviewer.bench.onnx_tools import untrained_generator
    from diviewer.bench.runner import gl_timing_mode, temporal_rows
    from diviewer.contract.runtime import NeuralGI
    from diviewer.scene import load_scene

    scene = load_scene("cornell")
    path = tiny_bench_inputs / "stride64.onnx"
    onnx.save(untrained_generator(4, 6, scene, 64), str(path))
    net = NeuralGI(path)
    assert net.multiple == 64
    ds = _open_evalset(BenchSettings(evalset=str(tiny_bench_inputs / "es")), scene, [])
    settings = BenchSettings(temporal_frames=2, temporal_spp=2, temporal_max_spp=1, vxgi_grids=())
    t = temporal_rows(ctx, settings, scene, ds, [{"path": str(path)}], lambda v: net, gl_timing_mode(ctx, "sync"),
                      [], lambda *_: None)
    assert t["resolution"] == [32, 32]
    row = t["methods"][f"{path}|1"]
    assert math.isfinite(row["change"]) and row["change"] > 0 and row["reference_change"] > 0


def test_bench_accuracy_from_a_compact_set_matches_the_full_set(tiny_bench_inputs, tmp_path, monkeypatch):
    """The bench's default evaluation set is the scene's compact one; its ladder (stored as scores) and its
    images score as the full set's frames do."""
    from diviewer.bench.core import BenchSettings, _open_evalset
    from diviewer.bench.runner import score_evalset
    from diviewer.evaluation.frames import EvalFrames, write_compact
    from diviewer.scene import load_scene

    root = tiny_bench_inputs
    write_compact(root / "es", tmp_path / "evalsets" / "cornell", frames_per_split=1, log=lambda *_: None)
    monkeypatch.setattr("diviewer.evaluation.frames.DEFAULT_EVALSETS", tmp_path / "evalsets")
    notes: list[str] = []
    compact = _open_evalset(BenchSettings(), load_scene("cornell"), notes)  # no --evalset given
    assert compact is not None and compact.compact and notes == []
    full = EvalFrames(root / "es")
    idx, shape = full.bench_frames()
    assert shape == (32, 32) and compact.bench_frames() == (idx, shape)
    assert [full.entry(i)["split"] for i in idx] == ["unseen_configs", "unseen_objects"]  # the scene's camera
    a = score_evalset(compact, idx, shape, {}, None)["methods"]
    b = score_evalset(full, idx, shape, {}, None)["methods"]
    assert set(a) == set(b) == {"direct", "noise_floor", "pt_spp1", "pt_spp4"}
    for k in a:
        assert a[k]["psnr_tm"]["mean"] == pytest.approx(b[k]["psnr_tm"]["mean"], abs=0.05), k
        assert a[k]["equivalent_spp"]["psnr_tm"]["text"] == b[k]["equivalent_spp"]["psnr_tm"]["text"], k


def test_bare_generator_ratio_is_reported_per_model_row():
    """bench prints each model's inference time over the bare generator's of the same K and size (issue 28)."""
    from diviewer.bench.core import bare_ratio_lines

    def row(kind, K, res, ms, **kw):
        return {"kind": kind, "label": f"{kind} K={K}", "K": K, "resolution": [res, res], "gi_resolution": [res, res],
                "timing": {"stages": {"inference": {"median": ms}}}, **kw}

    rows = [row("neural", 8, 128, 3.0), row("neural", 8, 64, 1.0), row("untrained", 8, 128, 2.5, untrained=True),
            row("direct", None, 128, 0.5)]
    lines = bare_ratio_lines(rows)
    assert rows[0]["bare_ratio"] == pytest.approx(1.2) and "bare_ratio" not in rows[1]  # no bare K=8 at 64
    assert len(lines) == 3 and "1.20 x the bare K=8" in lines[-1]
    assert bare_ratio_lines(rows[1:2]) == []


def test_two_models_of_one_name_get_precision_twins_of_their_own(tmp_path):
    """bench converts each model to its other precision in a scratch folder: a/sponza.onnx and b/sponza.onnx must
    not share one converted file (the second overwrote the first, and both rows timed it)."""
    pytest.importorskip("onnx")
    import shutil

    from diviewer.bench.core import _variants
    from diviewer.paths import models_dir

    paths = []
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        paths.append(tmp_path / name / "sponza.onnx")
        shutil.copyfile(models_dir() / "sponza.onnx", paths[-1])
    (tmp_path / "scratch").mkdir()
    notes = []
    out = _variants(paths, tmp_path / "scratch", notes, log=lambda *_: None)
    twins = [v for v in out if v.get("converted_from")]
    assert len(twins) == 2 and not notes
    assert twins[0]["path"] != twins[1]["path"] and all(Path(v["path"]).is_file() for v in twins)
    assert [v["source"] for v in twins] == [str(p) for p in paths]


def _encoding_2_model(path: Path) -> Path:
    """An encoding-2 model like the cornell one shipped before encoding 3 (K=4, 7 levels, 228x128; random weights)."""
    torch = pytest.importorskip("torch")
    import onnx

    from onnx_models import base_meta

    from diviewer.bench.onnx_tools import set_meta
    from diviewer.contract.encoding import Encoding
    from diviewer.train.export import gi_module, onnx_bytes
    from diviewer.train.networks import UnetGenerator

    torch.manual_seed(0)
    enc = Encoding(exposure=1.0, depth_scale=10.0, version=2)
    module = gi_module(UnetGenerator(K=4, levels=7).eval(), enc, {"target": "indirect", "divide_albedo": True})
    model = onnx.load_from_string(onnx_bytes(module, torch.rand(1, 128, 256, 10), torch.ones(1)))
    set_meta(model, {**base_meta(), "encoding": enc.to_dict(), "resolution": [228, 128], "multiple": 128, "K": 4,
                     "levels": 7, "target": "indirect"})
    onnx.save(model, str(path))
    return path


def test_int8_quantisation_calibrates_an_encoding_2_model_with_its_light_scales(tmp_path):
    """An encoding-2 model takes each frame's light scale: calibration feeds it, and the int8 model runs (it failed
    with 'Required inputs (['light_scale']) are missing')."""
    pytest.importorskip("onnx")
    from diviewer.bench.onnx_tools import get_meta, quantize_int8
    from diviewer.contract.conditioning import stand_in
    from diviewer.contract.runtime import NeuralGI, read_metadata

    src = _encoding_2_model(tmp_path / "v2.onnx")
    enc = read_metadata(src)["encoding"]
    assert enc["version"] == 2
    rng = np.random.default_rng(3)
    calib = []
    for scale in (0.5, 2.0):  # at the model's 228x128 (16:9), which the graph runs padded to 256x128
        calib.append((random_buffers(rng, 128, 228, batch=1), stand_in(enc, (228, 128), light_scale=scale)))
    out = quantize_int8(src, tmp_path / "int8.onnx", calib, percentile=None)
    import onnx

    meta = get_meta(onnx.load(str(out)))
    assert meta["precision"] == "int8" and meta["quantization"]["calibration"] == "min-max"
    y = NeuralGI(out).run(calib[0][0][0], light_scale=0.5)
    assert y.shape == (128, 228, 3) and np.isfinite(y).all() and y.max() > 0


def test_int8_quantisation_calibrates_an_encoding_3_model_with_its_cameras(tmp_path):
    """The shipped cornell model takes each frame's camera (encoding 3): calibration feeds it, padded as the runtime
    pads, and the int8 twin runs off the model's own size and stays near the fp32 model on a calibration frame
    (bench made no int8 twin of encoding-3 models before)."""
    pytest.importorskip("onnx")
    import onnx

    from diviewer.bench.onnx_tools import CALIB_PERCENTILE, get_meta, quantize_int8
    from diviewer.contract.conditioning import stand_in
    from diviewer.paths import models_dir
    from diviewer.contract.runtime import NeuralGI, read_metadata

    src = models_dir() / "cornell.onnx"
    enc = read_metadata(src)["encoding"]
    if enc["version"] < 3:
        pytest.skip("the shipped cornell model is not encoding 3")
    rng = np.random.default_rng(5)
    camera = {"position": (0.0, 1.0, 3.5), "target": (0.0, 1.0, 0.0), "up": (0.0, 1.0, 0.0), "fov": 45.0}
    calib = [(random_buffers(rng, 96, 160, batch=1), stand_in(enc, (160, 96), light_scale=s, camera=camera))
             for s in (0.5, 2.0)]
    out = quantize_int8(src, tmp_path / "int8.onnx", calib)
    meta = get_meta(onnx.load(str(out)))  # the default activation ranges: a percentile, recorded in the model
    assert meta["precision"] == "int8" and meta["quantization"]["calibration"] == f"percentile {CALIB_PERCENTILE:g}"
    x, cond = calib[0]
    y8 = NeuralGI(out).run(x[0], **cond.inputs())
    y32 = NeuralGI(src).run(x[0], **cond.inputs())
    assert y8.shape == (96, 160, 3) and np.isfinite(y8).all() and y8.max() > 0
    assert np.abs(y8 - y32).mean() < 0.1 * np.abs(y32).mean()


def test_fp16_twin_of_a_lean_export_halves_the_generator_only():
    """bench's fp16 twin of the shipped fp32 model: the generator in float16 between one Cast in and one out,
    the encoding and its NaN guard untouched (onnxruntime's converter mistyped the guard's If and the file did
    not load); within export's fp16 tolerance (1e-2 of peak) of the fp32 model, NaN and Inf still sanitised."""
    onnx = pytest.importorskip("onnx")
    import onnxruntime as ort

    from diviewer.bench.onnx_tools import GENERATOR_PREFIX, get_meta, to_fp16
    from diviewer.paths import models_dir

    src = onnx.load(str(models_dir() / "cornell.onnx"))
    assert get_meta(src)["precision"] == "fp32"
    half = to_fp16(src)
    onnx.checker.check_model(half)
    assert get_meta(half)["precision"] == "fp16"
    casts = [n for n in half.graph.node if n.op_type == "Cast" and n.name.endswith(("_to_fp16", "_to_fp32"))]
    assert len(casts) == 2
    weights = {i.input[1] for i in half.graph.node if i.op_type in ("Conv", "ConvTranspose")}
    assert all(w.data_type == onnx.TensorProto.FLOAT16 for w in half.graph.initializer if w.name in weights)
    assert any(n.op_type == "If" for n in half.graph.node if not n.name.startswith(GENERATOR_PREFIX))
    runs = [ort.InferenceSession(m.SerializeToString(), providers=["CPUExecutionProvider"]) for m in (src, half)]
    rng = np.random.default_rng(7)
    x = random_buffers(rng, 128, 128, batch=1)
    feed = {"buffers": x, "light_scale": np.full(1, 0.7, np.float32)}
    if int(get_meta(src)["encoding"]["version"]) >= 3:  # encoding 3: the frame's camera too
        from diviewer.contract.runtime import NeuralGI
        from diviewer.scene import load_scene

        feed["camera"] = NeuralGI.camera(load_scene("cornell").default.camera, 128, 128)[None]
    ref, got = (r.run(None, feed)[0] for r in runs)
    assert np.abs(got - ref).max() <= 1e-2 * np.abs(ref).max()
    x[0, 3, 3, 2], x[0, 5, 5, 0] = np.nan, np.inf  # a NaN normal and an infinite depth
    assert np.isfinite(runs[1].run(None, feed)[0]).all()


@pytest.mark.slow
def test_bench_scores_the_shipped_model_with_no_gi_steps_and_no_vxgi(tmp_path):
    """The shipped cornell model (encoding 3, the area's direct light) takes each frame's GL scene and camera even
    where no GI step or VXGI grid asks for GL rendering: its accuracy is scored, not a crash."""
    out = tmp_path / "b.json"
    r = subprocess.run([sys.executable, "-m", "diviewer", "bench", "--quick", "--gi-steps", "--vxgi-grids",
                        "--untrained-k", "--eval-frames", "1", "--pt-frames", "1", "--json", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-3000:]
    rows = json.loads(out.read_text())["rows"]
    fp32 = next(row for row in rows if row["kind"] == "neural" and row.get("precision") == "fp32"
                and row.get("step", 1) == 1 and "cornell_linear" not in str(row.get("model")))
    assert fp32["accuracy"] is not None and fp32["accuracy"]["psnr_tm"] > 25


def test_an_int8_variant_not_kept_is_noted_once_whatever_the_resolutions():
    """The bench's rows at 128 and 256 carry one accuracy per model: the int8 verdict is noted once, and each row
    keeps its own drop and verdict."""
    from diviewer.bench.report import _int8

    def row(res, precision, psnr):
        return {"model": "m.onnx", "label": "m K=8 " + precision, "precision": precision, "resolution": [res, res],
                "step": 1, "accuracy": {"psnr_tm": psnr}}

    rows = [row(res, p, v) for res in (128, 256) for p, v in (("fp32", 30.0), ("int8", 28.0))]
    notes: list[str] = []
    _int8(rows, 0.5, notes)
    assert notes == ["m K=8 int8: int8 loses 2.00 dB (PSNR tm) > 0.5 dB: not kept"]
    assert [r["int8"]["kept"] for r in rows if r["precision"] == "int8"] == [False, False]


def test_the_bench_times_a_moving_sun_with_the_viewers_map_and_scores_with_the_full_one(ctx, monkeypatch):
    """Each timed frame moves the sun, so its map is drawn at the viewer's moving size, as the viewer draws it;
    outside the timing (the accuracy images) the renderer draws the scene's full map again."""
    import diviewer.gl.shadow_fit as shadow_fit
    from diviewer.bench.runner import GlBench
    from scenes import facing_plane

    monkeypatch.setattr(shadow_fit, "MOVING_SHADOW_SIZE", 32)
    scene = dataclasses.replace(facing_plane(lights=[{"name": "sun", "type": "directional",
                                                      "direction": [0.3, -0.4, -1.0]}]), shadow_size=256)
    configs = [scene.default.replace_light("sun", direction=(0.3 + 0.05 * k, -0.4, -1.0)) for k in range(4)]
    gb = GlBench(ctx, scene, 16, 16, "sync")
    try:
        timing = gb.time_direct(configs, warmup=2)
        assert timing["frame"]["median"] > 0
        assert gb.renderer.shadow_pass.maps["sun"].size == 32 and gb.renderer.moving_shadow_size is None
        gb.renderer.render(configs[0])  # the sun moved again, outside the timing: the full map
        assert gb.renderer.shadow_pass.maps["sun"].size == 256
    finally:
        gb.release()
