"""Tests for diviewer.train.trainer: the pix2pix loop shrunk to a few steps on a synthetic dataset."""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import math
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from diviewer.data.dataset import CHANNELS, FORMAT, FORMAT_VERSION, Dataset, write_frame  # noqa: E402
from diviewer.contract.encoding import fit_exposure  # noqa: E402
from diviewer.errors import DiviewerError  # noqa: E402
from diviewer.train import trainer  # noqa: E402
from diviewer.train.checkpoint import build_generator_from_checkpoint, load_checkpoint  # noqa: E402
from diviewer.commands.train import add_parser as add_train_parser, run as run_train  # noqa: E402
from diviewer.train.config import TrainConfig  # noqa: E402
from diviewer.train.distributed import epoch_batches  # noqa: E402
from diviewer.train.report import CSV_COLUMNS, validate  # noqa: E402
from diviewer.train.targets import ALBEDO_FLOOR, compose_radiance, raw_exposure, target_radiance  # noqa: E402
from diviewer.train.trainer import train  # noqa: E402

RES = 32
FAR = 10.0
SPLITS = ["train"] * 8 + ["val"] * 2
SCENE_TOML = """
[scene]
name = "NAME"
[camera]
position = [0, 0, 5]
target = [0, 0, 0]
near = 0.05
far = 10
[materials.m]
albedo = [0.5, 0.5, 0.5]
[meshes.box]
shape = "box"
size = [1, 1, 1]
[[objects]]
name = "box"
mesh = "box"
material = "m"
[[lights]]
type = "directional"
name = "sun"
direction = [0, -1, 0]
irradiance = 2.0
"""
"""The scene make_dataset's manifest records (its lights give each frame's light scale: encoding 2)."""


def _frame(seed: int, res: int = RES) -> np.ndarray:
    """Smooth analytic buffers: a curved surface facing the camera, lit by a light that moves with the seed."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:res, 0:res] / (res - 1.0)
    geometry = (xx - 0.1) ** 2 + (yy - 0.1) ** 2 > 0.04  # a background corner
    depth = np.where(geometry, 2.0 + xx + 0.5 * yy, 0.0)
    n = np.stack([xx - 0.5, yy - 0.5, np.ones_like(xx)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    angle = rng.uniform(-0.8, 0.8)
    light = np.array([math.sin(angle), 0.3, math.cos(angle)])
    light /= np.linalg.norm(light)
    albedo = np.stack([0.2 + 0.6 * xx, np.full_like(xx, 0.5), 0.2 + 0.6 * yy], -1)
    direct = albedo * np.clip(n @ light, 0, None)[..., None] * 2.0
    pt_direct = direct * 0.97
    pt = pt_direct + 0.3 * albedo * (0.5 + 0.5 * np.sin(angle + 3 * xx))[..., None]
    g = geometry[..., None]
    planes = [depth[..., None], n * g, albedo * g, direct * g, pt * g, pt_direct * g]
    return np.concatenate(planes, -1).astype(np.float16)


def make_dataset(root: Path, scene: str = "synthetic", seed0: int = 0, res: int = RES,
                 splits: list[str] = SPLITS) -> Dataset:
    """A dataset folder like `diviewer capture` writes, with analytic frames (no GL, no Mitsuba)."""
    root.mkdir(parents=True)
    # _frame's light has strength 2: the light scale of every frame (encoding 2 divides by it)
    sun = {"type": "directional", "name": "sun", "direction": [0, -1, 0], "color": [1, 1, 1], "irradiance": 2.0}
    frames = [{"index": i, "split": s, "seed": seed0 + i,
               "config": {"camera": {"position": [0, 0, 5], "near": 0.05, "far": FAR}, "lights": [sun], "objects": []}}
              for i, s in enumerate(splits)]
    manifest = {
        "format": FORMAT, "format_version": FORMAT_VERSION, "scene": scene, "scene_hash": f"hash-of-{scene}",
        "scene_file": str(root / f"{scene}.toml"), "scene_toml": SCENE_TOML.replace("NAME", scene),
        "resolution": [res, res], "channels": [list(c) for c in CHANNELS], "dtype": "float16", "gt": "pt",
        "spp": 4, "max_depth": 4, "seed": seed0, "frames": len(frames), "split_fractions": [0.8, 0.2, 0.0],
        "render_settings": {}, "frame_list": frames,
    }
    (root / "manifest.json").write_text(json.dumps(manifest))
    ds = Dataset(root)
    for f in frames:
        write_frame(ds, f["index"], _frame(f["seed"], res), {"index": f["index"], "split": f["split"]})
    return ds


def tiny(data: Path, out: Path, **kw) -> TrainConfig:
    """A shrunk run: K=4, a small discriminator, 2 steps per epoch (8 train frames, batch 4), CPU."""
    return TrainConfig(**{"data": data, "out": out, "K": 4, "ndf": 8, "epochs": 2, "batch_size": 4,
                          "device": "cpu", **kw})


def quiet(*_args) -> None:
    pass


@pytest.fixture(scope="module", autouse=True)
def _one_thread():
    """Tiny tensors gain nothing from threads, and a busy machine makes OpenMP's spinning threads crawl."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("train") / "data"
    make_dataset(root)
    return root


@pytest.fixture(scope="module")
def run(data, tmp_path_factory):
    """One finished 2-epoch run shared by the tests that only read its files."""
    out = tmp_path_factory.mktemp("run") / "run"
    result = train(tiny(data, out), log=quiet)
    return out, result


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.slow
def test_run_writes_metrics_curves_and_checkpoints(run):
    out, result = run
    assert result["epoch"] == 2 and result["step"] == 4 and len(result["losses"]) == 4
    rows = read_csv(out / "metrics.csv")
    assert list(rows[0]) == list(CSV_COLUMNS)
    assert [(float(r["epoch"]), int(r["step"])) for r in rows] == [(1.0, 2), (2.0, 4)]
    for r in rows:
        for k in ("loss_D", "loss_G_GAN", "loss_G_L1", "val_mse", "val_ssim", "val_mse_tm", "val_psnr_tm",
                  "val_ssim_tm"):
            assert math.isfinite(float(r[k])), k
        assert 0 < float(r["val_ssim_tm"]) <= 1 and float(r["val_mse_tm"]) > 0
    from PIL import Image

    with Image.open(out / "curves.png") as im:
        assert im.format == "PNG" and im.width > 2 * im.height
        colours = np.unique(np.asarray(im.convert("RGB")).reshape(-1, 3), axis=0)
        assert len(colours) > 3  # axes, labels and coloured lines were drawn
    assert (out / "last.ckpt").is_file() and (out / "best.ckpt").is_file()
    assert result["best"] == pytest.approx(max(float(r["val_ssim_tm"]) for r in rows))


def test_checkpoints_are_self_describing_and_weights_only(run, data):
    out, _ = run
    ds = Dataset(data)
    for name in ("last.ckpt", "best.ckpt"):
        ckpt = torch.load(out / name, weights_only=True)
        assert ckpt["format"] == "diviewer-checkpoint"
        assert ckpt["dataset"]["hash"] == ds.hash
        assert ckpt["dataset"]["scene"] == "synthetic" and ckpt["dataset"]["scene_hash"] == "hash-of-synthetic"
        assert ckpt["model_args"]["K"] == 4 and ckpt["model_args"]["levels"] == 5  # 32 px -> 1x1 bottleneck
        assert ckpt["net_config"]["target"] == "full" and ckpt["config"]["K"] == 4
        assert {"netG", "netD", "optG", "optD", "rng", "data_order", "versions", "val", "encoding"} <= set(ckpt)
        assert set(ckpt["rng"][0]) == {"torch", "cuda", "numpy", "python"}
        assert "torch" in ckpt["versions"] and "diviewer" in ckpt["versions"]
    last = load_checkpoint(out / "last.ckpt")
    assert last["epoch"] == 2 and last["step"] == 4 and last["data_order"] == {
        "seed": 0, "epoch": 2, "batch": 0, "world": 1, "batch_size": 4}
    # The encoding was fixed from the train split: exposure from its GL direct light, depth from the far plane.
    _, train_arr = ds.array("train")
    # Encoding 2 (the default): fitted on the direct light divided by each frame's light scale (2 here).
    assert last["encoding"]["version"] == 2
    assert last["encoding"]["exposure"] == pytest.approx(
        fit_exposure([f[..., ds.slices["direct"]].astype(np.float32) / 2.0 for f in train_arr]))
    assert last["encoding"]["depth_scale"] == FAR


def test_rebuilt_generator_reproduces_the_recorded_validation(run, data):
    out, _ = run
    ckpt = load_checkpoint(out / "best.ckpt")
    netG, enc, meta = build_generator_from_checkpoint(ckpt)
    assert not netG.training and meta["target"] == "full" and meta["scene"] == "synthetic"
    assert enc.to_dict() == ckpt["encoding"]
    ds = Dataset(data)
    _, val = ds.array("val")
    cfg = TrainConfig.from_dict(ckpt["config"])
    from diviewer.data.scales import light_scales

    _, train_arr = ds.array("train")
    tm = None if enc.version < 2 else raw_exposure(ds, train_arr)  # validation's tone map, as eval fits it
    again = validate(netG, val, ds.slices, enc, cfg, torch.device("cpu"), scales=light_scales(ds, ds.indices("val")),
                     tonemap_exposure=tm)
    assert again == pytest.approx(ckpt["val"], rel=1e-6)  # the weights that produced the recorded metrics
    x = torch.randn(2, 10, RES, RES)
    netG2, _, _ = build_generator_from_checkpoint(out / "best.ckpt")
    with torch.no_grad():
        assert torch.equal(netG(x), netG2(x))  # eval mode: deterministic, no dropout


@pytest.mark.slow
def test_resume_equals_continuous_training(data, tmp_path):
    # 3 epochs of 2 steps straight, against: stop after 3 steps (inside epoch 2), resume to the end.
    straight = train(tiny(data, tmp_path / "a", epochs=3), log=quiet)
    first = train(tiny(data, tmp_path / "b", epochs=3, max_steps=3), log=quiet)
    mid = load_checkpoint(tmp_path / "b" / "last.ckpt")
    assert first["step"] == 3 and mid["data_order"]["epoch"] == 1 and mid["data_order"]["batch"] == 1
    second = train(tiny(data, tmp_path / "b", epochs=3), resume=True, log=quiet)
    assert second["step"] == 6 and [r["step"] for r in second["losses"]] == [4, 5, 6]

    def curve(losses):
        return np.array([[r["loss_D"], r["loss_G_GAN"], r["loss_G_L1"]] for r in losses])

    np.testing.assert_allclose(curve(first["losses"] + second["losses"]), curve(straight["losses"]),
                               rtol=1e-5, atol=1e-6)
    a, b = load_checkpoint(tmp_path / "a" / "last.ckpt"), load_checkpoint(tmp_path / "b" / "last.ckpt")
    for net in ("netG", "netD"):
        for k, v in a[net].items():
            torch.testing.assert_close(b[net][k], v, rtol=1e-5, atol=1e-6, msg=f"{net}.{k}")
    for opt in ("optG", "optD"):
        for i, s in a[opt]["state"].items():
            torch.testing.assert_close(b[opt]["state"][i]["exp_avg_sq"], s["exp_avg_sq"], rtol=1e-4, atol=1e-9)
    assert b["val"] == pytest.approx(a["val"], rel=1e-5)
    # metrics.csv: the resumed run has the same epoch rows, plus the row where the first part stopped.
    rows_a, rows_b = read_csv(tmp_path / "a" / "metrics.csv"), read_csv(tmp_path / "b" / "metrics.csv")
    assert [r["step"] for r in rows_b] == ["2", "3", "4", "6"]
    ends = [r for r in rows_b if r["step"] != "3"]
    for ra, rb in zip(rows_a, ends, strict=True):
        for k in ("epoch", "step", "loss_D", "loss_G_GAN", "loss_G_L1", "val_ssim_tm"):
            assert float(rb[k]) == pytest.approx(float(ra[k]), rel=1e-5), k


def test_a_run_resumed_on_other_hardware_records_both(data, tmp_path):
    from diviewer.train.checkpoint import atomic_save

    train(tiny(data, tmp_path / "r", epochs=2, max_steps=2), log=quiet)
    ckpt = load_checkpoint(tmp_path / "r" / "last.ckpt")
    assert ckpt["trained_on"]["device"] == "cpu" and ckpt["trained_on"]["autocast"] == "fp32"
    gpu = {"device": "cuda", "name": "NVIDIA H100", "autocast": "bf16", "torch_threads": None}
    atomic_save({**ckpt, "trained_on": gpu}, tmp_path / "r" / "last.ckpt")  # as if the first part ran there
    train(tiny(data, tmp_path / "r", epochs=2), resume=True, log=quiet)
    after = load_checkpoint(tmp_path / "r" / "last.ckpt")["trained_on"]
    assert after["device"] == "cpu" and after["before"] == gpu


def test_ctrl_c_saves_at_a_step_boundary_and_resumes_exactly(run, data, tmp_path, monkeypatch):
    straight_out, straight = run  # the same settings, run straight through
    found = signal.getsignal(signal.SIGINT)  # SIG_IGN when the suite runs in the background (nohup, &)
    calls = []
    real_split = trainer.split_batch

    def split_then_interrupt(*args, **kw):
        calls.append(1)
        if len(calls) == 3:  # the training loop's batches: steps 1, 2, then inside step 3
            os.kill(os.getpid(), signal.SIGINT)
        return real_split(*args, **kw)

    monkeypatch.setattr(trainer, "split_batch", split_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        train(tiny(data, tmp_path / "b", epochs=2), log=quiet)
    monkeypatch.setattr(trainer, "split_batch", real_split)
    assert signal.getsignal(signal.SIGINT) is found  # the handler the trainer found is back
    assert load_checkpoint(tmp_path / "b" / "last.ckpt")["step"] == 3  # step 3 finished, then saved
    rest = train(tiny(data, tmp_path / "b", epochs=2), resume=True, log=quiet)
    assert [r["step"] for r in rest["losses"]] == [4]
    assert rest["losses"][0] == pytest.approx(straight["losses"][3], rel=1e-5)
    a, b = load_checkpoint(straight_out / "last.ckpt"), load_checkpoint(tmp_path / "b" / "last.ckpt")
    for k, v in a["netG"].items():
        torch.testing.assert_close(b["netG"][k], v, rtol=1e-5, atol=1e-6)


DDP_SCRIPT = """
import json, os, sys, torch, torch.distributed as dist
from diviewer.train import trainer
params = []
class Adam(torch.optim.Adam):  # remember each rank's parameters to compare them afterwards
    def __init__(self, p, **kw):
        p = list(p); super().__init__(p, **kw); params.append(p)
torch.optim.Adam = Adam
dist.init_process_group("gloo")  # kept open across the runs below
data, out = sys.argv[1], sys.argv[2]
def run(name, resume=False, **kw):
    params.clear()
    cfg = trainer.TrainConfig(data=data, out=f"{out}/{name}", K=4, ndf=8, epochs=3, batch_size=2, device="cpu", **kw)
    r = trainer.train(cfg, resume=resume, log=lambda *a: None)
    return {"step": r["step"], "sums": [sum(float(x.detach().double().sum()) for x in p) for p in params]}
res = {"straight": run("a"), "first": run("b", max_steps=3), "resumed": run("b", resume=True)}
with open(f"{out}/rank{dist.get_rank()}.json", "w") as f:
    json.dump(res, f)
dist.destroy_process_group()
# Leave without the interpreter's teardown: once in ~10 runs torch's C++ threads aborted there ("terminate called
# without an active exception") after every result was written (2026-11-24), failing a run that had passed.
sys.stdout.flush(); sys.stderr.flush(); os._exit(0)
"""


@pytest.mark.slow
def test_torchrun_two_cpu_processes_stay_in_sync_and_resume_exactly(data, tmp_path):
    script = tmp_path / "ddp.py"
    script.write_text(DDP_SCRIPT)
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2", str(script),
           str(data), str(tmp_path)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    r0, r1 = (json.loads((tmp_path / f"rank{r}.json").read_text()) for r in (0, 1))
    assert r0 == r1  # gradients are all-reduced: both ranks hold the same weights after every run
    assert r0["straight"]["step"] == 6  # 8 frames over 2 ranks at batch 2: 2 steps per epoch
    assert r0["resumed"]["step"] == 6 and r0["resumed"]["sums"] == pytest.approx(r0["straight"]["sums"], rel=1e-6)
    ckpt = load_checkpoint(tmp_path / "a" / "last.ckpt")
    assert ckpt["data_order"]["world"] == 2 and len(ckpt["rng"]) == 2  # every rank's random state
    assert [r["step"] for r in read_csv(tmp_path / "a" / "metrics.csv")] == ["2", "4", "6"]  # rank 0 alone writes


def test_indirect_target_divided_by_albedo_trains(data, tmp_path):
    result = train(tiny(data, tmp_path / "ind", epochs=1, target="indirect", divide_albedo=True), log=quiet)
    assert result["step"] == 2 and math.isfinite(result["val"]["ssim_tm"])
    netG, enc, meta = build_generator_from_checkpoint(tmp_path / "ind" / "last.ckpt")
    assert meta["target"] == "indirect" and meta["divide_albedo"] is True and meta["net_config"]["target"] == "indirect"


def test_residual_target_trains_and_exports_a_graph_that_adds_the_gl_direct_light(data, tmp_path):
    """target "residual": netG learns pt - GL direct; the exported graph composes it exactly as "indirect" (GL direct
    + prediction, clamped at 0) and export's verification against training's functions passes."""
    from diviewer.contract.runtime import read_metadata
    from diviewer.train.export import export

    result = train(tiny(data, tmp_path / "res", epochs=1, target="residual", divide_albedo=True), log=quiet)
    assert result["step"] == 2 and math.isfinite(result["val"]["ssim_tm"])
    card = export(tmp_path / "res" / "last.ckpt", tmp_path / "res.onnx", log=quiet)
    assert card["target"] == "residual" and read_metadata(tmp_path / "res.onnx")["target"] == "residual"


def test_target_and_composition_invert_each_other():
    rng = np.random.default_rng(1)
    albedo = rng.uniform(0, 1, (4, 4, 3)) * (rng.uniform(size=(4, 4, 1)) > 0.3)  # some albedo-0 pixels
    pt_direct = rng.uniform(0, 2, (4, 4, 3))
    pt = pt_direct + rng.uniform(0, 1, (4, 4, 3))
    for target, divide in (("full", False), ("indirect", False), ("indirect", True)):
        y = target_radiance(pt, pt_direct, albedo, target, divide)
        np.testing.assert_allclose(compose_radiance(y, pt_direct, albedo, target, divide), pt, rtol=1e-12)
        as_torch = (torch.from_numpy(a) for a in (pt, pt_direct, albedo))
        yt = target_radiance(*as_torch, target, divide)
        np.testing.assert_allclose(yt.numpy(), y, rtol=1e-12)
    # residual: what the path tracer adds to the GL direct light (which differs from its own direct light, here
    # brighter in places, so the residual is negative there), composed back onto that same GL direct light
    gl_direct = pt_direct * rng.uniform(0.5, 1.5, (4, 4, 3))
    for divide in (False, True):
        y = target_radiance(pt, pt_direct, albedo, "residual", divide, gl_direct)
        assert (y < 0).any()
        np.testing.assert_allclose(compose_radiance(y, gl_direct, albedo, "residual", divide), pt, rtol=1e-12)
    with pytest.raises(ValueError, match="GL direct"):
        target_radiance(pt, pt_direct, albedo, "residual", True)
    # divided by albedo: where the albedo is tiny the divisor is the floor, so noise is not amplified
    y = target_radiance(pt, pt_direct, albedo, "indirect", True)
    assert np.abs(y).max() <= np.abs(pt - pt_direct).max() / ALBEDO_FLOOR + 1e-12


def test_epoch_batches_are_a_pure_function_and_ranks_partition_them():
    a = epoch_batches(10, 3, seed=7, batch_size=4)
    assert a == epoch_batches(10, 3, seed=7, batch_size=4) and a != epoch_batches(10, 4, seed=7, batch_size=4)
    assert [len(b) for b in a] == [4, 4, 2] and sorted(sum(a, [])) == list(range(10))
    ranks = [epoch_batches(10, 3, seed=7, batch_size=2, rank=r, world=2) for r in (0, 1)]
    assert len(ranks[0]) == len(ranks[1]) == 3  # equal step counts: no rank waits on a collective
    assert set(sum(ranks[0], [])) | set(sum(ranks[1], [])) == set(range(10))


def test_bad_checkpoints_are_user_errors_naming_the_file(run, tmp_path):
    out, _ = run
    missing = tmp_path / "nope.ckpt"
    with pytest.raises(DiviewerError, match="nope.ckpt"):
        load_checkpoint(missing)
    truncated = tmp_path / "truncated.ckpt"
    blob = (out / "last.ckpt").read_bytes()
    truncated.write_bytes(blob[: len(blob) // 2])
    with pytest.raises(DiviewerError, match="truncated.ckpt"):
        load_checkpoint(truncated)
    garbage = tmp_path / "garbage.ckpt"
    garbage.write_bytes(b"not a checkpoint at all")
    with pytest.raises(DiviewerError, match="garbage.ckpt"):
        build_generator_from_checkpoint(garbage)
    foreign = tmp_path / "foreign.ckpt"
    torch.save({"state_dict": {"w": torch.zeros(1)}}, foreign)
    with pytest.raises(DiviewerError, match="foreign.ckpt.*not a diviewer checkpoint"):
        load_checkpoint(foreign)


@pytest.mark.slow
def test_cli_trains_resumes_and_refuses_conflicts(data, tmp_path):
    ap = argparse.ArgumentParser()
    add_train_parser(ap.add_subparsers(dest="command"))
    out = tmp_path / "cli"
    common = ["train", "--data", str(data), "--out", str(out), "--device", "cpu", "--ndf", "8", "--no-world-inputs"]
    args = ap.parse_args([*common, "--k", "4", "--epochs", "1", "--seed", "3"])
    assert args.func is run_train
    assert run_train(args) == 0
    assert load_checkpoint(out / "last.ckpt")["step"] == 2
    # a second fresh run into the same folder would overwrite it
    with pytest.raises(DiviewerError, match="--resume"):
        run_train(ap.parse_args([*common, "--k", "4", "--epochs", "2"]))
    # --resume inherits --epochs: the run is complete, nothing more to do
    assert run_train(ap.parse_args([*common, "--resume"])) == 0
    assert load_checkpoint(out / "last.ckpt")["step"] == 2
    # --resume without --k/--seed takes them from the checkpoint and trains one more epoch
    assert run_train(ap.parse_args([*common, "--epochs", "2", "--resume"])) == 0
    ckpt = load_checkpoint(out / "last.ckpt")
    assert ckpt["step"] == 4 and ckpt["config"]["K"] == 4 and ckpt["config"]["seed"] == 3
    assert [r["step"] for r in read_csv(out / "metrics.csv")] == ["2", "4"]
    with pytest.raises(DiviewerError, match="K: 4 -> 8"):
        run_train(ap.parse_args([*common, "--epochs", "3", "--resume", "--k", "8"]))


def test_resume_refuses_another_dataset(run, tmp_path):
    out, _ = run
    other = tmp_path / "other"
    make_dataset(other, scene="elsewhere", seed0=100)
    with pytest.raises(DiviewerError, match="another dataset"):
        train(tiny(other, out, epochs=3), resume=True, log=quiet)


def test_config_validation_names_the_field(tmp_path):
    with pytest.raises(DiviewerError, match="train.divide_albedo"):
        TrainConfig(data=tmp_path, out=tmp_path, divide_albedo=True)
    with pytest.raises(DiviewerError, match="train.batch_size"):
        TrainConfig(data=tmp_path, out=tmp_path, batch_size=0)
    with pytest.raises(DiviewerError, match="train.ssim_exposure.*ssim_weight > 0"):
        TrainConfig(data=tmp_path, out=tmp_path, ssim_exposure="metered")
    with pytest.raises(DiviewerError, match="train.ssim_exposure.*one of scene, metered, both"):
        TrainConfig(data=tmp_path, out=tmp_path, ssim_weight=0.1, ssim_exposure="viewer")
    from diviewer.train.config import CHOICES
    from diviewer.train.losses import SSIM_EXPOSURES
    assert CHOICES["ssim_exposure"] == SSIM_EXPOSURES, "the config's choices are the loss's"
    cfg = TrainConfig(data=tmp_path, out=tmp_path / "r", K=16, max_steps=5)
    assert TrainConfig.from_dict(cfg.to_dict()) == cfg


def test_a_folder_left_from_an_earlier_run_is_not_replaced(run, data, tmp_path, capsys):
    """best.ckpt (or metrics.csv, curves.png) without last.ckpt: refused, with or without --resume."""
    from diviewer.cli import main

    out = tmp_path / "old"
    out.mkdir()
    best = out / "best.ckpt"
    shutil.copyfile(run[0] / "best.ckpt", best)
    before = best.read_bytes()
    for resume in (False, True):
        with pytest.raises(DiviewerError, match="best.ckpt.*earlier run"):
            train(tiny(data, out, epochs=1), resume=resume, log=quiet)
    argv = ["train", "--data", str(data), "--out", str(out), "--k", "4", "--ndf", "8", "--device", "cpu",
            "--lr-decay", "none"]  # the default recipe's decay starts at step 20,000, beyond this tiny run
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "best.ckpt" in err[0] and "Traceback" not in err[0]
    assert best.read_bytes() == before and sorted(p.name for p in out.iterdir()) == ["best.ckpt"]


def test_an_untrainable_dataset_is_refused_before_the_run_folder_exists(tmp_path):
    small = tmp_path / "small"
    make_dataset(small, res=16)
    out = tmp_path / "run16"
    with pytest.raises(DiviewerError, match=r"16x16.*at least 24 px"):
        train(tiny(small, out), log=quiet)
    assert not out.exists()


def test_resumed_epoch_rows_average_only_their_own_epoch(run, data, tmp_path):
    """After a resume from an epoch end, the next row's losses are that epoch's alone (issue 17 #10)."""
    straight_out, _ = run
    train(tiny(data, tmp_path / "r", epochs=1), log=quiet)
    assert load_checkpoint(tmp_path / "r" / "last.ckpt")["accum"]["n"] == 0  # saved after the sums were reset
    train(tiny(data, tmp_path / "r", epochs=2), resume=True, log=quiet)
    rows_a, rows_b = read_csv(straight_out / "metrics.csv"), read_csv(tmp_path / "r" / "metrics.csv")
    assert [r["step"] for r in rows_b] == ["2", "4"]
    for ra, rb in zip(rows_a, rows_b, strict=True):
        for k in ("loss_D", "loss_G_GAN", "loss_G_L1"):
            assert float(rb[k]) == pytest.approx(float(ra[k]), rel=1e-5), k


@pytest.mark.slow
@pytest.mark.parametrize("options", [
    {"gan_weight": 0.0},
    {"gan_weight": 0.5, "gan_mode": "lsgan"},
    {"recon_loss": "l2", "recon_space": "linear"},
    {"recon_loss": "l1", "recon_space": "linear"},
    {"n_layers_D": 2, "norm_D": "instance", "d_lr": 8e-4},
    {"upsample": "resize", "norm": "instance"},
    {"upsample": "shuffle", "norm": "none"},
    {"precision": "bf16"},
    {"gan_weight": 0.0, "ssim_weight": 0.5, "target": "indirect", "divide_albedo": True, "precision": "bf16"},
    {"gan_weight": 0.0, "ssim_weight": 0.5, "ssim_exposure": "both", "target": "indirect", "divide_albedo": True},
], ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()))
def test_each_training_option_trains_and_is_recorded(data, tmp_path, options):
    result = train(tiny(data, tmp_path / "o", epochs=1, **options), log=quiet)
    assert result["step"] == 2 and math.isfinite(result["val"]["ssim_tm"])
    ckpt = load_checkpoint(tmp_path / "o" / "last.ckpt")
    for k, v in options.items():
        assert ckpt["config"][k] == v, k
    net = ckpt["net_config"]
    assert (net["upsample"], net["norm"], net["norm_D"], net["n_layers_D"]) == (
        options.get("upsample", "transpose"), options.get("norm", "batch"), options.get("norm_D", "batch"),
        options.get("n_layers_D", 3))
    assert ckpt["loss_config"]["reconstruction"] == options.get("recon_loss", "l1")
    rows = read_csv(tmp_path / "o" / "metrics.csv")
    adversarial = options.get("gan_weight", 1.0) > 0
    for k in ("loss_D", "loss_G_GAN", "D_acc_real", "D_acc_fake"):
        assert (rows[-1][k] != "") == adversarial, k
    assert ckpt["loss_config"]["ssim_weight"] == options.get("ssim_weight", 0.0)
    assert ckpt["loss_config"]["ssim_exposure"] == options.get("ssim_exposure", "scene")
    assert (rows[-1]["loss_G_SSIM"] != "") == ("ssim_weight" in options)
    if "ssim_weight" in options:  # 1 - SSIM in [0, 2], times lambda_L1 and the weight
        assert 0.0 < float(rows[-1]["loss_G_SSIM"]) <= 2.0 * 100.0 * options["ssim_weight"]
    if adversarial:
        assert 0 <= float(rows[-1]["D_acc_real"]) <= 1 and 0 <= float(rows[-1]["D_acc_fake"]) <= 1
    netG, _, _ = build_generator_from_checkpoint(ckpt)  # the generator rebuilds with its options
    assert (netG.upsample, netG.norm) == (net["upsample"], net["norm"])


def test_gan_weight_zero_leaves_netD_untouched(data, tmp_path):
    train(tiny(data, tmp_path / "g0", epochs=1, gan_weight=0.0), log=quiet)
    ckpt = load_checkpoint(tmp_path / "g0" / "last.ckpt")
    assert ckpt["optD"]["state"] == {}  # netD never stepped


def test_train_frames_uses_the_first_frames_and_is_checked_on_resume(data, tmp_path):
    out = tmp_path / "tf"
    train(tiny(data, out, epochs=1, train_frames=4), log=quiet)
    ckpt = load_checkpoint(out / "last.ckpt")
    assert ckpt["dataset"]["train_indices"] == sorted(Dataset(data).indices("train"))[:4]
    assert ckpt["step"] == 1 and ckpt["config"]["train_frames"] == 4  # 4 frames at batch 4: one step per epoch
    with pytest.raises(DiviewerError, match="train_frames: 4 -> None"):
        train(tiny(data, out, epochs=2), resume=True, log=quiet)
    with pytest.raises(DiviewerError, match="only 8 train frames"):
        train(tiny(data, tmp_path / "many", train_frames=9), log=quiet)
    assert not (tmp_path / "many").exists()


def test_a_shape_option_cannot_change_on_resume(data, tmp_path):
    out = tmp_path / "shape"
    train(tiny(data, out, epochs=1), log=quiet)
    for change, text in (({"upsample": "resize"}, "upsample: 'transpose' -> 'resize'"),
                         ({"n_layers_D": 2}, "n_layers_D: 3 -> 2"), ({"norm": "none"}, "norm: 'batch' -> 'none'")):
        with pytest.raises(DiviewerError, match=text):
            train(tiny(data, out, epochs=2, **change), resume=True, log=quiet)


def test_early_stopping_stops_and_marks_the_curve(data, tmp_path):
    # Validate every step; with patience 1 the run stops at the first validation that is not better.
    out = tmp_path / "es"
    result = train(tiny(data, out, epochs=20, val_every_steps=1, patience=1, lr=0.05), log=quiet)
    rows = read_csv(out / "metrics.csv")
    ssim = [float(r["val_ssim_tm"]) for r in rows]
    assert result["stopped_early"] and result["step"] < 40
    assert ssim[-1] <= max(ssim[:-1])  # the last validation did not improve ...
    assert all(b > a for a, b in zip(ssim[:-2], ssim[1:-1]))  # ... and every one before it did
    assert result["best"] == pytest.approx(max(ssim))
    again = train(tiny(data, out, epochs=20, val_every_steps=1, patience=1, lr=0.05), resume=True, log=quiet)
    assert again["step"] == result["step"]  # stopped early stays stopped


def test_cli_maps_the_options_onto_the_config(data, tmp_path):
    ap = argparse.ArgumentParser()
    add_train_parser(ap.add_subparsers(dest="command"))
    out = tmp_path / "cli_opts"
    args = ap.parse_args(["train", "--data", str(data), "--out", str(out), "--device", "cpu", "--k", "4", "--ndf", "8",
                          "--no-world-inputs", "--epochs", "1", "--gan-weight", "0", "--recon-loss", "l2", "--recon-space", "linear",
                          "--n-layers-d", "2", "--d-lr", "1e-3", "--upsample", "resize", "--norm", "instance",
                          "--train-frames", "8", "--patience", "3", "--val-every-steps", "1", "--precision", "fp32", "--ssim-weight", "0.5",
                          "--ssim-exposure", "metered", "--lr-decay", "none"])  # the default recipe decays from step 20,000
    assert run_train(args) == 0
    cfg = load_checkpoint(out / "last.ckpt")["config"]
    assert (cfg["gan_weight"], cfg["recon_loss"], cfg["recon_space"], cfg["n_layers_D"], cfg["d_lr"]) == (
        0.0, "l2", "linear", 2, 1e-3)
    assert (cfg["upsample"], cfg["norm"], cfg["train_frames"], cfg["patience"], cfg["val_every_steps"]) == (
        "resize", "instance", 8, 3, 1)
    assert (cfg["ssim_weight"], cfg["ssim_exposure"]) == (0.5, "metered")


def test_cosine_schedule_runs_from_lr_to_the_floor_and_none_is_constant(data, tmp_path):
    from diviewer.train.step import LR_FLOOR, lr_factor

    cos = TrainConfig(data=data, out=tmp_path / "c", lr_decay="cosine")
    assert lr_factor(cos, 0, 100) == 1.0
    assert lr_factor(cos, 50, 100) == pytest.approx(0.5 * (1 + LR_FLOOR))
    assert lr_factor(cos, 100, 100) == pytest.approx(LR_FLOOR) and lr_factor(cos, 500, 100) == pytest.approx(LR_FLOOR)
    factors = [lr_factor(cos, s, 100) for s in range(101)]
    assert all(a >= b for a, b in zip(factors, factors[1:]))  # never rises
    flat = TrainConfig(data=data, out=tmp_path / "n")
    assert {lr_factor(flat, s, 100) for s in range(0, 101, 10)} == {1.0}


@pytest.mark.slow
def test_cosine_decay_is_applied_and_resumes_on_the_same_curve(data, tmp_path):
    # 3 epochs of 2 steps: the last step runs at the factor of step 5 of 6; a run stopped after 3 steps
    # and resumed ends with the same weights as the straight one (the rate is a function of the step).
    from diviewer.train.step import lr_factor

    straight = train(tiny(data, tmp_path / "a", epochs=3, lr_decay="cosine"), log=quiet)
    train(tiny(data, tmp_path / "b", epochs=3, max_steps=3, lr_decay="cosine"), log=quiet)
    resumed = train(tiny(data, tmp_path / "b", epochs=3, lr_decay="cosine"), resume=True, log=quiet)
    assert straight["step"] == resumed["step"] == 6
    a, b = load_checkpoint(tmp_path / "a" / "last.ckpt"), load_checkpoint(tmp_path / "b" / "last.ckpt")
    cfg = TrainConfig(data=data, out=tmp_path / "a", lr_decay="cosine")
    assert a["optG"]["param_groups"][0]["lr"] == pytest.approx(cfg.lr * lr_factor(cfg, 5, 6))
    for k, v in a["netG"].items():
        torch.testing.assert_close(b["netG"][k], v, rtol=1e-5, atol=1e-6, msg=k)
    with pytest.raises(DiviewerError, match="lr_decay"):  # the schedule is part of the run
        train(tiny(data, tmp_path / "b", epochs=4), resume=True, log=quiet)


def test_a_delayed_cosine_is_constant_then_anneals_to_the_floor(data, tmp_path):
    from diviewer.train.step import LR_FLOOR, constant_until, lr_factor

    cfg = TrainConfig(data=data, out=tmp_path / "c", lr_decay="cosine", lr_decay_start=40)
    assert {lr_factor(cfg, s, 100) for s in range(41)} == {1.0}
    assert lr_factor(cfg, 70, 100) == pytest.approx(0.5 * (1 + LR_FLOOR))  # half way through the anneal
    assert lr_factor(cfg, 100, 100) == pytest.approx(LR_FLOOR) and lr_factor(cfg, 90, 30) == LR_FLOOR
    factors = [lr_factor(cfg, s, 100) for s in range(101)]
    assert all(a >= b for a, b in zip(factors, factors[1:]))
    assert constant_until(cfg, 40) and not constant_until(cfg, 41)
    assert constant_until({"lr_decay": "none"}, 10**6) and constant_until({}, 5)
    with pytest.raises(DiviewerError, match="lr_decay_start"):
        TrainConfig(data=data, out=tmp_path / "c", lr_decay="cosine", lr_decay_start=-1)


@pytest.mark.slow
def test_a_constant_run_resumes_into_an_anneal_like_a_straight_run(data, tmp_path):
    # 3 epochs of 2 steps: a constant run stopped after 3 steps and resumed into a cosine that starts
    # at step 3 ends with the weights of a straight run on that schedule; an anneal that would
    # rewrite steps already taken is refused, naming the field.
    straight = train(tiny(data, tmp_path / "a", epochs=3, lr_decay="cosine", lr_decay_start=3), log=quiet)
    train(tiny(data, tmp_path / "b", epochs=3, max_steps=3), log=quiet)
    resumed = train(tiny(data, tmp_path / "b", epochs=3, lr_decay="cosine", lr_decay_start=3), resume=True,
                    log=quiet)
    assert straight["step"] == resumed["step"] == 6
    a, b = load_checkpoint(tmp_path / "a" / "last.ckpt"), load_checkpoint(tmp_path / "b" / "last.ckpt")
    assert b["config"]["lr_decay"] == "cosine" and b["config"]["lr_decay_start"] == 3
    assert a["optG"]["param_groups"][0]["lr"] < 2e-4 * 0.5
    for k, v in a["netG"].items():
        torch.testing.assert_close(b["netG"][k], v, rtol=1e-5, atol=1e-6, msg=k)
    train(tiny(data, tmp_path / "c", epochs=3, max_steps=3), log=quiet)
    with pytest.raises(DiviewerError, match="lr_decay"):  # step 3 would have run at a lower rate
        train(tiny(data, tmp_path / "c", epochs=3, lr_decay="cosine", lr_decay_start=1), resume=True, log=quiet)


@pytest.mark.slow
def test_a_warm_start_begins_from_the_parents_networks_and_records_it(data, tmp_path):
    # A run onto other frames of the same scene, from a finished run's networks: at a vanishing rate
    # its weights stay the parent's, its encoding is the parent's, and the checkpoint and the model
    # card's recipe record the parent (hash, step, how it was made) instead of a path.
    from diviewer.train.export import ExportSettings, export

    train(tiny(data, tmp_path / "parent", epochs=1), log=quiet)
    more = make_dataset(tmp_path / "more", seed0=100).root  # same scene, other frames
    parent_ckpt = tmp_path / "parent" / "last.ckpt"
    child = train(tiny(more, tmp_path / "child", epochs=1, lr=1e-12, init_from=str(parent_ckpt)), log=quiet)
    assert child["step"] == 2
    a, b = load_checkpoint(parent_ckpt), load_checkpoint(tmp_path / "child" / "last.ckpt")
    assert b["encoding"] == a["encoding"]
    convs = [k for k, v in a["netG"].items() if k.endswith("weight") and v.ndim == 4]
    assert convs
    for k in convs:
        torch.testing.assert_close(b["netG"][k], a["netG"][k], rtol=1e-6, atol=1e-7, msg=k)
    fresh = train(tiny(more, tmp_path / "fresh", epochs=1, lr=1e-12), log=quiet)
    c = load_checkpoint(tmp_path / "fresh" / "last.ckpt")
    assert fresh["step"] == 2 and not torch.allclose(c["netG"][convs[0]], a["netG"][convs[0]])
    init = b["init"]
    assert init["step"] == a["step"] and init["dataset_hash"] == a["dataset"]["hash"] and len(init["checkpoint_sha256"]) == 64
    meta = export(tmp_path / "child" / "best.ckpt", tmp_path / "m.onnx", ExportSettings(), log=quiet)
    rec = meta["recipe"]
    assert "init_from" not in rec["train"] and rec["init"]["step"] == a["step"]
    assert rec["init"]["recipe"]["train"]["K"] == 4 and rec["init"]["recipe"]["capture"] == a["dataset"]["capture"]
    # resumed, the run keeps its record; the parent cannot be swapped under it
    train(tiny(more, tmp_path / "child", epochs=2, lr=1e-12, init_from=str(parent_ckpt)), resume=True, log=quiet)
    assert load_checkpoint(tmp_path / "child" / "last.ckpt")["init"] == init
    with pytest.raises(DiviewerError, match="init_from"):
        train(tiny(more, tmp_path / "child", epochs=3, lr=1e-12), resume=True, log=quiet)


def test_a_warm_start_refuses_another_network_target_scene_or_file(data, tmp_path):
    train(tiny(data, tmp_path / "parent", epochs=1), log=quiet)
    parent = str(tmp_path / "parent" / "last.ckpt")
    cases = [({"K": 8}, "another generator"), ({"target": "indirect"}, "predicts something else"),
             ({"init_from": str(tmp_path / "none.ckpt")}, "no checkpoint")]
    for i, (kw, words) in enumerate(cases):
        with pytest.raises(DiviewerError, match=words) as e:
            train(tiny(data, tmp_path / f"c{i}", epochs=1, **{"init_from": parent, **kw}), log=quiet)
        assert e.value.field == "train.init_from"
    other = make_dataset(tmp_path / "other", scene="other").root
    with pytest.raises(DiviewerError, match="another scene file"):
        train(tiny(other, tmp_path / "c9", epochs=1, init_from=parent), log=quiet)


@pytest.mark.parametrize("asked,index", [("cuda", 0), ("cuda:1", 1), ("auto", 0)])
def test_a_cuda_device_always_has_an_index(data, tmp_path, monkeypatch, asked, index):
    # torch.cuda.set_device and get_rng_state refuse a bare "cuda" (seen on an H100, where every run
    # failed at the first step); faked here: this machine has no GPU.
    from diviewer.train import distributed

    chosen = []
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "set_device", lambda d: chosen.append(d))
    monkeypatch.setattr(torch.backends.cudnn, "benchmark", False)  # setup turns it on: restored after
    monkeypatch.delenv("WORLD_SIZE", raising=False)
    dev = distributed.setup(TrainConfig(data=data, out=tmp_path / "c", device=asked))
    assert dev.device == torch.device("cuda", index) and chosen == [dev.device]


# ---------------------------------------------------------------------------------------------
# Any window shape: random aspect crops of wider frames, padded to the stride as the runtime pads


def make_wide_dataset(root: Path, width: int = 48) -> Dataset:
    """make_dataset's frames cut to RES rows x ``width`` columns (a wide capture, like cornell's 228x128)."""
    ds = make_dataset(root)
    manifest = json.loads((root / "manifest.json").read_text())
    manifest["resolution"] = [width, RES]
    (root / "manifest.json").write_text(json.dumps(manifest))
    ds = Dataset(root)
    for f in ds.frames:
        write_frame(ds, f["index"], _frame(f["seed"], width)[:RES], {"index": f["index"], "split": f["split"]})
    return ds


def test_crop_plan_is_a_pure_function_within_the_range():
    from diviewer.train.targets import crop_plan

    cfg = TrainConfig(data=Path("d"), out=Path("o"), aspect_crops=(9 / 16, 16 / 9))
    plans = [crop_plan(cfg, e, b, 4, 128, 228) for e in range(3) for b in range(20)]
    assert plans == [crop_plan(cfg, e, b, 4, 128, 228) for e in range(3) for b in range(20)]  # resumable
    widths = {w for w, _ in plans}
    assert min(widths) >= 72 and max(widths) <= 227 and len(widths) > 10
    assert all(0 <= o <= 228 - w for w, left in plans for o in left)
    assert crop_plan(dataclasses.replace(cfg, aspect_crops=None), 0, 0, 4, 128, 228) is None


def test_masked_loss_counts_the_frames_pixels_only():
    from diviewer.train.losses import reconstruction_loss

    fake, real = torch.zeros(2, 3, 4, 8), torch.ones(2, 3, 4, 8)
    mask = torch.zeros(1, 1, 4, 8)
    mask[..., 2:6] = 1.0
    real[..., :2] = 100.0  # on the padding: not counted
    assert reconstruction_loss(fake, real, mask=mask).item() == pytest.approx(1.0)
    assert reconstruction_loss(fake, real, "l2", mask=mask).item() == pytest.approx(1.0)


def test_training_on_aspect_crops_of_wide_frames(tmp_path):
    """A 48x32 capture trained on random-width crops (one width per batch, padded to the stride 32 with the
    loss on the frame's pixels): the network's depth follows the height, validation runs on whole padded
    frames, and the export runs at the capture's own shape and at others."""
    from diviewer.contract.runtime import NeuralGI
    from diviewer.train.export import export

    make_wide_dataset(tmp_path / "wide")
    seen = []
    real_split = trainer.split_batch

    def spy(x16, *a, **kw):
        b = real_split(x16, *a, **kw)
        seen.append((kw.get("crop"), tuple(b["real_A"].shape), None if b["mask"] is None else float(b["mask"].sum())))
        return b

    trainer.split_batch = spy
    try:
        result = train(tiny(tmp_path / "wide", tmp_path / "run", aspect_crops=(0.5, 1.5)), log=quiet)
    finally:
        trainer.split_batch = real_split
    assert result["val"] is not None and all(math.isfinite(v) for v in result["val"].values())
    ckpt = load_checkpoint(tmp_path / "run" / "last.ckpt")
    assert ckpt["model_args"]["levels"] == 5 and ckpt["config"]["aspect_crops"] == (0.5, 1.5)
    for crop, shape, valid in seen:
        w, left = crop
        assert 16 <= w <= 48 and shape[2] == 32 and shape[3] % 32 == 0
        assert valid == (None if w % 32 == 0 else 32 * w)
    out = tmp_path / "wide.onnx"
    export(tmp_path / "run" / "best.ckpt", out, log=quiet)
    model = NeuralGI(out)
    rng = np.random.default_rng(0)
    for h, w in [(32, 48), (32, 57), (24, 24)]:
        x = rng.uniform(0.1, 2.0, (h, w, 10)).astype(np.float32)
        y = model.run(x, light_scale=2.0)
        assert y.shape == (h, w, 3) and np.all(np.isfinite(y))


def test_light_scale_and_aspect_crop_settings():
    with pytest.raises(DiviewerError, match="aspect_crops"):
        TrainConfig(data=Path("d"), out=Path("o"), aspect_crops=(2.0, 1.0))
    with pytest.raises(DiviewerError, match="light_scale"):
        TrainConfig(data=Path("d"), out=Path("o"), light_scale="yes")
    # a checkpoint from before these settings trained on encoding 1, whole frames
    old = {k: v for k, v in tiny(Path("d"), Path("o")).to_dict().items() if k not in ("light_scale", "aspect_crops")}
    cfg = TrainConfig.from_dict(old)
    assert cfg.light_scale is False and cfg.aspect_crops is None
    p = argparse.ArgumentParser()
    add_train_parser(p.add_subparsers())
    args = p.parse_args(["train", "--data", "d", "--out", "o", "--no-light-scale", "--aspect-crops", "9/16:16/9"])
    assert args.light_scale is False and args.aspect_crops == pytest.approx((9 / 16, 16 / 9))


def test_encoding_2_training_needs_light(tmp_path):
    ds = make_dataset(tmp_path / "dark")
    manifest = json.loads((tmp_path / "dark" / "manifest.json").read_text())
    for f in manifest["frame_list"]:
        f["config"]["lights"] = []
    (tmp_path / "dark" / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DiviewerError, match="no-light-scale"):
        train(tiny(tmp_path / "dark", tmp_path / "run"), log=quiet)
    assert ds is not None


def test_output_gain_fits_the_targets_exposure_and_trains_exports_and_resumes(data, tmp_path):
    """--output-gain: the gain puts the 99th percentile of the train split's exposed target (indirect / albedo /
    light scale x exposure) at 1; the batches' encoded targets use it, export verifies the graph that decodes with
    it, and a resumed run keeps it."""
    from diviewer.contract.encoding import Encoding, encode_radiance
    from diviewer.train.export import export

    out = tmp_path / "gain"
    kw = {"output_gain": True, "target": "indirect", "divide_albedo": True}
    train(tiny(data, out, **kw), log=quiet)
    ck = load_checkpoint(out / "last.ckpt")
    enc = Encoding.from_dict(ck["encoding"])
    ds = Dataset(data)
    targets = []
    for i in ds.indices("train"):
        f = ds.load(i)
        targets.append((f["pt"] - f["pt_direct"]) / np.clip(f["albedo"], ALBEDO_FLOOR, 1) / 2.0 * enc.exposure)
    # the frames' indirect light is ~1/5 of their direct light: the gain lifts it to the direct light's range
    assert enc.output_gain == pytest.approx(fit_exposure(targets), rel=0.05) and enc.output_gain > 2
    assert ck["config"]["output_gain"] is True
    t = targets[0] / enc.exposure
    assert np.abs(encode_radiance(t, enc.output())).max() > 2 * np.abs(encode_radiance(t, enc)).max()
    assert train(tiny(data, out, **kw, epochs=3), resume=True, log=quiet)["step"] == 6
    card = export(out / "last.ckpt", tmp_path / "gain.onnx", log=quiet)
    assert card["encoding"]["output_gain"] == enc.output_gain and card["verification"]["max_rel_to_peak"] < 1e-4
    with pytest.raises(DiviewerError, match="output_gain"):
        train(tiny(data, out, **{**kw, "output_gain": False}, epochs=4), resume=True, log=quiet)


def test_a_run_whose_target_lies_low_is_told_of_output_gain(data):
    """fit_encoding with a run's settings: indirect light at a tenth of the frames' own gives a gain above GAIN_NOTE,
    and a run without --output-gain is told so, once; the frames as they are (gain < 4) and a run with the gain are
    not."""
    from diviewer.data.scales import light_scales
    from diviewer.train.targets import GAIN_NOTE, fit_encoding

    ds = Dataset(data)
    idx = ds.indices("train")
    _, arr = ds.array("train", idx)
    scales = light_scales(ds, idx)
    pt, pt_direct = ds.slices["pt"], ds.slices["pt_direct"]
    dim = arr.astype(np.float32)
    dim[..., pt] = dim[..., pt_direct] + 0.1 * (dim[..., pt] - dim[..., pt_direct])
    dim = dim.astype(arr.dtype)
    run = tiny(data, data, target="indirect", divide_albedo=True)
    told = []
    enc = fit_encoding(ds, idx, dim, scales, output_of=run, say=told.append)
    assert len(told) == 1 and "--output-gain" in told[0] and enc.output_gain == 1
    gained = fit_encoding(ds, idx, dim, scales, output_of=dataclasses.replace(run, output_gain=True), say=told.append)
    assert len(told) == 1 and gained.output_gain >= GAIN_NOTE
    assert f"x {gained.output_gain:.3g}" in told[0]
    fit_encoding(ds, idx, arr, scales, output_of=run, say=told.append)
    assert len(told) == 1  # the frames as made: a gain near 3.7, below the note's threshold
