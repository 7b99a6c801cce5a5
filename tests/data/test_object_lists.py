"""diviewer.data.object_lists: each distinct frame object list stored once in a manifest, read back in full."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from diviewer.data.dataset import read_manifest
from diviewer.data.object_lists import FIELD, expand_object_lists, share_object_lists
from diviewer.errors import DiviewerError

ASSETS = Path(__file__).resolve().parents[2] / "assets" / "evalsets"


def _manifest() -> dict:
    wall = [{"name": "wall", "mesh": "quad", "position": [0.0, 1.0, 2.0]}]
    box = [*wall, {"name": "center", "mesh": "box", "position": [0.5, 0.0, 0.0]}]
    frames = [{"index": i, "split": "test", "config": {"camera": {"fov": 40 + i}, "objects": copy.deepcopy(objs)}}
              for i, objs in enumerate((wall, box, wall, box, wall))]
    frames.append({"index": 5, "split": "test", "config": {"camera": {"fov": 50}}})  # no object list: left as is
    frames.append({"index": 6, "split": "test", "config": "not a table"})  # read_manifest's checks are not ours
    return {"format": "diviewer-dataset", "scene": "s", "frame_list": frames, "after": 1}


def test_distinct_lists_are_stored_once_in_order_of_first_use_and_read_back_equal():
    m = _manifest()
    before = copy.deepcopy(m)
    shared = share_object_lists(m)
    assert m == before  # the input is not changed
    assert [len(x) for x in shared[FIELD]] == [1, 2]
    assert [f["config"].get("objects") if isinstance(f["config"], dict) else None for f in shared["frame_list"]] == [
        {"list": 0}, {"list": 1}, {"list": 0}, {"list": 1}, {"list": 0}, None, None]
    assert share_object_lists(shared) is shared  # already shared
    back = expand_object_lists(json.loads(json.dumps(shared)))
    assert back == before and FIELD not in back
    back["frame_list"][0]["config"]["objects"][0]["name"] = "changed"  # copies: one frame's edit is its own
    assert back["frame_list"][2]["config"]["objects"][0]["name"] == "wall"
    plain = {"frame_list": [{"index": 0, "split": "a", "config": {}}]}
    assert share_object_lists(plain) is plain and expand_object_lists(plain) is plain


@pytest.mark.parametrize("ref, field", [({"list": 2}, "frame_list[1].config.objects"),
                                        ({"list": True}, "frame_list[1].config.objects"),
                                        ({"list": 0, "extra": 1}, "frame_list[1].config.objects"),
                                        ("table", FIELD)])
def test_a_broken_reference_or_table_is_refused_naming_the_field(ref, field, tmp_path):
    shared = share_object_lists(_manifest())
    if ref == "table":
        shared[FIELD] = {"0": []}
    else:
        shared["frame_list"][1]["config"]["objects"] = ref
    with pytest.raises(DiviewerError) as err:
        expand_object_lists(shared, tmp_path / "manifest.json")
    assert f"manifest.json: {field}: " in str(err.value)


@pytest.mark.parametrize("scene", ["cornell", "sponza"])
def test_the_shipped_compact_sets_store_each_list_once_and_read_back_full_lists(scene):
    raw = json.loads((ASSETS / scene / "manifest.json").read_text())
    read = read_manifest(ASSETS / scene)
    distinct = {json.dumps(f["config"]["objects"], sort_keys=True) for f in read["frame_list"]}
    assert len(raw[FIELD]) == len(distinct) and FIELD not in read
    assert all(set(f["config"]["objects"]) == {"list"} for f in raw["frame_list"])
    assert all(isinstance(f["config"]["objects"], list) and f["config"]["objects"] for f in read["frame_list"])
    if scene == "sponza":  # static geometry: one list for every frame
        assert len(raw[FIELD]) == 1 and len(raw[FIELD][0]) > 100
