"""The scene survey behind `diviewer inspect`: counts and areas of a procedural room, its open space found inside
the walls and off the pedestal, a suggested camera there, and the largest open box exact on small grids."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from diviewer.scene import load_scene
from diviewer.scene.model import box_contains
from diviewer.scene.survey import largest_box, survey
from room_doc import write_room

INSIDE = ((-2.0, 0.0, -2.0), (2.0, 3.0, 2.0))


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    return survey(load_scene(write_room(tmp_path_factory.mktemp("room"))))


def test_counts_bounds_and_emitters(report):
    assert report["bounds"]["min"] == [-2.2, -0.2, -2.2] and report["bounds"]["max"] == [2.2, 3.2, 2.2]
    assert report["triangles"] == 8 * 12 and report["objects"] == 8
    assert report["emissive"]["materials"] == {"panel": pytest.approx(2.08)}  # 1 x 1 x 0.02 box
    assert [l["name"] for l in report["lights"]] == ["lamp"] and report["warnings"] == []
    assert {m["name"]: m["objects"] for m in report["materials"]} == {"wall": 7, "panel": 1}


def test_suggested_camera_region_is_inside_the_room_and_clear_of_the_pedestal(report):
    s = report["suggested"]
    lo, hi = (np.asarray(x) for x in s["camera_region"]["region"])
    assert np.all(lo < hi)
    assert box_contains(INSIDE, lo) and box_contains(INSIDE, hi)
    pedestal = (np.array([-0.4, 0.0, -0.4]), np.array([0.4, 1.0, 0.4]))
    assert np.any(lo > pedestal[1]) or np.any(hi < pedestal[0])  # the boxes do not overlap
    assert np.prod(hi - lo) > 0.25 * 4 * 3 * 4  # a room-sized share, not a sliver
    cam = s["camera"]
    assert box_contains((lo, hi), cam["position"]) and cam["near"] < cam["far"] <= 1e5 * cam["near"]
    assert np.linalg.norm(np.subtract(cam["target"], cam["position"])) > 1.0


def _brute(mask: np.ndarray, max_aspect: float) -> int:
    best = 0
    ranges = [list(itertools.combinations_with_replacement(range(n), 2)) for n in mask.shape]
    for (x0, x1), (y0, y1), (z0, z1) in itertools.product(*ranges):
        sides = (x1 - x0 + 1, y1 - y0 + 1, z1 - z0 + 1)
        if max(sides) <= max_aspect * min(sides) and mask[x0:x1 + 1, y0:y1 + 1, z0:z1 + 1].all():
            best = max(best, (x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1))
    return best


@settings(max_examples=60, deadline=None)
@given(arrays(bool, st.tuples(st.integers(1, 4), st.integers(1, 4), st.integers(1, 5))),
       st.sampled_from([math.inf, 1.0, 2.0]))
def test_largest_box_is_the_largest_all_open_box(mask, max_aspect):
    got = largest_box(mask, max_aspect)
    if got is None:
        assert not mask.any()
        return
    first, last = got
    assert mask[first[0]:last[0] + 1, first[1]:last[1] + 1, first[2]:last[2] + 1].all()
    assert int(np.prod(last - first + 1)) == _brute(mask, max_aspect)
    assert max(last - first + 1) <= max_aspect * min(last - first + 1)


def test_a_solid_inside_is_not_open_space_and_the_room_is(tmp_path):
    from diviewer.scene.survey import OpenSpaceSettings, open_cells

    big = ('\n[meshes.block]\nshape = "box"\nsize = [1.6, 1.6, 1.6]\n'
           '\n[[objects]]\nname = "block"\nmesh = "block"\nmaterial = "wall"\nposition = [1.0, 1.0, 1.0]\n')
    mask, origin, size = open_cells(load_scene(write_room(tmp_path, big)), OpenSpaceSettings(cells=32))

    def at(p):
        return bool(mask[tuple(((np.asarray(p) - origin) / size).astype(int))])
    assert at((1.0, 1.0, 1.0)) is False  # the block's inside: rays from it meet back faces
    assert at((-1.0, 2.0, -1.0)) is True  # the room's air
    assert at((0.0, 0.5, 0.0)) is False  # the pedestal's inside (a smaller pocket)


def test_the_region_is_found_where_the_scene_camera_stands(tmp_path):
    from diviewer.scene.survey import suggest_camera

    wall = ('\n[meshes.partition]\nshape = "box"\nsize = [0.2, 3.0, 4.0]\n'
            '\n[[objects]]\nname = "partition"\nmesh = "partition"\nmaterial = "wall"\nposition = [1.0, 1.5, 0.0]\n')
    scene = load_scene(write_room(tmp_path, wall))  # a big room x < 0.9 and a small one x > 1.1
    anywhere = suggest_camera(scene)["camera_region"]["region"]
    assert anywhere[1][0] < 0.9  # the largest box: in the big room
    here = suggest_camera(scene, near=(1.6, 1.5, 0.0))["camera_region"]["region"]
    assert here[0][0] > 1.1 and here[1][0] < 2.0  # in the small room, where the camera is


def test_a_materials_emission_texture_is_named(tmp_path):
    from gltf_doc import gltf_document, write_scene

    doc, blob = gltf_document()
    doc["materials"][0].update(emissiveFactor=[1.0, 1.0, 1.0], emissiveTexture={"index": 0})
    rows = {m["name"]: m for m in survey(load_scene(write_scene(tmp_path, doc=doc, blob=blob)))["materials"]}
    assert rows["leaf"]["emission_texture"].endswith("tex.png") and rows["stone"]["emission_texture"] is None
