"""diviewer.evaluation.evaluate.area_direct_of: the area direct light of a set made from (or restamped to) a scene file outside
assets/ is rendered from that file."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.evaluation.evaluate import area_direct_of
from diviewer.scene import load_scene

ASSETS = Path(__file__).resolve().parents[2] / "assets" / "scenes"


def _set(tmp_path: Path, scene_file: Path | None, scene_hash: str) -> SimpleNamespace:
    scene = load_scene("cornell")
    manifest = {"scene": "cornell", "scene_hash": scene_hash, "resolution": [16, 16],
                "scene_file": str(scene_file) if scene_file else None}
    return SimpleNamespace(manifest=manifest, root=tmp_path, frames=[{"index": 0, "config": scene.default.to_dict()}])


def test_the_sets_own_scene_file_is_used(tmp_path, ctx):
    copy = tmp_path / "cornell.toml"
    text = (ASSETS / "cornell.toml").read_text()
    # an edit the frames cannot see (a mesh no object uses): another file, another hash
    copy.write_text(text.replace("[meshes.cube]", '[meshes.spare]\nshape = "box"\nsize = [0.2, 0.2, 0.2]\n[meshes.cube]'))
    own = load_scene(str(copy))
    assert own.file_hash != load_scene("cornell").file_hash
    out = area_direct_of(_set(tmp_path, copy, own.file_hash), {2}, ctx=ctx)
    light = out[2][0]
    assert light.shape[:2] == (16, 16) and np.all(np.isfinite(light)) and light.max() > 0


def test_a_set_whose_file_is_gone_falls_back_to_the_shipped_scene_and_is_checked(tmp_path, ctx):
    with pytest.raises(DiviewerError, match="scene_hash"):
        area_direct_of(_set(tmp_path, tmp_path / "gone.toml", "0" * 64), {2}, ctx=ctx)
    shipped = load_scene("cornell").file_hash
    assert 0 in area_direct_of(_set(tmp_path, tmp_path / "gone.toml", shipped), {2}, ctx=ctx)[2]
