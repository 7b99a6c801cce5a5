"""World-space inputs (encoding version 3): the planes as the ablation's numpy reconstruction computes them, on
crops and padding as the runtime will pad, in training batches, and a run that trains on them."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from diviewer.errors import DiviewerError  # noqa: E402
from diviewer.contract.padding import pad_before, pad_index  # noqa: E402
from diviewer.scene import camera as cam  # noqa: E402
from diviewer.scene.loader import load_scene  # noqa: E402
from diviewer.train.checkpoint import load_checkpoint  # noqa: E402
from diviewer.contract.padding import shift_camera_params  # noqa: E402
from diviewer.train.world import light_planes, world_planes  # noqa: E402
from oracles import world_buffers  # noqa: E402

CAMERA = {"position": [-0.4, 1.4, 3.9], "target": [0.2, 1.3, 0.4], "up": [0.0, 1.0, 0.0], "fov": 41.0}


def _buffers(rng, h, w):
    depth = rng.uniform(0.5, 6.0, (h, w)).astype(np.float32)
    depth[:3] = 0.0
    n = rng.normal(size=(h, w, 3))
    return depth, (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)


def _params(**kw):
    return cam.camera_params(CAMERA["position"], CAMERA["target"], CAMERA["up"], CAMERA["fov"], **kw)


@pytest.mark.parametrize("x0", [0, 50, 100])
def test_world_planes_are_the_numpy_reconstruction(x0):
    depth, normal = _buffers(np.random.default_rng(x0), 128, 128)
    center, half = np.array([0.0, 1.0, 0.0]), 1.2
    pos, nrm = world_buffers(depth, normal, CAMERA, (228, 128), (x0, 0), center, half)
    p = torch.from_numpy(_params(width=128, height=128, x0=x0, source=(228, 128)))[None]
    got = world_planes(torch.from_numpy(depth)[None, None], torch.from_numpy(normal).permute(2, 0, 1)[None], p,
                       center, [half] * 3)[0].permute(1, 2, 0).numpy()
    np.testing.assert_allclose(got[..., :3], pos, atol=2e-5)
    np.testing.assert_allclose(got[..., 3:], nrm, atol=2e-5)


def test_planes_of_a_padded_frame_are_the_frames_planes_edge_padded():
    """What training computes on a padded crop is what the graph will compute on the runtime's padded frame:
    the frame's own planes, padded by edge replication like every other input."""
    h, w, m = 128, 100, 128
    depth, normal = _buffers(np.random.default_rng(1), h, w)
    cols, rows = pad_index(w, m), pad_index(h, m)
    full = torch.from_numpy(_params(width=w, height=h, x0=60, source=(228, 128)))[None]
    d, n = torch.from_numpy(depth)[None, None], torch.from_numpy(normal).permute(2, 0, 1)[None]
    plain = world_planes(d, n, full, (0, 1, 0), (1.1, 1.1, 1.1))
    padded_cams = torch.from_numpy(_params(width=w, height=h, x0=60, source=(228, 128),
                                           pad=(pad_before(w, m), pad_before(h, m))))[None]
    pad = lambda t: t[:, :, rows][:, :, :, cols]
    got = world_planes(pad(d), pad(n), padded_cams, (0, 1, 0), (1.1, 1.1, 1.1))
    np.testing.assert_allclose(got.numpy(), pad(plain).numpy(), atol=1e-5)


def test_shifted_cameras_are_camera_params_of_the_crop():
    full = torch.from_numpy(np.stack([_params(width=228, height=128)] * 2))
    got = shift_camera_params(full, torch.tensor([17.0, 80.0]), (14, 0), (100, 128)).numpy()
    for i, x0 in enumerate((17, 80)):
        np.testing.assert_allclose(got[i], _params(width=100, height=128, x0=x0, source=(228, 128), pad=(14, 0)),
                                   atol=1e-5)


def _world_dataset(tmp_path: Path, scene: str = "worldscene"):
    """test_trainer's synthetic dataset with a loadable scene file (its own, or a shipped scene's) and whole
    cameras in its frames."""
    from train.test_trainer import SCENE_TOML, make_dataset

    ds = make_dataset(tmp_path / "data", scene=scene)
    scene_file = ds.root / f"{scene}.toml"
    if scene == "worldscene":
        scene_file.write_text(SCENE_TOML.replace("NAME", "worldscene"))
    else:
        scene_file = load_scene(scene).path
    m = json.loads((ds.root / "manifest.json").read_text())
    m["scene_hash"], m["scene_file"] = load_scene(scene_file).file_hash, str(scene_file)
    for f in m["frame_list"]:
        f["config"]["camera"].update(target=[0, 0, 0], up=[0, 1, 0], fov=45.0)
    (ds.root / "manifest.json").write_text(json.dumps(m))
    return ds.root, load_scene(scene_file)


def test_a_run_trains_on_world_inputs_and_records_them(tmp_path):
    from train.test_trainer import quiet, tiny

    from diviewer.train.export import export
    from diviewer.train.trainer import train

    data, scene = _world_dataset(tmp_path)
    out = tmp_path / "run"
    r = train(tiny(data, out, world_inputs=True), log=quiet)
    assert r["val"] is not None and np.isfinite(r["val"]["psnr_tm"])
    ck = load_checkpoint(out / "last.ckpt")
    assert ck["model_args"]["in_channels"] == 16 and ck["config"]["world_inputs"] is True
    enc = ck["encoding"]
    lo, hi = scene.bounds()
    assert enc["version"] == 3
    np.testing.assert_allclose(enc["world_center"], (lo + hi) / 2)
    np.testing.assert_allclose(enc["world_half"], np.maximum((hi - lo) / 2, 1e-3))
    # resumes (the cameras are the run's, not the checkpoint's) ...
    assert train(tiny(data, out, world_inputs=True, epochs=3), resume=True, log=quiet)["step"] == 6
    # ... exports, verified against PyTorch with the frames' cameras, with the camera as the graph's third input ...
    card = export(out / "last.ckpt", tmp_path / "m.onnx", log=quiet)
    assert card["encoding"]["version"] == 3 and card["verification"]["max_rel_to_peak"] < 1e-4
    assert card["verification"]["zero_light_max"] == 0.0
    # ... and the runtime runs it at any size given each frame's camera, refusing it without one.
    from diviewer.contract.runtime import NeuralGI

    model = NeuralGI(tmp_path / "m.onnx")
    assert model.world and [i.name for i in model.session.get_inputs()] == ["buffers", "light_scale", "camera"]
    frame = np.load(data / "frames" / "000008.npy").astype(np.float32)[..., :10]
    config = json.loads((data / "manifest.json").read_text())["frame_list"][8]["config"]["camera"]
    for w in (32, 24, 40):
        x = frame[:, :w] if w <= 32 else np.concatenate([frame, frame[:, :w - 32]], 1)
        y = model.run(x, light_scale=2.0, camera=NeuralGI.camera(config, w, 32))
        assert y.shape == (32, w, 3) and np.isfinite(y).all()
    with pytest.raises(ValueError, match="camera"):
        model.run(frame, light_scale=2.0)


@pytest.mark.parametrize("lit", [False, True])
def test_the_graph_matches_training_on_a_padded_crop(tmp_path, lit):
    """The exported graph on a crop the runtime pads gives what training's own functions give on the same crop
    padded by split_batch: the world planes (and encoding 4's light planes) line up with the pixels on both paths."""
    from diviewer.contract.encoding import Encoding
    from diviewer.train.config import TrainConfig
    from diviewer.train.graph import ReferenceGI
    from diviewer.train.networks import UnetGenerator
    from diviewer.train.targets import split_batch

    torch.manual_seed(0)
    netG = UnetGenerator(19 if lit else 16, 3, K=4, levels=4).eval()
    enc = Encoding(exposure=1.0, depth_scale=10.0, version=4 if lit else 3, world_center=(0, 1, 0),
                   world_half=(1.5, 1.5, 1.5), lights=1 if lit else None)
    sun = torch.tensor([[0.6, -0.8, 0.0]]) if lit else None
    rng = np.random.default_rng(0)
    h, w, x0 = 32, 24, 5
    depth, normal = _buffers(rng, h, 40)
    albedo = rng.uniform(0, 1, (h, 40, 3)).astype(np.float32)
    direct = rng.uniform(0, 2, (h, 40, 3)).astype(np.float32)
    stored = np.concatenate([depth[..., None], normal, albedo, direct, direct * 1.5, direct], -1)[None]
    full_cam = _params(width=40, height=h)[None]
    slices = {"depth": slice(0, 1), "normal": slice(1, 4), "albedo": slice(4, 7), "direct": slice(7, 10),
              "pt": slice(10, 13), "pt_direct": slice(13, 16)}
    cfg = TrainConfig(data=tmp_path, out=tmp_path / "r", world_inputs=True, light_inputs=lit)
    b = split_batch(torch.from_numpy(stored), slices, enc, cfg, scale=torch.ones(1), multiple=16, crop=(w, [x0]),
                    cams=torch.from_numpy(full_cam), lights=sun)
    with torch.no_grad():
        want = netG(b["real_A"])[:, :, b["crop"][0], b["crop"][1]]
    # The runtime's way: the crop as a frame of its own, its camera over its own pixels (x0 in the source).
    crop_cam = _params(width=w, height=h, x0=x0, source=(40, h))
    from diviewer.contract.padding import pad_camera_params, pad_nhwc

    frame = pad_nhwc(stored[:, :, x0:x0 + w, :10], 16)
    cam_p = pad_camera_params(crop_cam[None], w, h, 16)
    ref = ReferenceGI(netG, enc, {"target": "indirect", "divide_albedo": True})
    captured = {}
    netG.register_forward_hook(lambda m, i, o: captured.update(x=i[0]))  # returns None: the output stays
    with torch.no_grad():
        ref(torch.from_numpy(frame), torch.ones(1), torch.from_numpy(cam_p), sun)
        got = netG(captured["x"])[:, :, b["crop"][0], b["crop"][1]]
    np.testing.assert_allclose(captured["x"].numpy(), b["real_A"].numpy(), atol=1e-5)
    np.testing.assert_allclose(got.numpy(), want.numpy(), atol=1e-5)


def test_fourier_features_of_the_world_position_train_export_and_run(tmp_path):
    """world_frequencies: recorded in the checkpoint's network, exported with its Sin and Cos and verified against
    PyTorch, run by the runtime; refused without world inputs or out of range, naming the field."""
    from train.test_trainer import quiet, tiny

    from diviewer.contract.runtime import NeuralGI
    from diviewer.train.export import export
    from diviewer.train.trainer import train

    data, _ = _world_dataset(tmp_path)
    out = tmp_path / "run"
    r = train(tiny(data, out, world_inputs=True, world_frequencies=4), log=quiet)
    assert r["val"] is not None and np.isfinite(r["val"]["psnr_tm"])
    ck = load_checkpoint(out / "last.ckpt")
    assert ck["model_args"]["frequencies"] == 4 and ck["config"]["world_frequencies"] == 4
    assert ck["netG"]["down.0.0.weight"].shape[1] == 16 + 24
    card = export(out / "last.ckpt", tmp_path / "m.onnx", log=quiet)
    assert card["verification"]["max_rel_to_peak"] < 1e-4 and card["verification"]["zero_light_max"] == 0.0
    from diviewer.bench.onnx_tools import network_inputs

    assert card["world_frequencies"] == 4 and network_inputs(card) == 16 + 24  # the bench's FLOPs count them
    import onnx

    ops = {n.op_type for n in onnx.load(str(tmp_path / "m.onnx")).graph.node}
    assert {"Sin", "Cos"} <= ops
    model = NeuralGI(tmp_path / "m.onnx")
    frame = np.load(data / "frames" / "000008.npy").astype(np.float32)[..., :10]
    config = json.loads((data / "manifest.json").read_text())["frame_list"][8]["config"]["camera"]
    y = model.run(frame, light_scale=1.0, camera=NeuralGI.camera(config, 32, 32))
    assert y.shape == (32, 32, 3) and np.isfinite(y).all()
    with pytest.raises(DiviewerError, match="train.world_frequencies: needs world_inputs"):
        tiny(data, tmp_path / "r2", world_frequencies=2)
    with pytest.raises(DiviewerError, match="train.world_frequencies: must be a whole number from 0 to 12"):
        tiny(data, tmp_path / "r2", world_inputs=True, world_frequencies=13)


def test_world_inputs_need_the_light_scale(tmp_path):
    from train.test_trainer import tiny

    with pytest.raises(DiviewerError, match="world_inputs"):
        tiny(tmp_path, tmp_path / "r", world_inputs=True, light_scale=False)


def test_light_inputs_need_world_inputs(tmp_path):
    from train.test_trainer import tiny

    with pytest.raises(DiviewerError, match="light_inputs"):
        tiny(tmp_path, tmp_path / "r", light_inputs=True)


def test_light_planes_hold_each_parameter_over_the_surfaces():
    depth = torch.tensor([[[[0.0, 2.0], [5.0, 0.0]]], [[[1.0, 1.0], [1.0, 1.0]]]])
    lights = torch.tensor([[0.0, -1.0, 0.5], [1.0, 0.0, 0.0]])
    planes = light_planes(lights, depth)
    assert planes.shape == (2, 3, 2, 2)
    np.testing.assert_array_equal(planes[0, :, 0, 1].numpy(), [0.0, -1.0, 0.5])
    assert not planes[0, :, 0, 0].any() and not planes[0, :, 1, 1].any()  # no surface: 0, as the world planes
    assert torch.equal(planes[1], lights[1].reshape(3, 1, 1).expand(3, 2, 2))


def _lit_dataset(tmp_path: Path):
    """_world_dataset with the sun turned differently in every frame (encoding 4 has something to read)."""
    data, scene = _world_dataset(tmp_path)
    m = json.loads((data / "manifest.json").read_text())
    for k, f in enumerate(m["frame_list"]):
        a = 0.3 * k - 1.2
        f["config"]["lights"][0]["direction"] = [float(np.sin(a)), -1.0, float(np.cos(a))]
    (data / "manifest.json").write_text(json.dumps(m))
    return data, scene


def test_a_run_trains_on_light_inputs_and_the_runtime_feeds_them(tmp_path):
    """Encoding 4 end to end: training records the lights' count and three more input planes, export verifies the
    graph with the frames' lights as its fourth input, and the runtime needs them and reads them."""
    from train.test_trainer import quiet, tiny

    from diviewer.evaluation.evaluate import evaluate
    from diviewer.contract.runtime import NeuralGI
    from diviewer.scene.lights import light_params
    from diviewer.train.export import export
    from diviewer.train.trainer import train

    data, scene = _lit_dataset(tmp_path)
    out = tmp_path / "run"
    r = train(tiny(data, out, world_inputs=True, light_inputs=True), log=quiet)
    assert r["val"] is not None and np.isfinite(r["val"]["psnr_tm"])
    ck = load_checkpoint(out / "last.ckpt")
    assert ck["model_args"]["in_channels"] == 19 and ck["config"]["light_inputs"] is True
    assert ck["encoding"]["version"] == 4 and ck["encoding"]["lights"] == len(scene.default.lights) == 1
    assert train(tiny(data, out, world_inputs=True, light_inputs=True, epochs=3), resume=True,
                 log=quiet)["step"] == 6
    card = export(out / "last.ckpt", tmp_path / "m.onnx", log=quiet)
    assert card["encoding"]["version"] == 4 and card["verification"]["max_rel_to_peak"] < 1e-4
    assert card["verification"]["zero_light_max"] == 0.0
    model = NeuralGI(tmp_path / "m.onnx")
    assert model.lit and [i.name for i in model.session.get_inputs()] == ["buffers", "light_scale", "camera", "light"]
    frame = np.load(data / "frames" / "000008.npy").astype(np.float32)[..., :10]
    config = json.loads((data / "manifest.json").read_text())["frame_list"][8]["config"]
    camera = NeuralGI.camera(config["camera"], 32, 32)
    lights = model.lights(config)
    enc = ck["encoding"]
    np.testing.assert_array_equal(lights, light_params(config["lights"], enc["world_center"], enc["world_half"]))
    y = model.run(frame, light_scale=2.0, camera=camera, light=lights)
    turned = model.run(frame, light_scale=2.0, camera=camera, light=-lights)
    assert np.isfinite(y).all() and not np.allclose(y, turned)  # the network reads where the light is
    with pytest.raises(ValueError, match="lights"):
        model.run(frame, light_scale=2.0, camera=camera)
    with pytest.raises(ValueError, match="light"):
        model.lights({"lights": []})
    summary = evaluate(tmp_path / "m.onnx", data, split="val", out=tmp_path / "e.json", log=lambda *_: None)
    assert summary["frames"] == 2 and np.isfinite(summary["methods"]["neural"]["psnr_tm"]["mean"])


@pytest.fixture(scope="module")
def cornell_world_model(tmp_path_factory):
    """A tiny encoding-3 model of the cornell scene file (trained two epochs on synthetic frames)."""
    from train.test_trainer import quiet, tiny

    from diviewer.train.export import export
    from diviewer.train.trainer import train

    tmp = tmp_path_factory.mktemp("cw")
    data, _ = _world_dataset(tmp, scene="cornell")
    train(tiny(data, tmp / "run", world_inputs=True), log=quiet)
    export(tmp / "run" / "last.ckpt", tmp / "cw.onnx", log=quiet)
    return data, tmp / "cw.onnx"


def test_eval_scores_a_world_model_on_a_dataset(cornell_world_model, tmp_path):
    from diviewer.evaluation.evaluate import evaluate

    data, model = cornell_world_model
    summary = evaluate(model, data, split="val", out=tmp_path / "e.json", log=lambda *_: None)
    assert summary["frames"] == 2 and np.isfinite(summary["methods"]["neural"]["psnr_tm"]["mean"])


@pytest.mark.gl
@pytest.mark.parametrize("res", ["48x32", "40x56"])
def test_render_and_the_gl_pass_feed_the_camera(gl_context, cornell_world_model, tmp_path, res):
    """`render --model` runs the GL pack and NeuralPass: the camera goes in at the GI size, any shape."""
    from diviewer.cli import main
    from diviewer.imageio import read_exr

    _, model = cornell_world_model
    w, h = (int(v) for v in res.split("x"))
    assert main(["render", "--scene", "cornell", "--model", str(model), "--res", res, "--out", str(tmp_path / "r")]) == 0
    neural = read_exr(tmp_path / "r" / "neural.exr")
    assert neural.shape == (h, w, 3) and np.all(np.isfinite(neural))


@pytest.mark.gl
def test_render_feeds_an_encoding_4_model_the_frames_lights(gl_context, tmp_path):
    """`render --model` with a model that takes the lights: the GL pass gives it the scene's lights (cornell's sun)
    with the camera."""
    from train.test_trainer import quiet, tiny

    from diviewer.cli import main
    from diviewer.imageio import read_exr
    from diviewer.train.export import export
    from diviewer.train.trainer import train

    data, scene = _world_dataset(tmp_path, scene="cornell")
    m = json.loads((data / "manifest.json").read_text())
    sun = dataclasses.asdict(scene.default.lights[0])
    for k, f in enumerate(m["frame_list"]):  # the scene's own light, turned a little each frame
        f["config"]["lights"] = [{"name": sun["name"], "type": "directional", "color": list(sun["color"]),
                                  "irradiance": sun["irradiance"],
                                  "direction": [0.1 * k - 0.4, *sun["direction"][1:]]}]
    (data / "manifest.json").write_text(json.dumps(m))
    train(tiny(data, tmp_path / "run", world_inputs=True, light_inputs=True), log=quiet)
    export(tmp_path / "run" / "last.ckpt", tmp_path / "lit.onnx", log=quiet)
    assert main(["render", "--scene", "cornell", "--model", str(tmp_path / "lit.onnx"), "--res", "48x32",
                 "--out", str(tmp_path / "r")]) == 0
    neural = read_exr(tmp_path / "r" / "neural.exr")
    assert neural.shape == (32, 48, 3) and np.all(np.isfinite(neural))


def test_light_inputs_refuse_a_frame_without_the_scenes_lights(tmp_path):
    """Every frame must describe the scene's lights for encoding 4: one that does not is named, one line."""
    from train.test_trainer import quiet, tiny

    from diviewer.train.trainer import train

    data, _ = _lit_dataset(tmp_path)
    m = json.loads((data / "manifest.json").read_text())
    m["frame_list"][3]["config"]["lights"] = []
    (data / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(DiviewerError, match="frame 3's configuration has not the scene's 1 light"):
        train(tiny(data, tmp_path / "run", world_inputs=True, light_inputs=True), log=quiet)
