"""glTF files validated, never trusted (issue 29 item 5): named refusals for each broken field, textures by their
real format, and hypothesis-generated mutations of a valid document that end in a clean error or a sound
load (and render), each within a time limit."""

from __future__ import annotations

import contextlib
import itertools
import json
import signal
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diviewer.errors import DiviewerError
from diviewer.scene import load_scene
from diviewer.scene.colour import srgb_to_linear
from diviewer.scene.textures import MAX_TEXTURE_SIDE, load_texture
from gltf_doc import gltf_document, write_scene
from mutation import mutate

LIMIT_S = 30
"""Hard limit on one load (SIGALRM): a hang (a node cycle, a runaway allocation) fails the test instead of
the suite. pytest-timeout is not a dependency; hypothesis' deadline below bounds each example too."""


@contextlib.contextmanager
def time_limit(seconds: int = LIMIT_S):
    def on_alarm(*_):
        raise TimeoutError(f"took more than {seconds} s: a hang")
    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def load_mutated(folder: Path, doc: dict, blob: bytes | None = None):
    """Write the scene with ``doc`` and load it within the time limit: the Scene, or the DiviewerError."""
    path = write_scene(folder, doc=doc, blob=blob)
    with time_limit():
        try:
            return load_scene(path)
        except DiviewerError as exc:
            assert str(path.parent / "tiny.gltf") in str(exc) or str(path) in str(exc), f"names no file: {exc}"
            return exc


def refused(tmp_path: Path, edit, field: str, words: str = "", blob: bytes | None = None) -> str:
    doc, _ = gltf_document()
    edit(doc)
    got = load_mutated(tmp_path, doc, blob)
    assert isinstance(got, DiviewerError), f"loaded; expected a refusal naming {field}"
    msg = str(got)
    assert "tiny.gltf" in msg and field in msg, msg
    assert words in msg, msg
    return msg


def _set(path: str, value):
    """An edit that sets doc[path] (dotted, with integer list indices)."""
    keys = [int(k) if k.isdigit() else k for k in path.split(".")]

    def edit(doc):
        obj = doc
        for k in keys[:-1]:
            obj = obj[k]
        obj[keys[-1]] = value
    return edit


CASES = {
    "cycle": (_set("nodes.2.children", [1]), "nodes[2].children[0]", "reached twice"),
    "self_cycle": (_set("nodes.1.children", [1]), "nodes[1].children[0]", "reached twice"),
    "two_parents": (_set("nodes.0.children", [2]), "children[0]", "reached twice"),
    "node_index": (_set("nodes.1.children", [7]), "nodes[1].children[0]", "not an index into 'nodes'"),
    "node_index_float": (_set("nodes.1.children", [2.0]), "nodes[1].children[0]", "not an index"),
    "node_index_bool": (_set("nodes.1.children", [True]), "nodes[1].children[0]", "not an index"),
    "scene_index": (_set("scene", 3), "scene", "not an index into 'scenes'"),
    "root_index": (_set("scenes.0.nodes", [0, -1]), "scenes[0].nodes[1]", "not an index"),
    "mesh_index": (_set("nodes.0.mesh", 5), "nodes[0].mesh", "not an index into 'meshes'"),
    "accessor_index": (_set("meshes.0.primitives.0.attributes.POSITION", 60),
                       "meshes[0].primitives[0].attributes.POSITION", "not an index into 'accessors'"),
    "bufferview_index": (_set("accessors.0.bufferView", 6), "accessors[0].bufferView", "not an index"),
    "buffer_index": (_set("bufferViews.0.buffer", 1), "bufferViews[0].buffer", "not an index into 'buffers'"),
    "material_index": (_set("meshes.1.primitives.0.material", 2), "meshes[1].primitives[0].material", "not an index"),
    "texture_index": (_set("materials.0.pbrMetallicRoughness.baseColorTexture.index", 1), "baseColorTexture.index",
                      "not an index into 'textures'"),
    "image_index": (_set("textures.0.source", 1), "textures[0].source", "not an index into 'images'"),
    "sampler_index": (_set("textures.0.sampler", 1), "textures[0].sampler", "not an index into 'samplers'"),
    "indices_not_triangles": (_set("accessors.3.count", 5), "meshes[0].primitives[0].indices", "whole number"),
    "index_out_of_range": (_set("meshes.0.primitives.0.indices", 5), "meshes[0].primitives[0].indices", "out of range"),
    "accessor_past_view": (_set("accessors.0.count", 5), "accessors[0]", "past its buffer view"),
    "view_past_buffer": (_set("bufferViews.5.byteLength", 4000), "bufferViews[5]", "past its buffer"),
    "short_stride": (_set("bufferViews.0.byteStride", 4), "bufferViews[0].byteStride", "less than"),
    "negative_offset": (_set("accessors.1.byteOffset", -4), "accessors[1].byteOffset", "whole number"),
    "position_type": (_set("accessors.0.type", "VEC2"), "attributes.POSITION", "expected a VEC3"),
    "unknown_component": (_set("accessors.0.componentType", 5130), "accessors[0]", "unknown componentType"),
    "uv_count": (_set("accessors.2.count", 3), "attributes.TEXCOORD_0", "one per POSITION"),
    "zero_scale": (_set("nodes.1.scale", [1, 0, 1]), "nodes[2]", "collapses"),
    "nan_translation": (_set("nodes.0.translation", [0, float("nan"), 0]), "nodes[0].translation", "finite"),
    "matrix_length": (_set("nodes.2.matrix", [1, 0, 0, 0, 1]), "nodes[2].matrix", "16 finite numbers"),
    "matrix_projective": (_set("nodes.2.matrix", [1, 0, 0, 0.5, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]),
                          "nodes[2].matrix", "affine"),
    "not_unit_quaternion": (_set("nodes.1.rotation", [0, 0, 0, 2]), "nodes[1].rotation", "unit quaternion"),
    "beyond_float32_composed": (lambda d: (d["nodes"][1].update(scale=[1e20] * 3), d["nodes"][2].update(scale=[1e20] * 3)),
                                "nodes[2]", "float32"),
    "places_beyond_float32": (lambda d: d["nodes"][2].update(translation=[3e38, 0, 0], scale=[3e38] * 3),
                              "nodes[2]", "places its mesh beyond float32"),
    "alpha_cutoff_string": (_set("materials.0.alphaCutoff", "0.5"), "materials[0].alphaCutoff", "finite number"),
    "alpha_cutoff_above_1": (_set("materials.0.alphaCutoff", 1.5), "materials[0].alphaCutoff", "[0.0, 1.0]"),
    "alpha_cutoff_negative": (_set("materials.0.alphaCutoff", -0.1), "materials[0].alphaCutoff", "[0.0, 1.0]"),
    "alpha_mode": (_set("materials.0.alphaMode", "CUTOUT"), "materials[0].alphaMode", "not one of"),
    "double_sided_number": (_set("materials.1.doubleSided", 1), "materials[1].doubleSided", "true or false"),
    "base_colour_3": (_set("materials.1.pbrMetallicRoughness.baseColorFactor", [0.5, 0.5, 0.5]),
                      "materials[1].pbrMetallicRoughness.baseColorFactor", "4 finite numbers"),
    "base_colour_range": (_set("materials.1.pbrMetallicRoughness.baseColorFactor", [2, 0.5, 0.5, 1]),
                          "baseColorFactor", "[0.0, 1.0]"),
    "emission_negative": (_set("materials.1.emissiveFactor", [-1, 0, 0]), "materials[1].emissiveFactor", ">= 0.0"),
    "tex_coord_1": (_set("materials.0.pbrMetallicRoughness.baseColorTexture.texCoord", 1), "texCoord", "TEXCOORD_0"),
    "embedded_buffer_short": (_set("buffers.0.uri", "data:application/octet-stream;base64,AAAA"), "buffers[0]",
                              "embedded buffer has 3 bytes"),
    "embedded_buffer_base64": (_set("buffers.0.uri", "data:application/octet-stream;base64,A@A"), "buffers[0].uri",
                               "malformed"),
    "embedded_buffer_not_base64": (_set("buffers.0.uri", "data:text/plain,abc"), "buffers[0].uri", "base64 data URI"),
    "buffer_without_uri": (lambda d: d["buffers"][0].pop("uri"), "buffers[0].uri", "only the first buffer of a .glb"),
    "remote_image": (_set("images.0.uri", "https://example.com/tex.png"), "images[0].uri", "relative file"),
    "missing_buffer_file": (_set("buffers.0.uri", "nope.bin"), "buffers[0].uri", "not found"),
    "extension_required": (_set("extensionsRequired", ["EXT_meshopt_compression"]), "extensionsRequired",
                           "does not read: EXT_meshopt_compression"),
    "extensions_not_names": (_set("extensionsUsed", "KHR_lights_punctual"), "extensionsUsed", "array of extension"),
    "texture_transform_uv_set": (_set("materials.0.pbrMetallicRoughness.baseColorTexture.extensions",
                                      {"KHR_texture_transform": {"texCoord": 1}}), "KHR_texture_transform.texCoord",
                                 "TEXCOORD_0"),
    "emissive_strength_negative": (lambda d: d["materials"][1].update(
        emissiveFactor=[1, 1, 1], extensions={"KHR_materials_emissive_strength": {"emissiveStrength": -2}}),
        "emissiveStrength", ">= 0.0"),
    "nodes_not_array": (_set("nodes", {"a": 1}), "nodes", "expected an array"),
    "node_not_object": (_set("nodes.2", 3), "nodes[2]", "JSON object"),
    "primitives_empty": (_set("meshes.1.primitives", []), "meshes[1].primitives", "non-empty"),
    "mode_lines": (_set("meshes.1.primitives.0.mode", 1), "meshes[1].primitives[0].mode", "triangle"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_broken_gltf_field_is_named(tmp_path, case):
    edit, field, words = CASES[case]
    refused(tmp_path, edit, field, words)


def test_document_that_is_not_an_object_is_refused(tmp_path):
    path = write_scene(tmp_path)
    (tmp_path / "tiny.gltf").write_text("[1, 2, 3]")
    with pytest.raises(DiviewerError, match="JSON object"):
        load_scene(path)
    (tmp_path / "tiny.gltf").write_text("[" * 100000)  # deeper than json's recursion limit
    with pytest.raises(DiviewerError, match="neither a glTF JSON file"):
        load_scene(path)


def test_all_degenerate_mesh_is_refused(tmp_path):
    doc, blob = gltf_document()
    raw = bytearray(blob)
    raw[0:48] = np.zeros((4, 3), np.float32).tobytes()  # the quad's 4 positions all at the origin
    got = load_mutated(tmp_path, doc, bytes(raw))
    assert isinstance(got, DiviewerError) and "meshes[0].primitives[0]" in str(got) and "zero area" in str(got)


def test_percent_encoded_uris_are_decoded(tmp_path):
    doc, _ = gltf_document()
    doc["images"][0]["uri"] = "my%20tex%C3%A9.png"
    path = write_scene(tmp_path, doc=doc)
    (tmp_path / "tex.png").rename(tmp_path / "my texé.png")
    scene = load_scene(path)
    assert scene.materials["leaf"].texture_source.endswith("my texé.png")


def test_the_valid_document_loads_with_its_hierarchy(tmp_path):
    scene = load_scene(write_scene(tmp_path))
    cube = next(o for o in scene.default.objects if o.name == "cube")
    assert cube.rotation[1] == pytest.approx(45.0, abs=1e-4), "the parent's rotation is composed"
    assert scene.materials["leaf"].is_masked and scene.materials["leaf"].alpha_cutoff == 0.5
    assert scene.materials["stone"].albedo == pytest.approx((0.6, 0.5, 0.4))
    assert not scene.materials["leaf"].double_sided, "glTF's doubleSided is false unless the material says so"


# --- textures by their real format ----------------------------------------------------------------------
def test_16_bit_greyscale_is_grey_not_white(tmp_path):
    from PIL import Image

    grey = np.full((4, 4), 32768, np.uint16)  # 50 % in sRGB terms
    Image.fromarray(grey).save(tmp_path / "g16.png")
    assert Image.open(tmp_path / "g16.png").mode.startswith("I")
    rgb, alpha = load_texture(tmp_path / "g16.png")
    assert alpha is None and rgb.shape == (4, 4, 3)
    np.testing.assert_allclose(rgb, srgb_to_linear(32768 / 65535), rtol=1e-5)


def test_float_tiff_is_linear_not_black(tmp_path):
    from PIL import Image

    values = np.linspace(0.0, 1.0, 16, dtype=np.float32).reshape(4, 4)
    Image.fromarray(values, mode="F").save(tmp_path / "f.tif")
    rgb, _ = load_texture(tmp_path / "f.tif")
    np.testing.assert_allclose(rgb[..., 1], values, rtol=1e-6)
    Image.fromarray(values * 3, mode="F").save(tmp_path / "bright.tif")
    with pytest.raises(DiviewerError, match=r"bright.tif.*\[0, 1\]"):
        load_texture(tmp_path / "bright.tif")


def test_32_bit_integer_tiff_scales_by_its_depth(tmp_path):
    from PIL import Image

    Image.fromarray(np.full((2, 2), 2 ** 30, np.int32), mode="I").save(tmp_path / "i.tif")
    rgb, _ = load_texture(tmp_path / "i.tif")
    np.testing.assert_allclose(rgb, srgb_to_linear(2 ** 30 / (2 ** 32 - 1)), rtol=1e-5)


def test_oversized_texture_names_itself_and_how_to_downscale(tmp_path):
    from PIL import Image

    Image.new("RGB", (MAX_TEXTURE_SIDE + 1, 2)).save(tmp_path / "wide.png")
    with pytest.raises(DiviewerError) as exc:
        load_texture(tmp_path / "wide.png", path=tmp_path / "s.toml", field="materials.m.texture")
    msg = str(exc.value)
    assert "wide.png" in msg and "materials.m.texture" in msg and "thumbnail" in msg and str(MAX_TEXTURE_SIDE) in msg


# --- hypothesis: mutations of the valid document ------------------------------------------------------------
KEYS = ["nodes", "children", "mesh", "matrix", "rotation", "scale", "translation", "accessors", "bufferView",
        "byteOffset", "byteStride", "byteLength", "count", "type", "componentType", "normalized", "indices",
        "material", "attributes", "POSITION", "NORMAL", "TEXCOORD_0", "uri", "source", "sampler", "index",
        "alphaMode", "alphaCutoff", "doubleSided", "baseColorFactor", "baseColorTexture", "emissiveFactor", "scene",
        "mode"]

leaves = (st.none() | st.booleans() | st.integers(-3, 8) | st.sampled_from([-1, 2 ** 31, 2 ** 32 + 1, 10 ** 12, 5126, 5123])
          | st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from(["MASK", "VEC3", "SCALAR", "tex.png",
                                                                              "../tiny.bin", "%2e%2e", ""])
          | st.text(max_size=6))
values = st.recursive(leaves, lambda kids: st.lists(kids, max_size=5) | st.dictionaries(st.sampled_from(KEYS), kids, max_size=3),
                      max_leaves=12)


@st.composite
def mutated_documents(draw):
    """The valid document with 1-3 edits: a value replaced, a key or item removed, or an item added."""
    doc, _ = gltf_document()
    mutate(draw, doc, draw(st.integers(1, 3)), values, st.sampled_from(KEYS))
    return doc


_counter = itertools.count()


def _check_sound(scene) -> None:
    """What a sound load promises: finite geometry and normals, faces in range, objects that resolve."""
    for m in scene.meshes.values():
        assert np.all(np.isfinite(m.vertices)) and np.all(np.isfinite(m.normals))
        assert len(m.faces) and int(m.faces.max()) < len(m.vertices)
    for o in scene.default.objects:
        assert o.mesh in scene.meshes and o.material in scene.materials
        assert np.all(np.isfinite(o.matrix()))
    for mat in scene.materials.values():
        assert 0.0 <= min(mat.albedo) and max(mat.albedo) <= 1.0 and 0.0 <= mat.alpha_cutoff <= 1.0


@settings(deadline=timedelta(seconds=LIMIT_S), max_examples=60)
@given(doc=mutated_documents())
def test_mutated_gltf_loads_soundly_or_is_refused(tmp_path, doc):
    got = load_mutated(tmp_path / f"m{next(_counter)}", doc)
    if not isinstance(got, DiviewerError):
        _check_sound(got)


@settings(deadline=timedelta(seconds=LIMIT_S), max_examples=12)
@given(doc=mutated_documents())
def test_mutated_gltf_that_loads_renders_finite(ctx, tmp_path, doc):
    from diviewer.gl.renderer import Renderer, RenderSettings

    got = load_mutated(tmp_path / f"r{next(_counter)}", doc)
    if isinstance(got, DiviewerError):
        return
    with time_limit():
        renderer = Renderer(ctx, got, 16, 16, RenderSettings(shadow_size=256))
        try:
            frame = renderer.frame()
        finally:
            renderer.release()
    for name in ("depth", "normal", "albedo", "direct"):
        assert np.all(np.isfinite(frame[name])), name


def test_mutations_reach_both_outcomes(tmp_path):
    """The generator is not vacuous: it finds mutants that load soundly and mutants that are refused."""
    from hypothesis import find

    for want_refusal in (False, True):
        doc = find(mutated_documents(), lambda d: want_refusal == isinstance(
            load_mutated(tmp_path / f"f{next(_counter)}", d), DiviewerError), settings=settings(max_examples=200))
        json.dumps(doc)  # a plain JSON document


@settings(max_examples=60, deadline=timedelta(seconds=LIMIT_S))
@given(cut=st.integers(0, 10_000), flip=st.integers(0, 10_000), byte=st.integers(0, 255))
def test_truncated_or_corrupted_glb_loads_soundly_or_is_refused(tmp_path_factory, cut, flip, byte):
    """Any prefix of a valid .glb, with any one byte changed, loads or ends in one DiviewerError naming it."""
    from gltf_doc import glb_bytes, scene_toml

    folder = tmp_path_factory.mktemp("glb")
    doc, blob = gltf_document()
    data = bytearray(glb_bytes(doc, blob))
    if data:
        data[flip % len(data)] = byte
    data = bytes(data[:len(data) - cut % (len(data) + 1)])
    write_scene(folder)
    (folder / "x.glb").write_bytes(data)
    (folder / "scene.toml").write_text(scene_toml("x.glb"))
    with time_limit():
        try:
            load_scene(folder / "scene.toml")
        except DiviewerError as exc:
            assert "x.glb" in str(exc), str(exc)
