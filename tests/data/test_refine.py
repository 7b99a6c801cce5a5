"""Refining a dataset's ground truth to more samples: the weighted mean of the capture and the extra render,
a dataset of its own identity, resumable, refusals named."""

from __future__ import annotations

import json

import numpy as np
import pytest

from diviewer.cli import main
from diviewer.data.capture import CaptureSettings, build_manifest, capture
from diviewer.data.dataset import IDENTITY, Dataset, identity
from diviewer.data.refine import refine, refine_seed, refined_manifest
from diviewer.errors import DiviewerError
from diviewer.scene import load_scene

needs_mitsuba = pytest.mark.mitsuba

TINY = dict(width=32, height=32, spp=4, max_depth=4)
QUIET = dict(log=lambda *_: None)


def test_refine_seed_is_a_pure_function_and_differs_from_the_frame_seed():
    assert refine_seed(123, 64) == refine_seed(123, 64)
    assert len({refine_seed(123, 64), refine_seed(124, 64), refine_seed(123, 256), 123}) == 4
    assert 0 <= refine_seed(2**31 - 1, 64) < 2**31


def test_identity_of_other_datasets_is_unchanged():
    """Only a refined manifest carries the record: every other dataset keeps the hash it had."""
    m = build_manifest(load_scene("cornell"), CaptureSettings(frames=4, **TINY))
    assert identity(m) == {k: m.get(k) for k in IDENTITY}
    assert identity({**m, "refined": {"from_spp": 4}})["refined"] == {"from_spp": 4}


@needs_mitsuba
def test_refined_truth_is_the_weighted_mean_of_capture_and_extra_render(gl_context, tmp_path):
    from diviewer.reference import mitsuba as ref
    from diviewer.scene.loader import config_from_dict

    src = tmp_path / "src"
    capture("cornell", src, CaptureSettings(frames=3, seed=1, **TINY), **QUIET)
    out = tmp_path / "refined"
    summary = refine(src, out, 16, **QUIET)
    assert summary["present"] == 3 and summary["rendered"] == 3
    a, b = Dataset(src), Dataset(out)
    assert b.check() == [] and b.manifest["spp"] == 16 and b.manifest["settings"]["spp"] == 16
    assert b.manifest["refined"]["from_spp"] == 4 and b.manifest["refined"]["from_hash"] == a.hash
    # Its own identity: not the source's, not a capture made at 16 spp directly.
    direct16 = build_manifest(load_scene("cornell"), CaptureSettings(frames=3, seed=1, **{**TINY, "spp": 16}))
    assert b.hash != a.hash and identity(b.manifest) != identity(direct16)
    scene = load_scene("cornell")
    for f in a.frames:
        i = f["index"]
        fa, fb = a.load(i), b.load(i)
        for name in ("depth", "normal", "albedo", "direct"):  # GL inputs as captured
            np.testing.assert_array_equal(fa[name], fb[name])
        seed = refine_seed(f["seed"], 4)
        frame = ref.load_frame(scene, config_from_dict(scene, f["config"]), 32, 32)
        e_old, e_new = ref.effective_spp(4), ref.effective_spp(12)
        full, direct, how = frame.full_and_direct(12, seed, 4)  # the one-pass truth (split_path), as refine renders
        assert how == "one_pass"
        for name, extra in (("pt", full), ("pt_direct", direct)):
            want = (e_old * fa[name] + e_new * extra) / (e_old + e_new)
            np.testing.assert_allclose(fb[name], want.astype(np.float16).astype(np.float32), rtol=2e-3, atol=1e-6)
        info = json.loads(b.path(i, ".json").read_text())
        assert info["refined"]["seed"] == seed and info["refined"]["extra_spp"] == e_new
        assert info["refined"]["pt_estimator"] == "one_pass"
    # Resumes: a second run renders nothing; a lost frame is rendered again, the same.
    before = b.path(1).read_bytes()
    assert refine(src, out, 16, **QUIET)["rendered"] == 0
    b.path(1, ".json").unlink()
    assert refine(src, out, 16, **QUIET)["rendered"] == 1 and b.path(1).read_bytes() == before
    # Another count into the same folder is refused, naming what differs.
    with pytest.raises(DiviewerError, match="spp"):
        refine(src, out, 32, **QUIET)


@needs_mitsuba
def test_refine_refusals_name_the_field(gl_context, tmp_path, capsys):
    src = tmp_path / "src"
    capture("cornell", src, CaptureSettings(frames=1, seed=1, **TINY), **QUIET)
    with pytest.raises(DiviewerError, match="above the dataset's 4 spp") as e:
        refined_manifest(Dataset(src), 4)
    assert e.value.field == "--spp"
    with pytest.raises(DiviewerError, match="both the source and the output"):
        refine(src, src, 8, **QUIET)
    assert main(["data", "refine", str(src), "--spp", "2", "--out", str(tmp_path / "x")]) != 0
    assert "--spp" in capsys.readouterr().err
