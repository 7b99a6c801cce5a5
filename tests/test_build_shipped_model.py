"""tools/build_shipped_model.py reads every shipped card's recipe, and a warm-started one's parent chain."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tool_modules import load_tool

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    return load_tool("build_shipped_model")


@pytest.mark.parametrize("card", sorted(p.stem for p in (ROOT / "assets" / "models").glob("*.onnx")
                                        if (p.with_suffix(".json")).is_file()))
def test_every_shipped_card_has_a_rebuildable_recipe(card):
    tool = _tool()
    r = tool.recipe(card)  # exits when a setting has no train option
    meta = json.loads((ROOT / "assets" / "models" / f"{card}.json").read_text())
    assert r["K"] == meta["K"] and r["dataset_hash"] == meta["dataset_hash"]
    assert set(r["train"]) <= set(tool._TRAIN_FLAGS)
    parent = r["init"]
    while parent is not None:  # a warm start names its parent's recipe and checkpoint
        assert len(parent["checkpoint_sha256"]) == 64 and set(parent["train"]) <= set(tool._TRAIN_FLAGS)
        parent = parent["init"]


def test_a_linear_baseline_is_refitted_on_its_networks_capture():
    tool = _tool()
    models = ROOT / "assets" / "models"
    baselines = [p.stem for p in models.glob("*.json") if json.loads(p.read_text()).get("kind") == "linear_baseline"]
    assert baselines, "cornell_linear is shipped"
    for name in baselines:
        card = json.loads((models / f"{name}.json").read_text())
        r = tool.recipe(name)
        net = json.loads((models / f"{card['scene']}.json").read_text())
        assert r["kind"] == "linear_baseline" and r["train"] == {} and r["init"] is None
        assert r["capture"] == net["recipe"]["capture"] and r["dataset_hash"] == net["dataset_hash"]
        assert r["fit"] == {"split": card["fit"]["split"], "frames": card["fit"]["frames"]}


def test_a_warm_started_recipe_builds_its_parent_first():
    tool = _tool()
    base = {"capture": {"frames": 10, "spp": 4, "max_depth": 4, "seed": 0, "split_fractions": [0.8, 0.2, 0.0]},
            "train": {"K": 4, "target": "indirect", "divide_albedo": True, "epochs": 3, "lr": 2e-4,
                      "train_frames": 8, "device": "cpu"}}
    child = {"capture": {**base["capture"], "frames": 40},
             "train": {**base["train"], "epochs": 1, "train_frames": None, "lr_decay": "cosine"},
             "init": {"checkpoint_sha256": "ab" * 32, "step": 6, "dataset_hash": "h-parent", "train_frames": 8,
                      "recipe": base}}
    r = tool._from_recipe(child, "toy", "cornell", "32x32", False, "h-child", Path("toy.json"),
                          {"K": 4, "target": "indirect", "divide_albedo": True})
    assert r["dataset_hash"] == "h-child" and r["capture"]["frames"] == 40 and "train_frames" not in r["train"]
    p = r["init"]
    assert p["name"] == "toy_init" and p["dataset_hash"] == "h-parent" and p["checkpoint_sha256"] == "ab" * 32
    assert (p["K"], p["target"], p["divide_albedo"]) == (4, "indirect", True) and p["train"]["train_frames"] == 8
    assert p["capture"]["frames"] == 10 and p["init"] is None
