"""Dataset capture: reproducible plans, split rules, resume after SIGKILL, corrupted frames, shards."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from diviewer.cli import main
from diviewer.data.capture import CaptureSettings, capture, merge, plan_frames
from diviewer.data.dataset import Dataset
from diviewer.errors import DiviewerError
from diviewer.scene import load_scene
from diviewer.scene.sampler import in_test_stretch

# Planning and the refusals need no path tracer; rendering a dataset does (skipped by what this machine has).
needs_mitsuba = pytest.mark.mitsuba  # tests/conftest.py skips it where mitsuba is not installed

TINY = dict(width=32, height=32, spp=4, max_depth=4)


def npy_bytes(root: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((root / "frames").glob("*.npy"))}


def test_plan_is_reproducible_and_keeps_test_objects_out_of_training():
    scene = load_scene("cornell")
    s = CaptureSettings(frames=60, seed=3)
    a, b = plan_frames(scene, s), plan_frames(scene, s)
    assert a == b
    assert plan_frames(scene, CaptureSettings(frames=60, seed=4)) != a
    counts = {k: sum(f["split"] == k for f in a) for k in ("train", "val", "test")}
    assert counts == {"train": 48, "val": 6, "test": 6}
    r = scene.ranges.objects["center"]
    mesh = {f["index"]: next(o["mesh"] for o in f["config"]["objects"] if o["name"] == "center") for f in a}
    assert all(mesh[f["index"]] in r.train_meshes for f in a if f["split"] != "test")
    assert all(mesh[f["index"]] in r.test_meshes for f in a if f["split"] == "test")


@pytest.mark.slow
def test_atrium_test_stretches_never_in_training():
    scene = load_scene("atrium")
    plan = plan_frames(scene, CaptureSettings(frames=200, seed=1))
    path = scene.ranges.camera
    train = [f["path_s"] for f in plan if f["split"] == "train"]
    test = [f["path_s"] for f in plan if f["split"] == "test"]
    assert train and test
    assert not any(in_test_stretch(path, s) for s in train)
    assert all(in_test_stretch(path, s) for s in test)
    val = [f["path_s"] for f in plan if f["split"] == "val"]
    assert any(in_test_stretch(path, s) for s in val) and not all(in_test_stretch(path, s) for s in val)


@pytest.mark.slow
@needs_mitsuba
def test_small_capture_writes_a_sound_dataset(gl_context, tmp_path):
    out = tmp_path / "ds"
    summary = capture("cornell", out, CaptureSettings(frames=16, seed=0, **TINY), log=lambda *_: None)
    assert summary["present"] == 16 and sum(summary["per_split"].values()) == 16
    ds = Dataset(out)
    assert ds.check() == []
    f = ds.load(ds.indices("train")[0])
    assert f["depth"].shape == (32, 32) and f["pt"].shape == (32, 32, 3)
    assert f["pt"].mean() > f["pt_direct"].mean() * 1.01, "full GI carries more light than direct alone"
    sidecar = json.loads(ds.path(ds.indices("train")[0], ".json").read_text())
    assert sidecar["pt_estimator"] == "one_pass", "the truth in one pass (split_path), and the sidecar says so"
    m = json.loads((out / "manifest.json").read_text())
    assert m["scene_hash"] == load_scene("cornell").file_hash and "versions" in m and len(m["frame_list"]) == 16
    # each distinct object list stored once (diviewer.data.object_lists); read back, every frame's is the plan's
    distinct = {json.dumps(f["config"]["objects"], sort_keys=True) for f in ds.frames}  # cornell's objects move
    assert len(m["object_lists"]) == len(distinct)
    assert all(set(f["config"]["objects"]) == {"list"} for f in m["frame_list"])
    plan = plan_frames(load_scene("cornell"), CaptureSettings(frames=16, seed=0, **TINY))
    planned = {f["index"]: f["config"] for f in plan}
    assert all(f["config"] == json.loads(json.dumps(planned[f["index"]])) for f in ds.frames)
    assert list((out / "thumbs").glob("*.png"))
    # running it again renders nothing and changes nothing
    before = npy_bytes(out)
    again = capture("cornell", out, CaptureSettings(frames=16, seed=0, **TINY), log=lambda *_: None)
    assert again["rendered"] == 0 and npy_bytes(out) == before


@needs_mitsuba
def test_other_settings_in_the_same_folder_are_refused(gl_context, tmp_path):
    out = tmp_path / "ds"
    capture("cornell", out, CaptureSettings(frames=2, seed=0, **TINY), log=lambda *_: None)
    with pytest.raises(DiviewerError, match="spp"):
        capture("cornell", out, CaptureSettings(frames=2, seed=0, **{**TINY, "spp": 8}), log=lambda *_: None)


def _capture_cmd(out: Path, frames: int) -> list[str]:
    return [sys.executable, "-m", "diviewer", "capture", "--scene", "cornell", "--frames", str(frames), "--res", "32",
            "--spp", "4", "--max-depth", "4", "--seed", "5", "--out", str(out)]


@pytest.mark.slow
@needs_mitsuba
def test_killed_capture_resumes_to_the_uninterrupted_result(gl_context, tmp_path):
    frames = 10
    ref = tmp_path / "ref"
    subprocess.run(_capture_cmd(ref, frames), check=True, capture_output=True)
    out = tmp_path / "killed"
    proc = subprocess.Popen(_capture_cmd(out, frames), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while time.time() < deadline and len(list((out / "frames").glob("*.json"))) < 3 and proc.poll() is None:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done = len(list((out / "frames").glob("*.json")))
    assert 0 < done < frames, f"kill should land mid-way ({done} frames done)"
    r = subprocess.run(_capture_cmd(out, frames), capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert npy_bytes(out) == npy_bytes(ref)
    assert not [p for p in (out / "frames").iterdir() if p.name.startswith(".")], "temporary files left behind"
    assert Dataset(out).check() == []


@needs_mitsuba
def test_corrupted_frame_is_reported_and_rendered_again(gl_context, tmp_path, capsys):
    out = tmp_path / "ds"
    settings = CaptureSettings(frames=4, seed=2, **TINY)
    capture("cornell", out, settings, log=lambda *_: None)
    good = npy_bytes(out)
    ds = Dataset(out)
    p1, p2 = ds.path(1), ds.path(2)
    p1.write_bytes(p1.read_bytes()[:200])  # truncated
    raw = bytearray(p2.read_bytes())
    raw[-10] ^= 0xFF  # one flipped byte in the pixels
    p2.write_bytes(bytes(raw))
    assert main(["data", "check", str(out)]) == 1
    report = capsys.readouterr().out
    assert "frame      1" in report and "frame      2" in report
    summary = capture("cornell", out, settings, log=lambda *_: None)
    assert summary["rendered"] == 2
    assert npy_bytes(out) == good
    assert main(["data", "check", str(out)]) == 0


@pytest.mark.slow
@needs_mitsuba
def test_shards_merge_into_the_whole(gl_context, tmp_path):
    settings = CaptureSettings(frames=6, seed=9, **TINY)
    whole = tmp_path / "whole"
    capture("cornell", whole, settings, log=lambda *_: None)
    a, b = tmp_path / "a", tmp_path / "b"
    capture("cornell", a, settings, shard=(1, 2), log=lambda *_: None)
    capture("cornell", b, settings, shard=(2, 2), log=lambda *_: None)
    assert len(Dataset(a).indices()) == 3 and len(Dataset(b).indices()) == 3
    merged = tmp_path / "merged"
    merge([a, b], merged, log=lambda *_: None)
    assert npy_bytes(merged) == npy_bytes(whole)
    assert Dataset(merged).check() == []


def test_vxgi_ground_truth_in_the_same_format(tmp_path):
    """--gt vxgi: the VXGI image in the pt channels, GL direct in pt_direct, settings in the manifest."""
    out = tmp_path / "v"
    settings = CaptureSettings(frames=3, gt="vxgi", vxgi_resolution=32, **TINY)
    capture("cornell", out, settings, log=lambda *_: None)
    ds = Dataset(out)
    assert ds.check() == [] and len(ds.indices()) == 3
    assert ds.manifest["gt"] == "vxgi" and ds.manifest["vxgi"]["resolution"] == 32
    for i in ds.indices():
        f = ds.load(i)
        assert np.all(np.isfinite(f["pt"]))
        np.testing.assert_array_equal(f["pt_direct"], f["direct"])
        indirect = f["pt"] - f["pt_direct"]
        assert indirect.min() >= -1e-3 and indirect.mean() > 1e-3  # float16 rounding aside, light was added
    # resumable like any capture: nothing left to render
    assert capture("cornell", out, settings, log=lambda *_: None)["rendered"] == 0
    with pytest.raises(DiviewerError, match="--gt"):
        capture("cornell", tmp_path / "w", CaptureSettings(frames=1, gt="nope", **TINY), log=lambda *_: None)
