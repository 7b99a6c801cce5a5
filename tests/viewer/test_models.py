"""Which model the viewer runs: ``--model auto`` without a model that fits says so in one line, with what
`diviewer build` would do, and the view goes on without neural GI."""

from __future__ import annotations

import pytest

import diviewer.paths as paths
from diviewer.gl.neural import GISettings
from diviewer.scene import load_scene
from diviewer.viewer.gi import GIControl
from diviewer.viewer.models import gi_resolution, open_model
from diviewer.viewer.state import ViewerState


@pytest.fixture
def no_models(tmp_path, monkeypatch):
    empty = tmp_path / "models"
    empty.mkdir()
    monkeypatch.setattr(paths, "models_dir", lambda: empty)
    return empty


def test_auto_without_a_model_for_a_shipped_scene_says_so_and_what_build_does(no_models, capsys):
    scene = load_scene("cornell")
    model, message = open_model("auto", scene)
    assert model is None
    assert f"no model for scene 'cornell' in {no_models}" in message and "without neural GI" in message
    assert "diviewer build --scene cornell" in message and "cornell.onnx" in message
    gi = GIControl(None, None, ViewerState(scene), "model", GISettings())
    gi.load("auto")  # the viewer's start: the line reaches the terminal, the view goes on without a model
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "diviewer view: no model for scene 'cornell'" in err
    assert gi.model is None and gi.state.model_message == message


def test_auto_for_a_scene_file_of_ones_own_names_where_build_writes_it(no_models, tmp_path):
    own = tmp_path / "mine.toml"
    own.write_text((paths.scenes_dir() / "cornell.toml").read_text())
    scene = load_scene(own)
    model, message = open_model("auto", scene)
    assert model is None and f"diviewer build --scene {own}" in message
    assert f"runs/mine/{scene.name}.onnx" in message and "--model" in message


def test_auto_finds_the_model_a_build_wrote_into_its_default_work_folder(no_models, tmp_path, monkeypatch):
    """`diviewer build --scene mine.toml` writes runs/mine/<name>.onnx; `view --model auto` run from the same
    folder takes it."""
    import shutil

    own = tmp_path / "mine.toml"
    own.write_text((paths.scenes_dir() / "cornell.toml").read_text())
    scene = load_scene(own)
    monkeypatch.chdir(tmp_path)
    built = tmp_path / "runs" / "mine" / f"{scene.name}.onnx"
    built.parent.mkdir(parents=True)
    shutil.copy(paths.assets_dir() / "models" / "cornell.onnx", built)
    model, message = open_model("auto", scene)
    assert model is not None and message == ""
    assert model.path.resolve() == built.resolve()


def test_auto_with_only_models_that_refuse_gives_their_reasons(no_models):
    (no_models / "cornell_broken.onnx").write_bytes(b"not onnx")
    model, message = open_model("auto", load_scene("cornell"))
    assert model is None and "cornell_broken.onnx" in message and "diviewer build --scene cornell" in message


def test_none_is_quiet(no_models, capsys):
    scene = load_scene("cornell")
    GIControl(None, None, ViewerState(scene), "model", GISettings()).load("none")
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("spec", ["inf/1", "1/0", "nan/2", "1/inf", "2/1", "1/1000"])
def test_a_gi_fraction_that_is_not_a_finite_share_of_the_window_is_refused(spec):
    from diviewer.errors import DiviewerError

    with pytest.raises(DiviewerError, match="--gi-res"):
        gi_resolution(spec, (256, 256), (128, 128), 32)
