"""KHR_draco_mesh_compression: a mesh the test compresses with DracoPy loads as its uncompressed copy; without
DracoPy the file is refused naming the extension and the extra."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.scene import load_scene
from gltf_doc import gltf_document, write_scene

DracoPy = pytest.importorskip("DracoPy")


def _draco_doc():
    """The test document with its box compressed: the box's accessors lose their buffer views (as Draco
    exporters write them) and the primitive names the Draco data's attribute ids."""
    doc, blob = gltf_document()
    v = np.frombuffer(blob, np.float32, count=24, offset=doc["bufferViews"][4]["byteOffset"]).reshape(8, 3)
    f = np.frombuffer(blob, np.uint16, count=36, offset=doc["bufferViews"][5]["byteOffset"]).reshape(12, 3)
    data = DracoPy.encode(v.astype(np.float64), f.astype(np.uint32), preserve_order=True, quantization_bits=16)
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
    blob += data
    doc["buffers"][0]["byteLength"] = len(blob)
    for a in (4, 5):
        del doc["accessors"][a]["bufferView"]
    prim = doc["meshes"][1]["primitives"][0]
    prim["extensions"] = {"KHR_draco_mesh_compression": {"bufferView": len(doc["bufferViews"]) - 1,
                                                         "attributes": {"POSITION": 0}}}
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    return doc, blob, v, f


def test_draco_mesh_decodes_to_the_uncompressed_one(tmp_path):
    doc, blob, v, f = _draco_doc()
    scene = load_scene(write_scene(tmp_path, doc=doc, blob=blob))
    box = scene.meshes["box"]
    assert np.array_equal(box.faces, f.astype(np.uint32))
    assert np.allclose(box.vertices, v, atol=1e-4)  # 16-bit quantisation of a unit box
    assert not scene.warnings


def test_draco_without_dracopy_names_the_extra(tmp_path, monkeypatch):
    doc, blob, _, _ = _draco_doc()
    monkeypatch.setitem(sys.modules, "DracoPy", None)  # import fails as where it is not installed
    with pytest.raises(DiviewerError, match=r"KHR_draco_mesh_compression.*DracoPy.*diviewer\[draco\]"):
        load_scene(write_scene(tmp_path, doc=doc, blob=blob))


def test_corrupt_draco_data_is_named(tmp_path):
    doc, blob, _, _ = _draco_doc()
    start = doc["bufferViews"][-1]["byteOffset"]
    blob = blob[:start] + b"\x07" * (len(blob) - start)
    with pytest.raises(DiviewerError, match=r"meshes\[1\]\.primitives\[0\]\.extensions\.KHR_draco.*does not decode"):
        load_scene(write_scene(tmp_path, doc=doc, blob=blob))


def test_draco_not_required_falls_back_to_the_uncompressed_copy_without_dracopy(tmp_path, monkeypatch):
    doc, blob, v, f = _draco_doc()
    doc["accessors"][4]["bufferView"], doc["accessors"][5]["bufferView"] = 4, 5  # the copy exporters keep
    doc["extensionsRequired"] = []
    monkeypatch.setitem(sys.modules, "DracoPy", None)
    box = load_scene(write_scene(tmp_path, doc=doc, blob=blob)).meshes["box"]
    assert np.array_equal(box.vertices, v) and np.array_equal(box.faces, f.astype(np.uint32))
