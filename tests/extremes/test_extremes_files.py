"""Files at the extremes: swapped, truncated and corrupt datasets, manifests, frame.json files and
checkpoints (pickle payloads included): one error or one reported problem, never a traceback or a leak."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from diviewer.cli import main
from diviewer.data.capture import CaptureSettings, build_manifest
from diviewer.data.dataset import Dataset, write_frame
from diviewer.errors import DiviewerError
from diviewer.scene import load_scene


def make_dataset(root, frames: int = 6, width: int = 8, height: int = 4) -> Dataset:
    """A small sound dataset written without GL or Mitsuba: the real manifest, synthetic frames."""
    settings = CaptureSettings(frames=frames, width=width, height=height, split_fractions=(0.5, 0.25, 0.25))
    manifest = build_manifest(load_scene("cornell"), settings)
    root.mkdir(parents=True, exist_ok=True)
    (root / "manifest.json").write_text(json.dumps(manifest))
    ds = Dataset(root)
    rng = np.random.default_rng(0)
    for f in ds.frames:
        arr = rng.uniform(0, 1, (height, width, ds.num_channels)).astype(ds.dtype)
        write_frame(ds, f["index"], arr, {"index": f["index"], "split": f["split"]})
    return ds


@pytest.fixture
def ds(tmp_path):
    return make_dataset(tmp_path / "data")


def _first(ds, split):
    return next(f["index"] for f in ds.frames if f["split"] == split)


def test_sound_dataset_checks_clean(ds):
    assert ds.check() == []


def test_swapped_frames_are_caught(ds, capsys):
    """Issue case 5: a val frame swapped with a train frame (both files) passed `data check`."""
    a, b = _first(ds, "train"), _first(ds, "val")
    for suffix in (".npy", ".json"):
        pa, pb = ds.path(a, suffix), ds.path(b, suffix)
        tmp = pa.with_name("swap")
        pa.rename(tmp), pb.rename(pa), tmp.rename(pb)
    problems = {p.index: p.problem for p in ds.check()}
    assert set(problems) == {a, b} and all("swapped" in p for p in problems.values())
    assert main(["data", "check", str(ds.root)]) == 1
    with pytest.raises(DiviewerError, match="swapped"):
        ds.array("train")  # training refuses it too (without checksums)


def test_swapped_arrays_only_are_caught_by_checksum(ds):
    a, b = _first(ds, "train"), _first(ds, "val")
    pa, pb = ds.path(a), ds.path(b)
    tmp = pa.with_name("swap")
    pa.rename(tmp), pb.rename(pa), tmp.rename(pb)
    assert {p.index for p in ds.check()} == {a, b}


def test_frame_moved_to_another_split_is_caught(ds):
    i = _first(ds, "val")
    info = json.loads(ds.path(i, ".json").read_text())
    ds.path(i, ".json").write_text(json.dumps({**info, "split": "train"}))
    assert [p.index for p in ds.check()] == [i]


@pytest.mark.parametrize("damage", ["truncate", "empty", "garbage", "sidecar_list", "sidecar_garbage",
                                    "nan", "wrong_shape", "no_sidecar"])
def test_damaged_frames_are_reported_not_raised(ds, damage):
    i = ds.frames[0]["index"]
    npy, side = ds.path(i), ds.path(i, ".json")
    if damage == "truncate":
        npy.write_bytes(npy.read_bytes()[:100])
    elif damage == "empty":
        npy.write_bytes(b"")
    elif damage == "garbage":
        npy.write_bytes(b"\x93NUMPY garbage" * 10)
    elif damage == "sidecar_list":
        side.write_text("[1, 2]")
    elif damage == "sidecar_garbage":
        side.write_bytes(b"\xff\x00{")
    elif damage in ("nan", "wrong_shape"):
        arr = np.load(npy)
        arr = arr[:2] if damage == "wrong_shape" else np.where(arr > 0.5, np.nan, arr).astype(arr.dtype)
        np.save(npy, arr)
        info = json.loads(side.read_text())
        from diviewer.data.dataset import sha256_file

        side.write_text(json.dumps({**info, "sha256": sha256_file(npy)}))
    elif damage == "no_sidecar":
        side.unlink()
    assert [p.index for p in ds.check()] == [i]
    assert [p.index for p in ds.check(verify_checksum=False)] == [i] or damage == "truncate"


MANIFEST_DAMAGE = {
    "not_json": lambda m: "{not json",
    "a_list": lambda m: "[]",
    "binary": lambda m: b"\xff\xfe\x00",
    "no_resolution": lambda m: {k: v for k, v in m.items() if k != "resolution"},
    "resolution_str": lambda m: {**m, "resolution": "128"},
    "resolution_zero": lambda m: {**m, "resolution": [0, 4]},
    "resolution_float": lambda m: {**m, "resolution": [8.5, 4]},
    "no_channels": lambda m: {k: v for k, v in m.items() if k != "channels"},
    "channels_bad": lambda m: {**m, "channels": [["depth", "x"]]},
    "channels_missing_direct": lambda m: {**m, "channels": [["depth", 1], ["normal", 3]]},
    "dtype_bad": lambda m: {**m, "dtype": "int8"},
    "no_frame_list": lambda m: {k: v for k, v in m.items() if k != "frame_list"},
    "frame_list_dict": lambda m: {**m, "frame_list": {}},
    "frame_index_str": lambda m: {**m, "frame_list": [{"index": "0", "split": "train"}]},
    "frame_split_bad": lambda m: {**m, "frame_list": [{"index": 0, "split": 7}]},
    "frame_duplicate": lambda m: {**m, "frame_list": [m["frame_list"][0], m["frame_list"][0]]},
    "format_version_str": lambda m: {**m, "format_version": "1"},
    "format_version_new": lambda m: {**m, "format_version": 99},
    "scene_missing": lambda m: {k: v for k, v in m.items() if k != "scene"},
}


@pytest.mark.parametrize("damage", sorted(MANIFEST_DAMAGE))
def test_corrupt_manifest_is_one_line_naming_the_field(ds, damage, capsys):
    path = ds.root / "manifest.json"
    new = MANIFEST_DAMAGE[damage](json.loads(path.read_text()))
    path.write_bytes(new if isinstance(new, bytes) else (new if isinstance(new, str) else json.dumps(new)).encode())
    assert main(["data", "check", str(ds.root)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(path) in err and "Traceback" not in err


def test_truncated_manifest_refuses_to_resume_a_capture(ds, tmp_path, capsys):
    path = ds.root / "manifest.json"
    path.write_text(path.read_text()[:200])
    assert main(["capture", "--scene", "cornell", "--frames", "6", "--res", "8x4", "--out", str(ds.root)]) == 2
    assert "manifest" in capsys.readouterr().err


# --- frame.json (render --config) ---------------------------------------------------------------
FRAME_DAMAGE = {
    "list": [],
    "no_config": {"scene": "cornell"},
    "config_list": {"config": []},
    "lights_int": {"config": {"camera": {}, "lights": 3, "objects": []}},
    "objects_str": {"config": {"camera": {}, "lights": [], "objects": "o"}},
    "camera_str": {"config": {"camera": "front", "lights": [], "objects": []}},
    "user_meshes_list": {"config": {}, "user_meshes": ["a.obj"]},
    "near_zero": {"config": {"camera": {"near": 0.0}, "lights": [], "objects": []}},
    "light_1e39": {"config": {"camera": {}, "lights": [{"type": "point", "position": [0, 1, 0], "intensity": 1e39}],
                              "objects": []}},
}


@pytest.mark.parametrize("damage", sorted(FRAME_DAMAGE))
def test_corrupt_frame_json_is_one_error(tmp_path, damage, capsys):
    cfg = tmp_path / "frame.json"
    cfg.write_text(json.dumps(FRAME_DAMAGE[damage]))
    out = tmp_path / "out"
    assert main(["render", "--res", "8", "--config", str(cfg), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(cfg) in err and not out.exists()


# --- checkpoints ---------------------------------------------------------------------------------
def _ckpt_cases(tmp_path):
    torch = pytest.importorskip("torch")
    import pickle

    flag = tmp_path / "ran"

    class Payload:
        def __reduce__(self):
            return (open, (str(flag), "w"))

    cases = {}
    p = tmp_path / "pickle.ckpt"
    torch.save({"format": "x", "payload": Payload()}, p)
    cases["pickle_payload"] = p
    p = tmp_path / "raw_pickle.ckpt"
    p.write_bytes(pickle.dumps(Payload()))
    cases["raw_pickle"] = p
    p = tmp_path / "list.ckpt"
    torch.save([1, 2, 3], p)
    cases["not_a_dict"] = p
    p = tmp_path / "empty.ckpt"
    p.write_bytes(b"")
    cases["empty"] = p
    p = tmp_path / "half.ckpt"
    torch.save({"format": "diviewer-checkpoint", "netG": {"w": torch.zeros(1000)}}, p)
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    cases["truncated"] = p
    return cases, flag


@pytest.mark.parametrize("case", ["pickle_payload", "raw_pickle", "not_a_dict", "empty", "truncated"])
def test_bad_checkpoints_are_refused_without_running_them(tmp_path, case, capsys):
    cases, flag = _ckpt_cases(tmp_path)
    out = tmp_path / "m.onnx"
    assert main(["export", str(cases[case]), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(cases[case]) in err
    assert not flag.exists() and not out.exists()


def test_export_never_overwrites_its_checkpoint(tmp_path, capsys):
    """Issue cases 1 and 2: --out onto the checkpoint, or a .json that its own card would overwrite."""
    ckpt = tmp_path / "best.ckpt"
    ckpt.write_bytes(b"precious weights")
    odd = tmp_path / "model.onnx"
    shutil.copy(ckpt, odd)
    for out in (ckpt, tmp_path / "model.json", odd, tmp_path / "sub" / ".." / "best.ckpt"):
        source = odd if out == odd else ckpt
        assert main(["export", str(source), "--out", str(out)]) == 2
        assert "--out" in capsys.readouterr().err
    assert ckpt.read_bytes() == b"precious weights" and odd.read_bytes() == b"precious weights"
    assert not (tmp_path / "model.json").exists()
