"""glTF files as downloaded: a .glb (BIN chunk, images in buffer views), a .gltf with data URIs, a .glb with an
external buffer, all loading to the same scene as the .gltf with files; a broken container named with its file."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.scene import load_scene
from gltf_doc import checker_rgba, data_uri, glb_bytes, gltf_document, png_bytes, scene_toml, write_scene


def _same(a, b) -> None:
    assert a.meshes.keys() == b.meshes.keys() and a.materials.keys() == b.materials.keys()
    for k in a.meshes:
        assert np.array_equal(a.meshes[k].vertices, b.meshes[k].vertices)
        assert np.array_equal(a.meshes[k].faces, b.meshes[k].faces)
    for k in a.materials:
        ta, tb = a.materials[k].texture, b.materials[k].texture
        assert (ta is None) == (tb is None) and (ta is None or np.array_equal(ta, tb))
        assert a.materials[k].albedo == b.materials[k].albedo
    assert [o.name for o in a.default.objects] == [o.name for o in b.default.objects]


@pytest.fixture
def reference(tmp_path):
    return load_scene(write_scene(tmp_path / "files"))


def _image_in_buffer(doc: dict, blob: bytes) -> bytes:
    """The document's image moved into a buffer view after the geometry (as exporters write a .glb)."""
    png = png_bytes(checker_rgba())
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(png)})
    doc["images"] = [{"bufferView": len(doc["bufferViews"]) - 1, "mimeType": "image/png"}]
    blob += png
    doc["buffers"][0]["byteLength"] = len(blob)
    return blob


def test_glb_with_its_bin_chunk_loads_as_the_gltf(tmp_path, reference):
    doc, blob = gltf_document()
    blob = _image_in_buffer(doc, blob)
    (tmp_path / "tiny.glb").write_bytes(glb_bytes(doc, blob))
    (tmp_path / "scene.toml").write_text(scene_toml("tiny.glb"))
    _same(load_scene(tmp_path / "scene.toml"), reference)


def test_glb_with_an_external_buffer(tmp_path, reference):
    folder = tmp_path / "glb"
    write_scene(folder)
    doc, _ = gltf_document()
    (folder / "x.glb").write_bytes(glb_bytes(doc, None))  # JSON chunk only; the buffer is tiny.bin beside it
    (folder / "scene.toml").write_text(scene_toml("x.glb"))
    scene = load_scene(folder / "scene.toml")
    _same(scene, reference)
    (folder / "tiny.bin").write_bytes(b"\0" * 8)
    with pytest.raises(DiviewerError, match="tiny.bin has 8 bytes"):
        load_scene(folder / "scene.toml")


def test_gltf_with_embedded_data_uris(tmp_path, reference):
    doc, blob = gltf_document()
    doc["buffers"][0]["uri"] = data_uri(blob)
    doc["images"][0]["uri"] = data_uri(png_bytes(checker_rgba()), "image/png")
    (tmp_path / "e.gltf").write_text(json.dumps(doc))
    (tmp_path / "scene.toml").write_text(scene_toml("e.gltf"))
    _same(load_scene(tmp_path / "scene.toml"), reference)


def _glb_case(tmp_path, data: bytes):
    (tmp_path / "bad.glb").write_bytes(data)
    (tmp_path / "scene.toml").write_text(scene_toml("bad.glb"))
    with pytest.raises(DiviewerError) as info:
        load_scene(tmp_path / "scene.toml")
    msg = str(info.value)
    assert "bad.glb" in msg and "gltf.file" in msg, msg
    return msg


def test_broken_glb_containers_are_named(tmp_path):
    doc, blob = gltf_document()
    good = glb_bytes(doc, blob)
    assert "truncated" in _glb_case(tmp_path, good[:-20])
    assert "truncated" in _glb_case(tmp_path, good[:10])
    assert "version 1" in _glb_case(tmp_path, good[:4] + struct.pack("<I", 1) + good[8:])
    swapped = bytearray(good)
    swapped[16:20] = struct.pack("<I", 0x004E4942)  # the first chunk typed BIN
    assert "first chunk is not the JSON chunk" in _glb_case(tmp_path, bytes(swapped))
    bad_json = bytearray(good)
    bad_json[20] = ord("!")
    assert "JSON chunk does not parse" in _glb_case(tmp_path, bytes(bad_json))
    assert "neither a glTF JSON file" in _glb_case(tmp_path, b"\x89PNG\r\n\x1a\n" + b"\0" * 64)


def test_editing_a_glb_changes_the_scene_identity(tmp_path):
    doc, blob = gltf_document()
    blob = _image_in_buffer(doc, blob)
    (tmp_path / "tiny.glb").write_bytes(glb_bytes(doc, blob))
    (tmp_path / "scene.toml").write_text(scene_toml("tiny.glb"))
    before = load_scene(tmp_path / "scene.toml").file_hash
    doc["materials"][1]["pbrMetallicRoughness"]["baseColorFactor"] = [0.1, 0.5, 0.4, 1.0]
    (tmp_path / "tiny.glb").write_bytes(glb_bytes(doc, blob))
    assert load_scene(tmp_path / "scene.toml").file_hash != before
