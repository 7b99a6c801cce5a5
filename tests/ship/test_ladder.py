"""diviewer.ship.ladder (`diviewer ship ladder`): the ladder rule on two eval JSONs, the record, and the verdict on the shipped card."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from onnx_models import base_meta, direct_times
from diviewer.cli import main
from diviewer.ship.ladder import ladder


def _model(path: Path, K: int) -> Path:
    meta = {**base_meta(), "K": K, "steps": 100 * K}
    direct_times(path, meta=meta)
    path.with_suffix(".json").write_text(json.dumps(meta))
    return path


def _stat(v: float) -> dict:
    return {"mean": v, "std": 0.0}


def _files(tmp: Path, psnr: dict[int, float], test_psnr: dict[int, float] | None = None
           ) -> tuple[Path, Path, dict[int, Path]]:
    """Eval JSONs: the evaluation set's two splits at ``psnr`` + 1 and + 2 dB (2 and 6 frames), the test split at
    ``test_psnr`` (default ``psnr``)."""
    models = {k: _model(tmp / f"k{k}.onnx", k) for k in psnr}
    test_psnr = test_psnr or psnr
    q = lambda v: {"psnr": _stat(v + 5), "ssim": _stat(0.9), "psnr_tm": _stat(v), "ssim_tm": _stat(0.8)}
    test = {"results": [{"model": str(p), "frames": 10, "reference_spp": 64, "inference_ms": {"median": 1.0},
                         "methods": {"neural": q(test_psnr[k]), "direct": q(15.0)}} for k, p in models.items()]}
    ev = {"reference_spp": 1024,
          "splits": {s: {"frames": n, "methods": {p.stem: {**q(psnr[k] + d), "psnr_tm_object_unlit": _stat(20.0)}
                                                  for k, p in models.items()}}
                     for s, n, d in (("moved_camera", 2, 1.0), ("window_shapes", 6, 2.0))}}
    (tmp / "test.json").write_text(json.dumps(test))
    (tmp / "ev.json").write_text(json.dumps(ev))
    return tmp / "test.json", tmp / "ev.json", models


@pytest.mark.parametrize("psnr,chosen", [({8: 31.55, 16: 31.79}, 8), ({8: 30.0, 16: 31.0, 32: 31.2}, 16)])
def test_the_rule_picks_the_smallest_sufficient_k(tmp_path, psnr, chosen):
    test, ev, models = _files(tmp_path, psnr)
    record = ladder("plane", json.loads(test.read_text()), json.loads(ev.read_text()), models, 0.5)
    assert record["chosen_K"] == chosen and [r["K"] for r in record["rows"]] == sorted(psnr)
    row = record["rows"][0]
    assert row["test_split"]["neural"]["psnr_tm"] == psnr[min(psnr)] and row["steps"] == 100 * min(psnr)
    assert row["evalset"]["moved_camera"]["psnr_tm_object_unlit"] == 20.0
    assert row["evalset_psnr_tm"] == pytest.approx(psnr[min(psnr)] + (1 * 2 + 2 * 6) / 8)
    assert record["measure"] == "evalset_psnr_tm" and "(8 frames scored, 1024 spp)" in record["rule"]


def test_the_rule_reads_the_evaluation_set_where_a_noisy_test_split_reads_the_models_alike(tmp_path):
    # cornell v3's ladder: 35.58 / 36.05 dB on the 64-spp test split (K = 8 within 0.5 dB), 0.74 dB apart at 1024 spp
    test, ev, models = _files(tmp_path, {8: 35.6, 16: 36.34}, test_psnr={8: 35.58, 16: 36.05})
    record = ladder("plane", json.loads(test.read_text()), json.loads(ev.read_text()), models, 0.5)
    assert record["chosen_K"] == 16


def test_ship_writes_the_record_and_the_card_in_both_places(tmp_path, capsys):
    import onnx

    test, ev, models = _files(tmp_path, {8: 31.55, 16: 31.79})
    ship = tmp_path / "ship"
    ship.mkdir()
    shipped = _model(ship / "plane.onnx", 8)
    argv = ["ship", "ladder", "--scene", "plane", "--test-split", str(test), "--evalset", str(ev), "--model",
            f"K8={models[8]}", "--model", f"K16={models[16]}", "--ship", str(ship), "--note", "a note"]
    assert main(argv) == 0
    assert json.loads(capsys.readouterr().out)["chosen_K"] == 8
    assert json.loads((ship / "plane_ladder.json").read_text())["chosen_K"] == 8
    card = json.loads(shipped.with_suffix(".json").read_text())
    assert card["ladder"]["chosen_K"] == 8 and card["ladder"]["file"] == "plane_ladder.json"
    assert card["ladder"]["why"].endswith("; a note")
    meta = json.loads({p.key: p.value for p in onnx.load(str(shipped)).metadata_props}["diviewer"])
    assert meta["ladder"] == card["ladder"]
    # A ladder that chose another K than the one shipped is refused: this command records, it does not swap models.
    _files(tmp_path, {8: 29.0, 16: 31.79})
    assert main(argv) == 2
    assert "ship that model first" in capsys.readouterr().err
    assert json.loads((ship / "plane_ladder.json").read_text())["chosen_K"] == 8  # the record kept


def test_a_model_without_its_k_is_refused_before_any_file_is_read(tmp_path, capsys):
    assert main(["ship", "ladder", "--scene", "plane", "--test-split", str(tmp_path / "t.json"), "--evalset",
                 str(tmp_path / "e.json"), "--model", "assets/models/cornell.onnx"]) == 2
    assert "--model assets/models/cornell.onnx: give KN=PATH" in capsys.readouterr().err
