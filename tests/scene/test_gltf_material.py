"""glTF materials: KHR_texture_transform on the uvs, KHR_materials_emissive_strength, an emissive texture kept as a
texture (never flattened to a uniform glow), unhonoured extensions named, the default material, and TOML overrides."""

from __future__ import annotations

import math

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.scene import load_scene
from diviewer.scene.colour import srgb_to_linear
from diviewer.scene.reads import SceneWarning
from gltf_doc import SCENE_TOML, gltf_document, write_scene

QUAD_UV = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float64)  # as gltf_doc writes it (glTF's v down)


def _load(tmp_path, edit=None, toml: str = SCENE_TOML):
    doc, blob = gltf_document()
    if edit:
        edit(doc)
    return load_scene(write_scene(tmp_path, doc=doc, blob=blob, toml=toml))


def _gltf_uv(scene) -> np.ndarray:
    uv = scene.meshes["quad"].uvs.astype(np.float64)
    return np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1)


def test_texture_transform_moves_the_uvs_as_the_extension_says(tmp_path):
    ext = {"offset": [0.5, 0.25], "rotation": math.pi / 2, "scale": [2.0, 3.0]}

    def edit(doc):
        doc["extensionsUsed"] = ["KHR_texture_transform"]
        doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] = {"KHR_texture_transform": ext}
    uv = _gltf_uv(_load(tmp_path, edit))
    # the spec's GLSL: translation * rotation * scale, rotation columns (cos, sin), (-sin, cos)
    s = QUAD_UV * (2.0, 3.0)
    expected = np.stack([-s[:, 1], s[:, 0]], axis=1) + (0.5, 0.25)
    assert np.allclose(uv, expected, atol=1e-6)


def test_emissive_strength_multiplies_the_emissive_factor(tmp_path):
    def edit(doc):
        doc["extensionsUsed"] = ["KHR_materials_emissive_strength"]
        doc["materials"][1].update(emissiveFactor=[1.0, 0.5, 0.25],
                                   extensions={"KHR_materials_emissive_strength": {"emissiveStrength": 8.0}})
    assert _load(tmp_path, edit).materials["stone"].emission == (8.0, 4.0, 2.0)


CHECKER_RGB = srgb_to_linear(np.array([200, 120, 60]) / 255.0)  # tex.png's colour, decoded as a base colour is


def test_an_emissive_texture_is_kept_as_a_texture_times_its_factor(tmp_path, recwarn):
    def edit(doc):
        doc["materials"][0].update(emissiveFactor=[1.0, 1.0, 0.5], emissiveTexture={"index": 0})
    leaf = _load(tmp_path, edit).materials["leaf"]
    assert leaf.emission == (1.0, 1.0, 0.5)  # the factor, not a uniform glow
    assert leaf.emission_texture.shape == (8, 8, 3) and leaf.emission_texture_source.endswith("tex.png")
    np.testing.assert_allclose(leaf.emission_texture.reshape(-1, 3), np.broadcast_to(CHECKER_RGB, (64, 3)), atol=1e-6)
    assert not [w for w in recwarn if "emissive" in str(w.message)]


def test_an_emissive_texture_under_a_zero_factor_is_not_read(tmp_path):
    def edit(doc):
        doc["materials"][0]["emissiveTexture"] = {"index": 0}  # glTF's emissiveFactor defaults to black
    leaf = _load(tmp_path, edit).materials["leaf"]
    assert leaf.emission == (0.0, 0.0, 0.0) and leaf.emission_texture is None and not leaf.is_emissive


def test_the_emissive_textures_transform_moves_the_uvs_of_a_material_without_a_base_colour_texture(tmp_path):
    ext = {"offset": [0.5, 0.25], "scale": [2.0, 3.0]}

    def edit(doc):
        doc["extensionsUsed"] = ["KHR_texture_transform"]
        leaf = doc["materials"][0]
        del leaf["pbrMetallicRoughness"]["baseColorTexture"], leaf["alphaMode"]
        leaf.update(emissiveFactor=[2.0, 2.0, 2.0],
                    emissiveTexture={"index": 0, "extensions": {"KHR_texture_transform": ext}})
    scene = _load(tmp_path, edit)
    assert scene.materials["leaf"].emission_texture is not None and scene.materials["leaf"].texture is None
    assert np.allclose(_gltf_uv(scene), QUAD_UV * (2.0, 3.0) + (0.5, 0.25), atol=1e-6)


def test_an_emissive_texture_placed_unlike_the_base_colour_is_left_out_with_a_warning(tmp_path):
    def edit(doc):
        doc["extensionsUsed"] = ["KHR_texture_transform"]
        doc["materials"][0].update(emissiveFactor=[1.0, 1.0, 1.0], emissiveTexture={
            "index": 0, "extensions": {"KHR_texture_transform": {"scale": [2.0, 2.0]}}})
    with pytest.warns(SceneWarning, match=r"materials\[0\]\.emissiveTexture: material 'leaf' places its emissive "
                                          r"texture .* with another transform than its base colour texture"):
        scene = _load(tmp_path, edit)
    leaf = scene.materials["leaf"]
    assert leaf.emission == (0.0, 0.0, 0.0) and leaf.emission_texture is None  # never a uniform glow
    assert np.allclose(_gltf_uv(scene), QUAD_UV, atol=1e-6)  # the base colour's (no) transform places the uvs


def test_a_toml_emission_replaces_the_factor_and_keeps_the_emissive_texture(tmp_path):
    def edit(doc):
        doc["materials"][0].update(emissiveFactor=[1.0, 1.0, 0.5], emissiveTexture={"index": 0})
    leaf = _load(tmp_path, edit, SCENE_TOML + "\n[materials.leaf]\nemission = [4.0, 2.0, 1.0]\n").materials["leaf"]
    assert leaf.emission == (4.0, 2.0, 1.0) and leaf.emission_texture is not None
    assert leaf.peak_emission == pytest.approx(tuple(CHECKER_RGB * (4.0, 2.0, 1.0)))


def test_unhonoured_extensions_are_named_and_required_ones_refused(tmp_path):
    def used(doc):
        doc["extensionsUsed"] = ["KHR_materials_specular", "KHR_texture_transform", "KHR_lights_punctual"]
    with pytest.warns(SceneWarning, match="not honoured.*KHR_materials_specular, KHR_lights_punctual"):
        scene = _load(tmp_path / "a", used)
    assert any("KHR_lights_punctual" in w for w in scene.warnings)

    def required(doc):
        doc["extensionsUsed"] = doc["extensionsRequired"] = ["KHR_materials_pbrSpecularGlossiness"]
    with pytest.raises(DiviewerError, match="extensionsRequired: .*does not read: KHR_materials_pbrSpecularGloss"):
        _load(tmp_path / "b", required)


def test_a_primitive_without_material_gets_the_stated_default_and_a_warning(tmp_path):
    def edit(doc):
        del doc["meshes"][1]["primitives"][0]["material"]
    with pytest.warns(SceneWarning, match=r"1 placed mesh\(es\) of the glTF have no material: .*'gltf_default'.*albedo 1 "):
        scene = _load(tmp_path / "a", edit)
    assert scene.materials["gltf_default"].albedo == (1.0, 1.0, 1.0)
    assert any("[materials.gltf_default] albedo" in w for w in scene.warnings)
    # the scene file gives it one, without editing the glTF
    scene = _load(tmp_path / "b", edit, SCENE_TOML + "\n[materials.gltf_default]\nalbedo = [0.5, 0.4, 0.3]\n")
    assert scene.materials["gltf_default"].albedo == (0.5, 0.4, 0.3) and not scene.warnings
    cube = next(o for o in scene.default.objects if o.name == "cube")
    assert cube.material == "gltf_default"


def test_toml_overrides_a_gltf_material_by_name_keeping_what_it_does_not_give(tmp_path):
    plain = _load(tmp_path / "a")
    toml = SCENE_TOML + ("\n[materials.stone]\nemission = [2.0, 2.0, 2.0]\n"
                         "\n[materials.leaf]\nalbedo = [0.5, 0.5, 0.5]\n")
    scene = _load(tmp_path / "b", toml=toml)
    stone, leaf = scene.materials["stone"], scene.materials["leaf"]
    assert stone.emission == (2.0, 2.0, 2.0) and stone.albedo == plain.materials["stone"].albedo
    assert stone.double_sided is False  # the glTF's, not the TOML default
    assert leaf.albedo == (0.5, 0.5, 0.5) and leaf.is_masked and np.array_equal(leaf.texture, plain.materials["leaf"].texture)
    assert scene.file_hash != plain.file_hash  # the override is part of what the scene looks like
    with pytest.raises(DiviewerError, match=r"materials\.stone\.glow: unknown key 'glow'; allowed keys: .*albedo"):
        _load(tmp_path / "c", toml=SCENE_TOML + "\n[materials.stone]\nglow = 1\n")


def test_a_misspelt_override_that_changes_nothing_is_named_in_a_warning(tmp_path):
    """[materials.NAME] for a name no glTF material has and no object uses overrides nothing: said, with the names
    the glTF's objects do use; a used override says nothing."""
    with pytest.warns(SceneWarning, match=r"materials\.ston: no glTF material is named 'ston' .*in use: .*stone"):
        scene = _load(tmp_path / "a", toml=SCENE_TOML + "\n[materials.ston]\nalbedo = [0.5, 0.5, 0.5]\n")
    assert any("materials.ston" in w for w in scene.warnings)
    scene = _load(tmp_path / "b", toml=SCENE_TOML + "\n[materials.stone]\nalbedo = [0.5, 0.5, 0.5]\n")
    assert not any("changes nothing" in w for w in scene.warnings)
