"""diviewer.evaluation.frames.compact_choice: which frames of a split the compact set keeps."""

from __future__ import annotations

from diviewer.evaluation.frames import compact_choice, frame_meshes

WALLS = [{"mesh": "floor"}, {"mesh": "wall_back"}]


def entries(meshes: list[str], start: int = 24) -> list[dict]:
    return [{"index": start + k, "config": {"objects": [*WALLS, {"mesh": m}]}} for k, m in enumerate(meshes)]


def test_every_mesh_of_a_split_is_kept_before_any_second_frame():
    # cornell's unseen objects: the first six frames show only the capsule cluster and the torus.
    split = entries(["cluster", "cluster", "cluster", "torus", "torus", "cluster", "knot", "knot", "torus"])
    assert compact_choice(split, 3) == [24, 27, 30]
    # then the second frame of each, in the split's order
    assert compact_choice(split, 6) == [24, 25, 27, 28, 30, 31]
    assert compact_choice(split, 100) == [e["index"] for e in split]


def test_a_split_of_one_content_keeps_its_first_frames():
    split = entries(["atrium"] * 10, start=0)
    assert compact_choice(split, 4) == [0, 1, 2, 3]


def test_the_order_is_the_full_sets_not_the_groups():
    split = entries(["b", "a", "b", "c", "a"])
    assert compact_choice(split, 4) == [24, 25, 26, 27]
    assert compact_choice(split, 3) == [24, 25, 27]


def test_frame_meshes_ignores_the_objects_order():
    a = {"config": {"objects": [{"mesh": "x"}, {"mesh": "floor"}]}}
    b = {"config": {"objects": [{"mesh": "floor"}, {"mesh": "x"}]}}
    assert frame_meshes(a) == frame_meshes(b) == ("floor", "x")
