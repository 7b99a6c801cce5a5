"""tools/restamp_scene_hash.py --new-toml: an evaluation set follows a scene file's edit only where none of its frames sees it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from diviewer.errors import DiviewerError
from diviewer.paths import scenes_dir
from diviewer.scene import load_scene
from tool_modules import load_tool

FRAME = '[meshes.frame]\nshape = "frame"\n'
PIPE = '\n[meshes.pipe]\nshape = "pipe"\nradius = 0.35\ninner_radius = 0.25\nheight = 0.6\n'


def _scene(tmp_path: Path, name: str, extra: str = "", replace: tuple[str, str] | None = None) -> Path:
    text = (scenes_dir() / "cornell.toml").read_text()
    if replace:
        assert replace[0] in text
        text = text.replace(*replace)
    path = tmp_path / name
    path.write_text(text + extra)
    return path


def _evalset(tmp_path: Path, toml: Path, meshes: list[str], name: str = "evalset") -> Path:
    root = tmp_path / name
    root.mkdir()
    frames = [{"index": i, "config": {"objects": [{"name": "center", "mesh": m}]}} for i, m in enumerate(meshes)]
    manifest = {"kind": "evalset", "scene": "cornell", "scene_hash": load_scene(toml).file_hash,
                "scene_toml": toml.read_text(), "frame_list": frames, "spp": 1024}
    (root / "manifest.json").write_text(json.dumps(manifest))
    return root


def test_a_mesh_no_frame_shows_moves_the_set_to_the_new_identity(tmp_path):
    tool = load_tool("restamp_scene_hash")
    old = _scene(tmp_path, "old.toml")
    new = _scene(tmp_path, "new.toml", PIPE)
    ev = _evalset(tmp_path, old, ["cube", "torus"])
    assert load_scene(old).file_hash != load_scene(new).file_hash
    assert tool.restamp_evalset(ev, old, new).startswith("restamped (meshes added: pipe")
    m = json.loads((ev / "manifest.json").read_text())
    assert m["scene_hash"] == load_scene(new).file_hash and m["scene_toml"] == new.read_text()
    assert m["restamped"]["from_scene_hash"] == load_scene(old).file_hash
    assert m["restamped"]["meshes_added"] == ["pipe"] and m["frame_list"][1]["config"]["objects"][0]["mesh"] == "torus"
    assert tool.restamp_evalset(ev, old, new) == "already current"


def test_an_edit_a_frame_can_see_is_refused_and_the_manifest_kept(tmp_path):
    tool = load_tool("restamp_scene_hash")
    old = _scene(tmp_path, "old.toml", PIPE)
    ev = _evalset(tmp_path, old, ["cube", "pipe"])
    before = (ev / "manifest.json").read_bytes()
    # a frame draws the pipe: declaring it differently changes that frame
    with pytest.raises(DiviewerError, match="meshes the set's frames show changed: pipe"):
        tool.restamp_evalset(ev, old, _scene(tmp_path, "new_pipe.toml", PIPE.replace("0.35", "0.4")))
    # a material is part of every frame
    red = _scene(tmp_path, "red.toml", PIPE, replace=("albedo = [0.63, 0.065, 0.05]", "albedo = [0.6, 0.065, 0.05]"))
    with pytest.raises(DiviewerError, match="the scene itself changed"):
        tool.restamp_evalset(ev, old, red)
    # a set made from another file
    with pytest.raises(DiviewerError, match="not made from"):
        tool.restamp_evalset(ev, _scene(tmp_path, "other.toml"), _scene(tmp_path, "new.toml", PIPE + FRAME))
    assert (ev / "manifest.json").read_bytes() == before


def test_the_command_line_names_the_file_on_refusal(tmp_path, capsys):
    tool = load_tool("restamp_scene_hash")
    old = _scene(tmp_path, "old.toml")
    (tmp_path / "nothing").mkdir()
    assert tool.main(["--old-toml", str(old), "--new-toml", str(old), str(tmp_path / "nothing")]) == 2
    err = capsys.readouterr().err
    assert "manifest.json" in err and err.count("\n") == 1
