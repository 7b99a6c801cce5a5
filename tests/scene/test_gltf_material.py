"""glTF materials: KHR_texture_transform on the uvs, KHR_materials_emissive_strength, an emissive texture left out
with a warning (never a silent glow), unhonoured extensions named, the default material, and TOML overrides."""

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


def test_an_emissive_texture_is_left_out_with_a_warning_that_gives_its_mean(tmp_path):
    def edit(doc):
        doc["materials"][1].update(emissiveFactor=[1.0, 1.0, 0.5], emissiveTexture={"index": 0})
    with pytest.warns(SceneWarning, match=r"materials\[1\]\.emissiveTexture: material 'stone' glows by a texture"):
        scene = _load(tmp_path, edit)
    assert scene.materials["stone"].emission == (0.0, 0.0, 0.0)  # not a uniform glow
    (msg,) = [w for w in scene.warnings if "emissiveTexture" in w]
    mean = srgb_to_linear(np.array([200, 120, 60]) / 255.0) * (1.0, 1.0, 0.5)  # the checker's colour
    assert "[materials.stone] emission = [" + ", ".join(f"{x:.4g}" for x in mean) + "]" in msg


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
