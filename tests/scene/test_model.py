"""The scene's records (`diviewer.scene.model`): a frame's configuration as the dict datasets and cards store."""

from __future__ import annotations

import dataclasses

from diviewer.scene import load_scene, sample_config
from diviewer.scene.model import _record


def _asdict_config(config) -> dict:
    """What FrameConfig.to_dict returned when it called dataclasses.asdict on every record."""
    def light(l):
        d = dataclasses.asdict(l)
        d["type"] = d.pop("kind")
        return d

    return {"camera": dataclasses.asdict(config.camera), "lights": [light(l) for l in config.lights],
            "objects": [dataclasses.asdict(o) for o in config.objects]}


def test_a_frames_dict_is_asdicts_without_its_deep_copy():
    """Every dataset's frame list holds these dicts (and its hash reads them): the shallow copy must give the same
    dict as asdict did, for the default frame and sampled ones of each split."""
    scene = load_scene("cornell")
    configs = [scene.default] + [sample_config(scene, seed, split)
                                 for seed, split in enumerate(("train", "val", "test"))]
    for config in configs:
        assert config.to_dict() == _asdict_config(config)


def test_a_record_holding_something_mutable_gets_a_copy():
    @dataclasses.dataclass(frozen=True)
    class Holder:
        name: str
        values: tuple = ()
        table: dict = dataclasses.field(default_factory=dict)

    flat = Holder("a", (1.0, (2, 3)))
    assert _record(flat) == dataclasses.asdict(flat)
    nested = Holder("b", (1.0,), {"k": [1, 2]})
    d = _record(nested)
    assert d == dataclasses.asdict(nested) and d["table"] is not nested.table and d["table"]["k"] is not nested.table["k"]
