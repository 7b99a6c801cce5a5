"""A derived dataset's lineage and its source's checks (diviewer.data.lineage): every frame verified as `data check`
does before any work, evaluation sets and steps a derivation cannot carry refused by what the manifest says, the chain
of steps recorded, older manifests read from their records."""

from __future__ import annotations

import json

import pytest

from diviewer.data.dataset import Dataset, sha256_file
from diviewer.data.lineage import (CARRIES, derivation_source, lineage, problem_field, refuse_derived_evalset,
                                   verified_frames, with_step)
from diviewer.data.truth_filter import TruthFilter, filter_dataset
from diviewer.errors import DiviewerError

from tiny_datasets import flip_byte, tiny_capture

QUIET = dict(log=lambda *_: None)


def test_a_capture_has_no_steps_and_a_derived_manifest_adds_one_to_its_sources(tmp_path):
    src = tiny_capture(tmp_path / "src")
    assert lineage(src.manifest) == []
    m = with_step(src, json.loads(json.dumps(src.manifest)), "filter-truth", {"levels": 1})
    (step,) = m["lineage"]
    assert step["operation"] == "filter-truth" and step["settings"] == {"levels": 1}
    assert step["source"] == {"path": str(src.root), "hash": src.hash, "kind": "capture",
                              "manifest_sha256": sha256_file(src.root / "manifest.json")}
    mid = tiny_capture(tmp_path / "mid", **{"lineage": m["lineage"]})  # a dataset with that lineage, derived again
    chain = with_step(mid, json.loads(json.dumps(mid.manifest)), "refine", {"spp": 8})["lineage"]
    assert [s["operation"] for s in chain] == ["filter-truth", "refine"]
    assert chain[0] == step and chain[1]["source"]["hash"] == mid.hash


def test_an_older_manifest_reads_its_steps_from_its_records():
    m = {"spp": 512, "refined": {"from_hash": "b", "from_spp": 256, "before": {"from_hash": "a", "from_spp": 64}},
         "refined_from": "/d/256", "truth_filter": {"levels": 2, "normal_power": 32.0, "plane": 0.01,
                                                    "from_hash": "c", "how": "..."}, "truth_filter_from": "/d/512"}
    steps = lineage(m)
    assert [s["operation"] for s in steps] == ["refine", "refine", "filter-truth"]
    assert all(s["reconstructed"] for s in steps)
    assert [s["source"]["hash"] for s in steps] == ["a", "b", "c"]
    assert [s["settings"].get("spp") for s in steps[:2]] == [256, 512]
    assert steps[1]["source"]["path"] == "/d/256" and steps[0]["source"]["path"] is None
    assert steps[2]["settings"] == {"levels": 2, "normal_power": 32.0, "plane": 0.01}
    # a capture made with the area's direct light records it too, without a source: no step
    assert lineage({"direct_area": {"samples": 4, "how": "captured"}}) == []
    assert [s["operation"] for s in lineage({"direct_area": {"samples": 4, "from_hash": "d"}})] == ["area-direct"]
    with pytest.raises(DiviewerError, match="lineage"):
        lineage({"lineage": [{"settings": {}}]})


@pytest.mark.parametrize("kind", [{"kind": "evalset"}, {"compact": {"frames_per_split": 1}}])
@pytest.mark.parametrize("operation", sorted(CARRIES))
def test_an_evaluation_set_is_no_source(tmp_path, kind, operation):
    src = tiny_capture(tmp_path / "set", **kind)
    with pytest.raises(DiviewerError) as err:
        derivation_source(src.root, tmp_path / "out", operation)
    assert err.value.field == "kind" and "evaluation set" in str(err.value)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("operation, step, refused", [
    ("refine", "filter-truth", True), ("refine", "area-direct", False), ("refine", "refine", False),
    ("filter-truth", "filter-truth", True), ("filter-truth", "refine", False), ("area-direct", "area-direct", True),
    ("area-direct", "filter-truth", False), ("refine", "sharpen", True)])
def test_a_source_is_refused_by_the_steps_its_lineage_holds(tmp_path, operation, step, refused):
    src = tiny_capture(tmp_path / "src", lineage=[{"operation": step, "source": {"path": "/elsewhere"}}])
    if refused:
        with pytest.raises(DiviewerError) as err:
            derivation_source(src.root, tmp_path / "out", operation)
        assert err.value.field == "lineage" and "/elsewhere" in str(err.value)
    else:
        assert derivation_source(src.root, tmp_path / "out", operation).hash == src.hash


def test_an_older_filtered_dataset_is_refused_as_refines_source(tmp_path):
    src = tiny_capture(tmp_path / "src", truth_filter={"levels": 1, "from_hash": "a"}, truth_filter_from="/capture")
    with pytest.raises(DiviewerError, match="filtered.*cannot carry.*/capture"):
        derivation_source(src.root, tmp_path / "out", "refine")


@pytest.mark.parametrize("damage, field", [
    (lambda ds: flip_byte(ds.path(1)), "sha256"),  # a pixel's byte: only the checksum sees it
    (lambda ds: flip_byte(ds.path(1), 0), "sha256"),  # the array's header: unreadable, and its checksum differs
    (lambda ds: ds.path(1).write_bytes(ds.path(0).read_bytes()), "sha256"),
    (lambda ds: ds.path(1, ".json").write_text("{"), "sidecar")])
def test_an_unsound_frame_is_refused_naming_its_file_and_field(tmp_path, damage, field):
    src = tiny_capture(tmp_path / "src")
    damage(src)
    for partial in (False, True):  # --partial derives around absent frames, never around corrupt ones
        with pytest.raises(DiviewerError) as err:
            verified_frames(src, "refine", partial=partial, **QUIET)
        assert err.value.field == field and err.value.path == src.path(1) and "frame 1" in str(err.value)


def test_an_absent_frame_is_refused_unless_partial(tmp_path):
    src = tiny_capture(tmp_path / "src", frames=4)
    src.path(2).unlink()
    src.path(3, ".json").unlink()  # an interrupted write
    with pytest.raises(DiviewerError, match="incomplete: 2 of 4") as err:
        verified_frames(src, "refine", **QUIET)
    assert err.value.field == "frame_list"
    said = []
    assert [f["index"] for f in verified_frames(src, "refine", partial=True, log=said.append)] == [0, 1]
    assert "2 of 4 source frames absent" in said[0]


def test_problem_words_map_to_fields():
    assert problem_field("checksum mismatch (corrupted or truncated)") == "sha256"
    assert problem_field("shape (1, 2, 3), expected (4, 5, 6)") == "resolution"
    assert problem_field("non-finite values in pt") == "channels"
    assert problem_field("missing") == "frame_list"


def test_a_derived_dataset_records_its_chain_and_eval_refuses_such_a_set(tmp_path):
    src = tiny_capture(tmp_path / "src")
    filter_dataset(src.root, tmp_path / "f", TruthFilter(), **QUIET)
    f = Dataset(tmp_path / "f")
    assert [s["operation"] for s in f.manifest["lineage"]] == ["filter-truth"]
    assert f.manifest["lineage"][0]["source"]["hash"] == src.hash
    with pytest.raises(DiviewerError, match="cannot carry") as err:
        derivation_source(f.root, tmp_path / "r", "refine")
    assert err.value.field == "lineage"
    refuse_derived_evalset(src.manifest, src.root)  # as rendered: nothing to refuse
    with pytest.raises(DiviewerError, match="not as `diviewer evalset` rendered it") as err:
        refuse_derived_evalset({**f.manifest, "kind": "evalset"}, f.root)
    assert err.value.field == "lineage" and str(src.root) in str(err.value)
    with pytest.raises(DiviewerError, match="filtered"):  # an older derived set: its record says it
        refuse_derived_evalset({"kind": "evalset", "truth_filter": {"levels": 1, "from_hash": "a"}}, f.root)


@pytest.mark.mitsuba
def test_a_chain_of_derivations_keeps_every_step(tmp_path, gl_context):
    from diviewer.data.area import area_direct
    from diviewer.data.refine import refine

    src = tiny_capture(tmp_path / "src")
    area_direct(src.root, tmp_path / "area", 2, **QUIET)
    refine(tmp_path / "area", tmp_path / "refined", 8, **QUIET)
    filter_dataset(tmp_path / "refined", tmp_path / "filtered", TruthFilter(), **QUIET)
    area, refined, filtered = (Dataset(tmp_path / n) for n in ("area", "refined", "filtered"))
    steps = filtered.manifest["lineage"]
    assert [s["operation"] for s in steps] == ["area-direct", "refine", "filter-truth"]
    assert [s["source"]["hash"] for s in steps] == [src.hash, area.hash, refined.hash]
    assert [s["settings"] for s in steps] == [{"samples": 2}, {"spp": 8, "from_spp": 4},
                                              {"levels": 1, "normal_power": 32.0, "plane": 0.01}]
    assert filtered.check() == [] and {"direct_area", "refined", "truth_filter"} <= set(filtered.manifest)
    # each step's records stay: an older reader, without the lineage, finds the same operations
    older = {k: v for k, v in filtered.manifest.items() if k != "lineage"}
    assert sorted(s["operation"] for s in lineage(older)) == sorted(s["operation"] for s in steps)
