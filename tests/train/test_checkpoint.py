"""A checkpoint's records (`diviewer.train.checkpoint`): the samples a refined truth really holds."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

from diviewer.train.checkpoint import truth_spp


def _dataset(root: Path, manifest: dict, refined: dict[int, dict]):
    (root / "frames").mkdir(parents=True)
    for i, rec in refined.items():
        (root / "frames" / f"{i:06d}.json").write_text(json.dumps({"index": i, "refined": rec}))
    return SimpleNamespace(manifest=manifest, path=lambda i, suffix=".npy": root / "frames" / f"{i:06d}{suffix}")


def test_a_refined_truths_samples_are_its_frames_own_counts(tmp_path):
    """Sponza's "256-spp" frames hold 64 + 195 (the sampler rounds 192 up): the record says so, over the frames
    asked for; a dataset never refined has none (its manifest's spp is the count)."""
    frames = {0: {"from_spp": 64, "extra_spp": 195}, 1: {"from_spp": 64, "extra_spp": 195},
              2: {"from_spp": 259, "extra_spp": 256}}
    ds = _dataset(tmp_path / "a", {"spp": 256, "refined": {"from_spp": 64}}, frames)
    assert truth_spp(ds, [0, 1]) == {"min": 259, "max": 259}
    assert truth_spp(ds, [0, 2]) == {"min": 259, "max": 515}
    assert truth_spp(ds, []) is None
    assert truth_spp(_dataset(tmp_path / "b", {"spp": 64}, {}), [0]) is None
