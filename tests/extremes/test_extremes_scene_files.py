"""Scene files validated, never trusted (issue 29 item 5): ranges with min <= max everywhere, non-zero axes, test
stretches that leave training a stretch; hypothesis-generated mutations of a valid scene that end in a clean
error naming file and field, or in a scene whose every split samples finite configurations."""

from __future__ import annotations

from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diviewer.errors import DiviewerError
from diviewer.scene import sample_config
from diviewer.scene.loader import parse_scene
from diviewer.scene.scene_ranges import train_length
from mutation import mutate
from test_extremes_gltf import LIMIT_S, time_limit

PATH = Path("/scenes/fuzz.toml")


def valid_scene() -> dict:
    """A small scene with every kind of range: a light's, an object's, a camera path with test stretches."""
    return {
        "scene": {"name": "fuzz", "exposure": 0.0},
        "camera": {"position": [0, 1, 5], "target": [0, 0, 0], "fov": 45, "near": 0.1, "far": 50},
        "materials": {"m": {"albedo": [0.5, 0.5, 0.5]}, "glow": {"albedo": [0.2, 0.2, 0.2], "emission": [1, 1, 1]}},
        "meshes": {"b": {"shape": "box", "size": [1, 2, 1]}, "s": {"shape": "sphere", "subdivisions": 1},
                   "c": {"shape": "cylinder", "sections": 8}},
        "objects": [{"name": "floor", "mesh": "b", "material": "m", "scale": [4, 0.1, 4]},
                    {"name": "center", "mesh": "s", "material": "glow", "position": [0, 1, 0]}],
        "lights": [{"name": "sun", "type": "directional", "direction": [0, -1, 0.2], "irradiance": 2.0},
                   {"name": "bulb", "type": "point", "position": [1, 3, 1], "intensity": 5.0}],
        "ranges": {
            "lights": {"sun": {"axis": [1, 0, 0], "angle": [-30, 30], "intensity": [0.5, 2.0]}},
            "objects": {"center": {"axes": [[0, 1, 0], [1, 0, 0]], "angle": [0, 360], "offset": [[-1, 0, -1], [1, 0.5, 1]],
                                   "train_meshes": ["s"], "test_meshes": ["c"]}},
            "camera": {"positions": [[0, 1, 5], [3, 1, 4], [4, 2, 0]], "targets": [[0, 0, 0], [0, 0, 0], [0, 1, 0]],
                       "test_stretches": [[0.2, 0.3], [0.7, 0.8]], "closed": False},
        },
    }


def refused(data: dict, field: str, words: str = "") -> str:
    with pytest.raises(DiviewerError) as exc:
        parse_scene(data, path=PATH)
    msg = str(exc.value)
    assert str(PATH) in msg and field in msg and words in msg, msg
    return msg


def test_the_valid_scene_samples_every_split():
    scene = parse_scene(valid_scene(), path=PATH)
    for split in ("train", "val", "test"):
        config = sample_config(scene, 3, split)
        assert np.all(np.isfinite(config.camera.position))


def _with(path: str, value) -> dict:
    data = valid_scene()
    keys = [int(k) if k.isdigit() else k for k in path.split(".")]
    obj = data
    for k in keys[:-1]:
        obj = obj[k]
    obj[keys[-1]] = value
    return data


RANGE_CASES = {
    "light_angle_reversed": ("ranges.lights.sun.angle", [30, -30], "ranges.lights.sun.angle", "min <= max"),
    "light_intensity_reversed": ("ranges.lights.sun.intensity", [2.0, 0.5], "ranges.lights.sun.intensity", "min <= max"),
    "light_axis_zero": ("ranges.lights.sun.axis", [0, 0, 0], "ranges.lights.sun.axis", "non-zero"),
    "object_angle_reversed": ("ranges.objects.center.angle", [360, 0], "ranges.objects.center.angle", "min <= max"),
    "object_offset_reversed": ("ranges.objects.center.offset", [[1, 0, -1], [-1, 0.5, 1]], "ranges.objects.center.offset",
                               "min must be <= its max"),
    "object_axis_zero": ("ranges.objects.center.axes", [[0, 1, 0], [0, 0, 0]], "ranges.objects.center.axes[1]", "non-zero"),
    "stretch_reversed": ("ranges.camera.test_stretches", [[0.3, 0.2]], "ranges.camera.test_stretches", "start < end"),
    "stretches_cover_all": ("ranges.camera.test_stretches", [[0.0, 0.6], [0.5, 1.0]], "ranges.camera.test_stretches",
                            "whole path"),
    "one_stretch_covers_all": ("ranges.camera.test_stretches", [[0.0, 1.0]], "ranges.camera.test_stretches", "whole path"),
    "keyframe_looks_nowhere": ("ranges.camera.targets", [[0, 0, 0], [3, 1, 4], [0, 1, 0]], "ranges.camera.targets",
                               "keyframe 1"),
    "region_reversed": ("ranges.camera", {"region": [[1, 0, 0], [-1, 2, 2]]}, "ranges.camera.region", "below its max"),
    "region_fov_reversed": ("ranges.camera", {"region": [[-1, 0, 2], [1, 2, 6]], "fov": [60, 30]}, "ranges.camera.fov",
                            "min <= max"),
}


@pytest.mark.parametrize("case", sorted(RANGE_CASES))
def test_bad_range_names_file_and_field(case):
    path, value, field, words = RANGE_CASES[case]
    refused(_with(path, value), field, words)


def test_train_length_merges_overlapping_stretches():
    assert train_length([]) == 1.0
    assert train_length([(0.2, 0.3), (0.25, 0.5)]) == pytest.approx(0.7)
    assert train_length([(0.0, 0.6), (0.5, 1.0)]) == pytest.approx(0.0)
    assert train_length([(0.5, 1.0), (0.0, 0.4)]) == pytest.approx(0.1)


# --- hypothesis: mutations of the valid scene -------------------------------------------------------------
SCENE_KEYS = ["position", "target", "up", "fov", "near", "far", "albedo", "emission", "shape", "size", "radius",
              "subdivisions", "mesh", "material", "scale", "rotation", "type", "direction", "irradiance", "intensity",
              "color", "axis", "angle", "axes", "offset", "train_meshes", "test_meshes", "positions", "targets",
              "test_stretches", "closed", "region", "target_jitter", "test_regions", "default_share", "name"]
# What TOML can hold (no null): numbers at the edges, names that exist, vectors, tables.
toml_leaves = (st.booleans() | st.integers(-3, 8) | st.sampled_from([0, -1, 10 ** 9, 2 ** 63 - 1])
               | st.floats(allow_nan=True, allow_infinity=True, width=64)
               | st.sampled_from(["s", "c", "b", "m", "glow", "sun", "center", "box", "point", "directional"])
               | st.text(max_size=5))
toml_values = st.recursive(toml_leaves, lambda kids: st.lists(kids, max_size=4)
                           | st.dictionaries(st.sampled_from(SCENE_KEYS), kids, max_size=3), max_leaves=10)


@st.composite
def mutated_scenes(draw):
    data = valid_scene()
    mutate(draw, data, draw(st.integers(1, 3)), toml_values, st.sampled_from(SCENE_KEYS))
    return data


@settings(deadline=timedelta(seconds=LIMIT_S), max_examples=80)
@given(data=mutated_scenes())
def test_mutated_scene_samples_finite_configs_or_is_refused(data):
    with time_limit():
        try:
            scene = parse_scene(data, path=PATH)
        except DiviewerError as exc:
            assert str(PATH) in str(exc), f"names no file: {exc}"
            return
        for split in ("train", "val", "test"):
            for seed in (0, 1):
                config = sample_config(scene, seed, split)
                c = config.camera
                assert np.all(np.isfinite([*c.position, *c.target, c.fov, c.near, c.far]))
                assert np.all(np.isfinite(c.view_matrix())) and np.all(np.isfinite(c.projection(1.0)))
                for o in config.objects:
                    assert np.all(np.isfinite(o.matrix())) and o.mesh in scene.meshes
                for light in config.lights:
                    assert all(np.isfinite(v) for v in getattr(light, "direction", getattr(light, "position", ())))
