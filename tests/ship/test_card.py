"""diviewer.ship.card (`diviewer ship eval`): a shipped model's card records an evaluation of the same weights, card and metadata alike."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from onnx_models import base_meta, direct_times
from diviewer.cli import main
from diviewer.ship.card import record_eval


def _shipped(path: Path, sha: str) -> Path:
    meta = {**base_meta(), "checkpoint_sha256": sha, "evalset_compact": {"json": "compact.json"}}
    direct_times(path, factor=2.0, meta=meta)
    path.with_suffix(".json").write_text(json.dumps(meta))
    return path


def _eval(path: Path, method: str, row_extra: dict) -> Path:
    stat = lambda v: {"mean": v, "std": 0.0}
    row = {"psnr_tm": stat(35.0), "ssim_tm": stat(0.88), "psnr_tm_shade": stat(36.0), "flip_ldr": stat(0.06),
           "psnr_tm_object": None, "stride_shade": {"mean": 0.0512, "max": 0.31, "frames": 24}, **row_extra}  # None: a scene with no moving object has no object region
    ev = {"evalset": "runs/x/evalset", "reference_spp": 1024,
          "splits": {s: {"frames": 24, "methods": {method: row, "direct": {"psnr_tm": stat(25.0)}}}
                     for s in ("moved_camera", "window_shapes_228x128")}}
    path.write_text(json.dumps(ev))
    return path


def _weights(path: Path) -> dict:
    import onnx

    return {t.name: onnx.numpy_helper.to_array(t).tolist() for t in onnx.load(str(path)).graph.initializer}


def test_the_scores_of_the_same_weights_land_in_the_card_and_the_metadata(tmp_path):
    from diviewer.contract.runtime import read_metadata

    model = _shipped(tmp_path / "plane.onnx", "a" * 64)
    weights = _weights(model)
    ev = _eval(tmp_path / "full.json", "plane", {"checkpoint_sha256": "a" * 64})
    card = record_eval(model, ev)
    assert json.loads(model.with_suffix(".json").read_text()) == card == read_metadata(model)
    full = card["evalset_full"]
    assert full["this_model"]["moved_camera"] == {"psnr_tm": 35.0, "ssim_tm": 0.88, "psnr_tm_shade": 36.0,
                                                  "stride_shade": 0.051}
    assert full["frames"] == {"moved_camera": 24, "window_shapes_228x128": 24}
    assert (full["json"], full["evalset"], full["reference_spp"]) == (str(ev), "runs/x/evalset", 1024)
    assert card["evalset_compact"] == {"json": "compact.json"}  # the rest of the card is kept
    assert _weights(model) == weights
    # `diviewer eval`'s margin of the model's training truth over its error comes along, rounded as cards keep it
    margin = {"truth_spp": 64, "from": "pt_spp64", "median_db": -0.4321, "lowest_db": -1.987,
              "share_at_least_6db": 0.0, "frames": 24, "unresolved": 0}
    ev = _eval(tmp_path / "full.json", "plane", {"checkpoint_sha256": "a" * 64, "truth_margin": margin})
    card = record_eval(model, ev)
    assert card["evalset_full"]["this_model"]["moved_camera"]["truth_margin"] == {
        **margin, "median_db": -0.43, "lowest_db": -1.99}


def test_an_eval_of_other_weights_is_refused_and_the_card_kept(tmp_path):
    from diviewer.errors import DiviewerError

    model = _shipped(tmp_path / "plane.onnx", "a" * 64)
    before = model.read_bytes()
    ev = _eval(tmp_path / "full.json", "plane", {"checkpoint_sha256": "b" * 64})
    with pytest.raises(DiviewerError, match="scored checkpoint bbbbbbbbbbbbbbbb, not") as err:
        record_eval(model, ev)
    assert str(ev) in str(err.value) and "checkpoint_sha256" in str(err.value)
    assert model.read_bytes() == before
    with pytest.raises(DiviewerError, match="no method 'other'"):
        record_eval(model, ev, method="other")


def test_an_older_eval_is_matched_through_the_model_file_it_names(tmp_path):
    """JSONs written before `diviewer eval` recorded the checkpoint: the card of the model file they name decides;
    a file no longer there cannot be told apart, and is refused."""
    from diviewer.errors import DiviewerError

    model = _shipped(tmp_path / "plane.onnx", "a" * 64)
    (tmp_path / "ship").mkdir()
    twin = _shipped(tmp_path / "ship" / "plane.onnx", "a" * 64)  # the build's copy of the same weights
    ev = _eval(tmp_path / "full.json", "plane", {"model": str(twin)})
    card = record_eval(model, ev, "evalset_other")
    assert card["evalset_other"]["this_model"]["window_shapes_228x128"]["psnr_tm"] == 35.0
    gone = _eval(tmp_path / "gone.json", "plane", {"model": str(tmp_path / "nowhere.onnx")})
    with pytest.raises(DiviewerError, match="cannot tell which weights it scored"):
        record_eval(model, gone)


def test_the_command_records_the_scores_and_refuses_other_weights_in_one_line(tmp_path, capsys):
    model = _shipped(tmp_path / "plane.onnx", "a" * 64)
    ev = _eval(tmp_path / "full.json", "plane", {"checkpoint_sha256": "a" * 64})
    assert main(["ship", "eval", "--eval", str(ev), "--model", str(model), "--key", "evalset_cli"]) == 0
    assert "evalset_cli recorded" in capsys.readouterr().out
    assert json.loads(model.with_suffix(".json").read_text())["evalset_cli"]["frames"]["moved_camera"] == 24
    other = _eval(tmp_path / "other.json", "plane", {"checkpoint_sha256": "b" * 64})
    assert main(["ship", "eval", "--eval", str(other), "--model", str(model)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("diviewer ship: error:") and "scored checkpoint bbbbbbbbbbbbbbbb" in err
