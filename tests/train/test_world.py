"""World-space inputs (encoding version 3): the planes as the ablation's numpy reconstruction computes them, on
crops and padding as the runtime will pad, in training batches, and a run that trains on them."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from diviewer.errors import DiviewerError  # noqa: E402
from diviewer.padding import pad_before, pad_index  # noqa: E402
from diviewer.scene import camera as cam  # noqa: E402
from diviewer.scene.loader import load_scene  # noqa: E402
from diviewer.train.checkpoint import load_checkpoint  # noqa: E402
from diviewer.train.world import shift_cameras, world_planes  # noqa: E402
from tool_modules import load_tool  # noqa: E402

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
    tool = load_tool("experiments/world_inputs")
    depth, normal = _buffers(np.random.default_rng(x0), 128, 128)
    center, half = np.array([0.0, 1.0, 0.0]), 1.2
    pos, nrm = tool.world_buffers(depth, normal, CAMERA, (228, 128), (x0, 0), center, half)
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


def test_shift_cameras_is_camera_params_of_the_crop():
    full = torch.from_numpy(np.stack([_params(width=228, height=128)] * 2))
    got = shift_cameras(full, [17, 80], (14, 0), (100, 128)).numpy()
    for i, x0 in enumerate((17, 80)):
        np.testing.assert_allclose(got[i], _params(width=100, height=128, x0=x0, source=(228, 128), pad=(14, 0)),
                                   atol=1e-5)


def _world_dataset(tmp_path: Path):
    """test_trainer's synthetic dataset with a loadable scene file and whole cameras in its frames."""
    from train.test_trainer import SCENE_TOML, make_dataset

    ds = make_dataset(tmp_path / "data", scene="worldscene")
    scene_file = ds.root / "worldscene.toml"
    scene_file.write_text(SCENE_TOML.replace("NAME", "worldscene"))
    m = json.loads((ds.root / "manifest.json").read_text())
    m["scene_hash"] = load_scene(scene_file).file_hash
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
    # ... and export says plainly that it does not write such a model yet
    with pytest.raises(DiviewerError, match="world-space inputs"):
        export(out / "last.ckpt", tmp_path / "m.onnx", log=quiet)


def test_world_inputs_need_the_light_scale(tmp_path):
    from train.test_trainer import tiny

    with pytest.raises(DiviewerError, match="world_inputs"):
        tiny(tmp_path, tmp_path / "r", world_inputs=True, light_scale=False)
