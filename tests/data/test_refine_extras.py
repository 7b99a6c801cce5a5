"""A refinement's extra samples rendered elsewhere: the job carries what they need, the samples are the ones refine
renders, the refinement from them is refine's own up to their float16 rounding, and what is not this refinement's is
refused, naming the file and the field."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from diviewer.cli import main
from diviewer.data.capture import CaptureSettings, capture
from diviewer.data.dataset import Dataset
from diviewer.data.refine import extras_present, load_extras, refine
from diviewer.data.refine_extras import read_job, render_extras, write_job
from diviewer.errors import DiviewerError

TINY = dict(width=32, height=32, spp=4, max_depth=4)
QUIET = dict(log=lambda *_: None)


def test_a_job_file_that_is_not_one_is_refused_naming_it(tmp_path, capsys):
    bad = tmp_path / "job.json.xz"
    bad.write_text("{}")
    with pytest.raises(DiviewerError, match="not a refinement job") as e:
        read_job(bad)
    assert str(bad) in str(e.value)
    assert main(["data", "render-extras", str(bad), "--out", str(tmp_path / "extras")]) == 2
    assert "not a refinement job" in capsys.readouterr().err and not (tmp_path / "extras").exists()


@pytest.mark.parametrize("frames", ["9:3", "3:3", "-1:4", "a:b", "4"])
def test_refine_job_refuses_a_frame_range_that_is_none_before_any_work(tmp_path, capsys, frames):
    """`data refine-job --frames` takes A:B with 0 <= A < B, refused in one line naming the option before the
    dataset is even read (it does not exist here)."""
    job = tmp_path / "job.json.xz"
    assert main(["data", "refine-job", str(tmp_path / "none"), "--spp", "16", f"--frames={frames}",
                 "--out", str(job)]) == 2
    err = capsys.readouterr().err
    assert "--frames" in err and "A:B" in err and not job.exists()


@pytest.mark.mitsuba
def test_extras_rendered_elsewhere_refine_as_refine_does(gl_context, tmp_path, capsys):
    src = tmp_path / "src"
    capture("cornell", src, CaptureSettings(frames=4, seed=1, **TINY), **QUIET)
    job = tmp_path / "job.json.xz"
    assert main(["data", "refine-job", str(src), "--spp", "16", "--frames", "1:4", "--out", str(job)]) == 0
    assert "job of 3 frames" in capsys.readouterr().out  # frames 1..3 (index 0 is left to this machine)
    j = read_job(job)
    assert j["source_hash"] == Dataset(src).hash and [f["index"] for f in j["frames"]] == [1, 2, 3]
    assert "frame_list" not in j["manifest"] and j["manifest"]["spp"] == 16
    extras = tmp_path / "extras"
    # Two shards; the second stops at a deadline already past: nothing begun, and a later run finishes it.
    assert render_extras(job, extras, (1, 2), **QUIET)["rendered"] == 1  # index 2 (the 1st of 2: index % 2 == 0)
    assert main(["data", "render-extras", str(job), "--out", str(extras), "--shard", "2/2", "--deadline", "0"]) == 0
    assert "done: 0 of 2 frames of the shard" in capsys.readouterr().out
    assert render_extras(job, extras, (2, 2), **QUIET) == {"rendered": 2, "present": 2, "frames": 2,
                                                          "seconds": pytest.approx(0, abs=600)}
    assert extras_present(extras) == {1, 2, 3}
    with pytest.raises(DiviewerError, match="no such folder") as e:
        extras_present(tmp_path / "mistyped")
    assert e.value.field == "--extras"
    # Refined from the extras: only their frames, none rendered; then a plain refine finds them done.
    out, plain = tmp_path / "out", tmp_path / "plain"
    assert main(["data", "refine", str(src), "--spp", "16", "--out", str(out), "--extras", str(extras)]) == 0
    assert "3 to take from" in capsys.readouterr().out
    assert sorted(f.stem for f in (out / "frames").glob("*.json")) == ["000001", "000002", "000003"]
    assert refine(src, out, 16, **QUIET)["rendered"] == 1
    refine(src, plain, 16, **QUIET)
    a, b = Dataset(out), Dataset(plain)
    assert a.hash == b.hash and a.check() == []
    for i in (1, 2, 3):
        fa, fb = a.load(i), b.load(i)
        for name in ("pt", "pt_direct"):  # refine's mean, up to the extras' float16 rounding
            np.testing.assert_allclose(fa[name], fb[name], rtol=2e-3, atol=1e-5)
        np.testing.assert_array_equal(fa["albedo"], fb["albedo"])
        ra, rb = (json.loads(d.path(i, ".json").read_text())["refined"] for d in (a, b))
        assert {k: ra[k] for k in ("from_spp", "extra_spp", "seed", "pt_estimator")} == {
            k: rb[k] for k in ("from_spp", "extra_spp", "seed", "pt_estimator")}
        assert "seconds" not in ra and ra["elsewhere"]["dtype"] == "float16" and "seconds" in rb  # a build's pace
    np.testing.assert_array_equal(a.load(0)["pt"], b.load(0)["pt"])  # rendered here, as plain


@pytest.mark.mitsuba
def test_extras_not_of_this_refinement_are_refused_naming_the_field(gl_context, tmp_path):
    src = tmp_path / "src"
    capture("cornell", src, CaptureSettings(frames=2, seed=1, **TINY), **QUIET)
    job, extras = tmp_path / "job.json.xz", tmp_path / "extras"
    write_job(src, 8, 0, 2, job)
    render_extras(job, extras, **QUIET)
    ds = Dataset(src)
    from diviewer.data.refine import refine_seed
    from diviewer.reference.mitsuba import effective_spp

    seed = refine_seed(ds.frames[0]["seed"], 4)
    load_extras(extras, 0, ds, 8, seed, effective_spp(4))  # this refinement's: read
    with pytest.raises(DiviewerError, match="spp") as e:  # another count
        load_extras(extras, 0, ds, 16, seed, effective_spp(12))
    assert e.value.field == "spp" and "000000.json" in str(e.value)
    with pytest.raises(DiviewerError, match="seed"):
        load_extras(extras, 0, ds, 8, seed + 1, effective_spp(4))
    side = extras / "000000.json"
    info = json.loads(side.read_text())
    side.write_text(json.dumps({**info, "source_hash": "0" * 64}))
    with pytest.raises(DiviewerError, match="source_hash"):
        load_extras(extras, 0, ds, 8, seed, effective_spp(4))
    shutil.copy(extras / "000001.npy", extras / "000000.npy")  # another frame's array under its name
    with pytest.raises(DiviewerError, match="checksum"):
        load_extras(extras, 0, ds, 8, seed, effective_spp(4))
    with pytest.raises(DiviewerError, match="absent"):
        load_extras(extras, 5, ds, 8, seed, effective_spp(4))
