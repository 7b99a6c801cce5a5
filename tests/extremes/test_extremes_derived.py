"""The derived-dataset commands (`data refine`, `area-direct`, `filter-truth`) against a hostile source: a corrupt
frame (a flipped byte in its pixels or in its header), an incomplete source, an evaluation set, a filtered truth fed
to refine: each refused in one line naming the file and the field, exit 2, before any work, nothing written; and the
truth filter's settings from 0 to float64's largest never writing a non-finite frame."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diviewer.cli import main
from diviewer.data.dataset import Dataset
from diviewer.data.truth_filter import TruthFilter, filter_dataset, filter_irradiance

from tiny_datasets import flip_byte, tiny_capture

COMMANDS = {"refine": ["--spp", "8"], "area-direct": ["--samples", "2"], "filter-truth": []}
QUIET = dict(log=lambda *_: None)


def _run(capsys, command: str, src, out) -> list[str]:
    assert main(["data", command, str(src), "--out", str(out), *COMMANDS[command]]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and not out.exists(), err
    return err


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("offset", [-7, 3])  # a pixel's byte; the .npy header's (the frame was dropped unsaid)
def test_a_flipped_byte_in_the_source_is_refused_naming_the_frame(tmp_path, capsys, command, offset):
    src = tiny_capture(tmp_path / "src")
    flip_byte(src.path(2), offset)
    (err,) = _run(capsys, command, src.root, tmp_path / "out")
    assert "000002.npy" in err and "sha256" in err and "frame 2" in err
    with_partial = main(["data", command, str(src.root), "--out", str(tmp_path / "out"), "--partial",
                         *COMMANDS[command]])
    assert with_partial == 2 and not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_an_incomplete_source_is_refused_without_partial(tmp_path, capsys, command):
    src = tiny_capture(tmp_path / "src")
    src.path(1, ".json").unlink()
    (err,) = _run(capsys, command, src.root, tmp_path / "out")
    assert "incomplete: 2 of 3" in err and "frame_list" in err and "--partial" in err


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_an_evaluation_set_is_refused_as_a_source(tmp_path, capsys, command):
    src = tiny_capture(tmp_path / "set", kind="evalset")
    (err,) = _run(capsys, command, src.root, tmp_path / "out")
    assert "evaluation set" in err and "kind" in err and "manifest.json" in err


def test_refine_refuses_a_filtered_truth_and_the_filter_writes_its_lineage(tmp_path, capsys):
    src = tiny_capture(tmp_path / "src")
    assert main(["data", "filter-truth", str(src.root), "--out", str(tmp_path / "f")]) == 0
    capsys.readouterr()
    (err,) = _run(capsys, "refine", tmp_path / "f", tmp_path / "out")
    assert "lineage" in err and "filtered" in err and str(src.root) in err
    (err,) = _run(capsys, "filter-truth", tmp_path / "f", tmp_path / "out")
    assert "lineage" in err


@settings(max_examples=12, deadline=None)
@given(power=st.sampled_from([0.0, 1.0, 32.0, 1e30, 1e300, 1.7e308]),
       plane=st.sampled_from([1e-6, 0.01, 1e300]), range_sigma=st.sampled_from([0.0, 1e-300, 0.6, 1e300, 1.7e308]),
       levels=st.integers(1, 3))
def test_finite_settings_never_give_a_non_finite_weight(power, plane, range_sigma, levels):
    rng = np.random.default_rng(0)
    n = np.zeros((9, 9, 3), np.float32)
    n[..., 2] = 1.0
    n[..., 0] = rng.uniform(-0.05, 0.05, (9, 9))  # a little off unit length, as a float16 G-buffer's normals are
    z = rng.uniform(2.0, 4.0, (9, 9)).astype(np.float32)
    e = rng.uniform(0.0, 6e4, (9, 9, 3)).astype(np.float32)
    with np.errstate(over="raise", invalid="raise"):  # no overflow anywhere, not only none left in the output
        out = filter_irradiance(e, n, z, 60.0, TruthFilter(levels, power, plane, range_sigma))
    assert np.all(np.isfinite(out)) and out.min() >= e.min() * (1 - 1e-6) and out.max() <= e.max() * (1 + 1e-6)


def test_a_huge_normal_power_filters_a_whole_dataset_into_finite_frames(tmp_path):
    src = tiny_capture(tmp_path / "src")
    filter_dataset(src.root, tmp_path / "f", TruthFilter(normal_power=1e300), **QUIET)
    assert Dataset(tmp_path / "f").check() == []
