"""diviewer.ship.model (`diviewer ship model`): an exported model becomes the scene's shipped one, its card and ONNX
metadata alike."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from onnx_models import base_meta, direct_times
from diviewer.cli import main


def _model(path: Path, factor: float) -> Path:
    meta = {**base_meta(), "K": 8}
    direct_times(path, factor=factor, meta=meta)
    path.with_suffix(".json").write_text(json.dumps(meta))
    return path


def _ship(argv: list[str], capsys=None) -> dict:
    """`diviewer ship model ARGV`, and the card it wrote (read from the --ship folder's SCENE.json)."""
    assert main(["ship", "model", *argv]) == 0
    dest = Path(argv[argv.index("--ship") + 1])
    return json.loads((dest / f"{base_meta()['scene']}.json").read_text())


def _eval(path: Path, scores: dict[str, float]) -> Path:
    stat = lambda v: {"mean": v, "std": 0.0}
    row = lambda v: {"psnr_tm": stat(v), "ssim_tm": stat(0.9), "psnr_tm_object_unlit": stat(v - 10),
                     "ssim_tm_object_unlit": stat(None)}
    ev = {"splits": {s: {"methods": {m: row(v) for m, v in scores.items()}} for s in ("moved_camera", "window_shapes")}}
    path.write_text(json.dumps(ev))
    return path


def test_ship_writes_card_fields_and_files_and_replaces_the_shipped_model(tmp_path):
    from diviewer.contract.runtime import read_metadata

    ship, run = tmp_path / "ship", tmp_path / "run"
    ship.mkdir()
    run.mkdir()
    (run / "metrics.csv").write_text("epoch,step\n1,10\n")
    scene = base_meta()["scene"]
    _model(ship / f"{scene}.onnx", 1.0)
    new = _model(tmp_path / "new_k8.onnx", 2.0)
    ev = _eval(tmp_path / "ev.json", {"new_k8": 35.0, scene: 33.0})
    card = _ship(["--model", str(new), "--run", str(run), "--eval", str(ev), "--command", "diviewer train ...",
                      "--note", "a test model", "--ladder-why", "K=16 within 0.2 dB", "--ship", str(ship)])
    shipped = ship / f"{scene}.onnx"
    assert json.loads(shipped.with_suffix(".json").read_text()) == card == read_metadata(shipped)
    assert card["rebuild"] == f"diviewer build --scene {scene}" and card["commands"] == ["diviewer train ..."]
    assert card["ladder"] == {"chosen_K": 8, "why": "K=16 within 0.2 dB", "file": f"{scene}_ladder.json"}
    compact = card["evalset_compact"]
    assert compact["this_model"]["moved_camera"] == {"psnr_tm": 35.0, "ssim_tm": 0.9, "psnr_tm_object_unlit": 25.0}
    assert compact["previous_shipped"]["window_shapes"]["psnr_tm"] == 33.0
    assert (ship / f"{scene}_metrics.csv").read_text() == "epoch,step\n1,10\n"
    assert not (ship / f"{scene}_curves.png").exists()  # the run had none: nothing copied
    assert shipped.read_bytes() != (tmp_path / "new_k8.onnx").read_bytes()  # the card is in its metadata


def test_ship_draws_the_ladders_curves_from_each_ks_run_sized_by_the_ladder_record(tmp_path):
    """--ladder-run K RUN (a run folder or its metrics.csv), once per K: one figure of every K's curves, named in
    the card's ladder."""
    from PIL import Image

    from diviewer.contract.runtime import read_metadata

    ship = tmp_path / "ship"
    ship.mkdir()
    scene = base_meta()["scene"]
    runs = []
    for k, level in ((4, 30.0), (8, 31.0)):
        run = tmp_path / f"run_k{k}"
        run.mkdir()
        (run / "metrics.csv").write_text("epoch,step,loss_G_L1,val_psnr_tm,val_ssim_tm\n"
                                         + "".join(f"{i},{10 * i},{1 / i},{level + i},{0.8 + i / 100}\n"
                                                   for i in range(1, 5)))
        runs += ["--ladder-run", str(k), str(run if k == 4 else run / "metrics.csv")]  # a run, or its metrics
    (ship / f"{scene}_ladder.json").write_text(json.dumps({"rows": [{"K": 4, "bytes": 700_000},
                                                                    {"K": 8, "bytes": 2_700_000}]}))
    new = _model(tmp_path / "new_k8.onnx", 2.0)
    ev = _eval(tmp_path / "ev.json", {"new_k8": 35.0, scene: 33.0})
    card = _ship(["--model", str(new), "--run", str(tmp_path / "run_k8"), "--eval", str(ev), "--command", "c",
                      "--note", "n", "--ladder-why", "w", "--ship", str(ship), *runs])
    assert card["ladder"]["curves"] == f"{scene}_ladder_curves.png" == read_metadata(ship / f"{scene}.onnx")[
        "ladder"]["curves"]
    with Image.open(ship / card["ladder"]["curves"]) as im:
        px = {tuple(int(v) for v in c) for c in im.convert("RGB").getdata()}
    assert {(31, 119, 180), (255, 127, 14)} <= px  # a line for each K


def test_a_model_missing_from_the_eval_json_is_refused_by_name(tmp_path, capsys):
    scene = base_meta()["scene"]
    new = _model(tmp_path / "new_k8.onnx", 2.0)
    ev = _eval(tmp_path / "ev.json", {scene: 33.0})
    assert main(["ship", "model", "--model", str(new), "--run", str(tmp_path), "--eval", str(ev), "--command", "c",
                 "--note", "n", "--ladder-why", "w", "--ship", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "diviewer ship: error:" in err and "no method 'new_k8'" in err and str(ev) in err
    assert not (tmp_path / f"{scene}.onnx").exists()  # nothing shipped


def test_a_scene_file_edited_with_the_model_takes_the_previous_models_scores_from_their_own_json(tmp_path):
    """--previous-eval: the new model scored on the restamped set, the shipped one on the set before it."""
    ship = tmp_path / "ship"
    ship.mkdir()
    scene = base_meta()["scene"]
    _model(ship / f"{scene}.onnx", 1.0)
    new = _model(tmp_path / "new_k8.onnx", 2.0)
    ev_new, ev_old = _eval(tmp_path / "new.json", {"new_k8": 36.0}), _eval(tmp_path / "old.json", {scene: 31.0})
    card = _ship(["--model", str(new), "--run", str(tmp_path), "--eval", str(ev_new), "--previous-eval",
                      str(ev_old), "--command", "c", "--note", "n", "--ladder-why", "w", "--ship", str(ship)])
    compact = card["evalset_compact"]
    assert compact["this_model"]["moved_camera"]["psnr_tm"] == 36.0
    assert compact["previous_shipped"]["moved_camera"]["psnr_tm"] == 31.0
    assert (compact["json"], compact["previous_json"]) == (str(ev_new), str(ev_old))


def test_a_model_that_scores_worse_than_the_shipped_one_is_refused_unless_asked(tmp_path, capsys):
    """Shipping over a better model is refused before anything is written; --replace-worse ships it anyway, and the
    line says what it replaced and how the two scored."""
    ship, run = tmp_path / "ship", tmp_path / "run"
    ship.mkdir()
    run.mkdir()
    scene = base_meta()["scene"]
    old = _model(ship / f"{scene}.onnx", 1.0)
    before = old.read_bytes()
    new = _model(tmp_path / "new_k8.onnx", 2.0)
    ev = _eval(tmp_path / "ev.json", {"new_k8": 31.0, scene: 33.0})
    argv = ["ship", "model", "--model", str(new), "--run", str(run), "--eval", str(ev), "--command", "x", "--note",
            "n", "--ladder-why", "w", "--ship", str(ship)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "scores 31.00 dB" in err and "33.00" in err and "--replace-worse" in err
    assert old.read_bytes() == before
    assert main([*argv, "--replace-worse"]) == 0
    out = capsys.readouterr().out
    assert "replacing the model there: 31.00 dB against its 33.00" in out and old.read_bytes() != before
