"""`diviewer inspect`: a bare .glb in, its report printed and written as JSON, and a scene file that loads, with
the suggested camera and a lamp; existing files never overwritten; a scene of its own meshes gets no skeleton."""

from __future__ import annotations

import json
import tomllib

import pytest

from diviewer.cli import main
from diviewer.scene import load_scene, sample_config
from gltf_doc import glb_bytes, gltf_document, png_bytes, checker_rgba, data_uri
from room_doc import write_room


@pytest.fixture
def glb(tmp_path):
    doc, blob = gltf_document()
    doc["images"][0] = {"uri": data_uri(png_bytes(checker_rgba()), "image/png")}
    del doc["meshes"][1]["primitives"][0]["material"]
    path = tmp_path / "model.glb"
    path.write_bytes(glb_bytes(doc, blob))
    return path


def test_inspect_a_glb_writes_a_report_and_a_scene_file_that_loads(glb, tmp_path, capsys):
    toml, report = tmp_path / "out" / "my.toml", tmp_path / "r.json"
    toml.parent.mkdir()
    assert main(["inspect", "--scene", str(glb), "--json", str(report), "--write-toml", str(toml)]) == 0
    out, err = capsys.readouterr()
    assert "14 triangles placed" in out and "DEFAULT (the file gives none)" in out and "suggested [camera]" in out
    # said once, in the report's own list, not again on stderr nor by the skeleton's check
    assert "warning:" not in err and (out.count("warning:") == 1 and "gltf_default" in out)
    data = json.loads(report.read_text())
    assert data["triangles"] == 14 and data["bounds"]["max"] == [2.0, 0.51, 2.0]
    text = toml.read_text()
    assert tomllib.loads(text)["gltf"]["file"] == "../model.glb"
    scene = load_scene(toml)
    assert scene.materials["gltf_default"].albedo == (0.8, 0.8, 0.8) and not scene.warnings
    assert scene.default.lights[0].name == "lamp"
    assert list(scene.default.camera.position) == data["suggested"]["camera"]["position"]
    cam = sample_config(scene, 3).camera  # the region and the lamp's box are usable ranges
    assert cam.position != scene.default.camera.position or cam.fov != scene.default.camera.fov


def test_inspect_never_overwrites(glb, tmp_path, capsys):
    toml = tmp_path / "mine.toml"
    toml.write_text("# mine\n")
    assert main(["inspect", "--scene", str(glb), "--write-toml", str(toml)]) == 2
    assert "never overwrites" in capsys.readouterr().err and toml.read_text() == "# mine\n"
    report = tmp_path / "r.json"
    report.write_text("{}")
    assert main(["inspect", "--scene", str(glb), "--json", str(report)]) == 2
    assert report.read_text() == "{}"


def test_inspect_a_scene_file_and_refuse_a_skeleton_for_its_own_meshes(tmp_path, capsys):
    room = write_room(tmp_path)
    assert main(["inspect", "--scene", str(room)]) == 0
    assert "emissive surfaces: 2.08 m^2" in capsys.readouterr().out
    assert main(["inspect", "--scene", str(room), "--write-toml", str(tmp_path / "new.toml")]) == 2
    assert "--write-toml" in capsys.readouterr().err and not (tmp_path / "new.toml").exists()


def test_inspect_a_missing_glb_is_one_line(tmp_path, capsys):
    assert main(["inspect", "--scene", str(tmp_path / "nope.glb")]) == 2
    assert "glTF file not found" in capsys.readouterr().err
