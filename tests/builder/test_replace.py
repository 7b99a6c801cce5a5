"""What a build's ship replaces: scored first, refused where the new model scores worse (unless --replace-worse),
and the replaced files kept in the work folder."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

import diviewer.builder.replace as replace
from diviewer.errors import DiviewerError


@pytest.fixture
def plan(tmp_path):
    return SimpleNamespace(work=tmp_path / "w", evalset_dir=tmp_path / "evalset",
                           model=lambda k: tmp_path / "w" / "models" / f"x_k{k}.onnx")


def _scored(monkeypatch, value):
    def score(plan, old, log):
        if isinstance(value, Exception):
            raise value
        return value

    monkeypatch.setattr(replace, "score_replaced", score)


def test_a_worse_model_is_refused_with_one_line_naming_both_scores_and_where_the_new_one_is(plan, monkeypatch):
    _scored(monkeypatch, 40.0)
    said = []
    with pytest.raises(DiviewerError) as err:
        replace.check_not_worse(plan, Path("ship/x.onnx"), 8, 35.5, False, said.append)
    text = str(err.value)
    assert "35.50 dB against 40.00 dB" in text and "nothing replaced" in text and "--replace-worse" in text
    assert str(plan.model(8)) in text and "--ship" in text and "\n" not in text
    rec = replace.check_not_worse(plan, Path("ship/x.onnx"), 8, 35.5, True, said.append)
    assert rec == {"model": "ship/x.onnx", "evalset_psnr_tm": 40.0, "new_evalset_psnr_tm": 35.5}
    assert "the new K = 8 scores 35.50 dB against 40.00 dB" in said[-1]


@pytest.mark.parametrize("new", [40.0, 41.0])
def test_a_model_that_scores_as_well_or_better_replaces_the_old(plan, monkeypatch, new):
    _scored(monkeypatch, 40.0)
    rec = replace.check_not_worse(plan, Path("x.onnx"), 16, new, False, lambda _: None)
    assert rec["evalset_psnr_tm"] == 40.0 and rec["new_evalset_psnr_tm"] == new


def test_a_model_that_cannot_be_scored_is_replaced_only_when_asked(plan, monkeypatch):
    _scored(monkeypatch, DiviewerError("the model was made for scene 'sponza'", field="scene_hash"))
    with pytest.raises(DiviewerError, match="cannot be scored on its evaluation set .*made for scene 'sponza'"):
        replace.check_not_worse(plan, Path("x.onnx"), 8, 30.0, False, lambda _: None)
    said = []
    assert replace.check_not_worse(plan, Path("x.onnx"), 8, 30.0, True, said.append)["evalset_psnr_tm"] is None
    assert "replaced as asked (--replace-worse)" in said[0]


def test_the_files_a_ship_replaces_are_kept_in_the_work_folder(plan, tmp_path):
    ship = tmp_path / "ship"
    ship.mkdir()
    (ship / "x.onnx").write_bytes(b"model")
    (ship / "x.json").write_text("{}")
    said = []
    kept = replace.keep_replaced(plan, [ship / "x.onnx", ship / "x.json", ship / "x_metrics.csv"], said.append)
    assert kept.parent == plan.work / replace.REPLACED
    assert (kept / "x.onnx").read_bytes() == b"model" and (kept / "x.json").read_text() == "{}"
    assert sorted(p.name for p in kept.iterdir()) == ["x.json", "x.onnx"] and str(kept) in said[0]
    assert replace.keep_replaced(plan, [ship / "nothing.onnx"], said.append) is None
