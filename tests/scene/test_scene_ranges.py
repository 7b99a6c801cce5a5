"""A scene file's [ranges] for lights: a point light's position box (drawn inside it, refused outside the scene's
bounds or on a sun), and unknown keys answered with the keys the table allows."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diviewer.errors import DiviewerError
from diviewer.scene import load_scene, sample_config
from diviewer.scene.model import box_contains
from diviewer.scene.ranges_check import light_reasons
from room_doc import write_room

BOX = ((-1.5, 2.0, -1.5), (1.5, 2.8, 1.5))
RANGES = """
[ranges.lights.lamp]
position = [[-1.5, 2.0, -1.5], [1.5, 2.8, 1.5]]
intensity = [0.5, 2.0]
"""


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    return load_scene(write_room(tmp_path_factory.mktemp("room"), RANGES))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), split=st.sampled_from(["train", "val", "test"]))
def test_point_light_is_drawn_inside_its_box(room, seed, split):
    lamp = sample_config(room, seed, split).lights[0]
    assert box_contains(BOX, lamp.position)
    assert 0.5 * 5.0 * (1 - 1e-9) <= lamp.intensity <= 2.0 * 5.0 * (1 + 1e-9)
    assert light_reasons(lamp, room.default.lights[0], room.ranges.lights["lamp"], (0, 1.5, 0)) == []


def test_positions_fill_the_box(room):
    p = np.array([sample_config(room, s).lights[0].position for s in range(400)])
    lo, hi = np.asarray(BOX[0]), np.asarray(BOX[1])
    assert np.all(p.min(axis=0) < lo + 0.1 * (hi - lo)) and np.all(p.max(axis=0) > hi - 0.1 * (hi - lo))


def test_a_light_outside_its_box_is_out_of_range(room):
    import dataclasses

    lamp = dataclasses.replace(room.default.lights[0], position=(0.0, 1.0, 0.0))
    (why,) = light_reasons(lamp, room.default.lights[0], room.ranges.lights["lamp"], (0, 1.5, 0))
    assert "outside its trained box" in why


@pytest.mark.parametrize("ranges, words", [
    ("position = [[-1.0, 2.0, -1.0], [1.0, 3.5, 1.0]]", "leaves the scene's bounds"),
    ("position = [[1.0, 2.0, -1.0], [-1.0, 2.5, 1.0]]", "each min <= its max"),
    ("position = [[0.0, 2.0, 0.0]]", "[[min x, y, z], [max x, y, z]]"),
    ("position = [[-1.0, 2.0, -1.0], [1.0, 2.5, 1.0]]\nangle = [0.0, 90.0]", "not both"),
])
def test_bad_position_boxes_are_refused(tmp_path, ranges, words):
    with pytest.raises(DiviewerError, match=r"ranges\.lights\.lamp\.position") as info:
        load_scene(write_room(tmp_path, f"\n[ranges.lights.lamp]\n{ranges}\n"))
    assert words in str(info.value)


def test_a_sun_has_no_position_box(tmp_path):
    sun = '\n[[lights]]\nname = "sun"\ntype = "directional"\ndirection = [0.0, -1.0, 0.0]\n'
    with pytest.raises(DiviewerError, match="is a sun .*it has no position"):
        load_scene(write_room(tmp_path, sun + "\n[ranges.lights.sun]\nposition = [[0, 1, 0], [1, 2, 1]]\n"))


def test_unknown_key_lists_the_allowed_keys(tmp_path):
    with pytest.raises(DiviewerError) as info:
        load_scene(write_room(tmp_path, "\n[ranges.lights.lamp]\nregion = [[0, 1, 0], [1, 2, 1]]\n"))
    msg = str(info.value)
    assert "ranges.lights.lamp.region: unknown key 'region'; allowed keys: angle, axis, intensity, position" in msg


def test_a_range_for_an_unknown_light_lists_the_lights(tmp_path):
    with pytest.raises(DiviewerError, match=r"ranges\.lights\.lamb: no light named 'lamb'; lights: lamp"):
        load_scene(write_room(tmp_path, "\n[ranges.lights.lamb]\nintensity = [0.5, 2.0]\n"))
