"""tools/ship_ladder.py: the smallest K within the tolerance of the best, ablation runs kept apart."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from tool_modules import load_tool

pytest.importorskip("torch")  # parameter counts build the generators


def _tool():
    return load_tool("ship_ladder")


def _results(root: Path, psnr: dict[str, float]) -> Path:
    runs = {}
    for tag, p in psnr.items():
        q = {"mse": 0.01, "psnr": p + 3, "ssim": 0.9, "mse_tm": 0.01, "psnr_tm": p, "ssim_tm": 0.8}
        runs[f"toy/{tag}"] = {"last_row": {"step": "100"}, "best_ckpt": True,
                              "test": {"frames": 5, "reference_spp": 64,
                                       "methods": {m: {k: {"mean": v, "std": 0.0} for k, v in q.items()}
                                                   for m in ("neural", "direct")}}}
    root.mkdir(parents=True)
    (root / "record.json").write_text(json.dumps({"runs": runs, "machine": {"node": "test"},
                                                  "scenes": {"toy": {"frames": 10}}}))
    return root


@pytest.mark.parametrize("psnr,chosen", [
    ({"k8": 30.0, "k16": 30.4, "k32": 29.0}, 8),       # K=8 within 0.5 dB of the best (K=16)
    ({"k8": 29.8, "k16": 30.4, "k32": 30.5}, 16),      # K=8 is 0.7 dB below the best (K=32): the next K
    ({"k8": 25.0, "k16": 26.0, "k32": 30.0}, 32),      # only the best is near enough
])
def test_the_smallest_k_within_the_tolerance_is_chosen(tmp_path, monkeypatch, psnr, chosen):
    tool = _tool()
    monkeypatch.setattr(tool, "MODELS", tmp_path / "models")
    (tmp_path / "models").mkdir()
    results = _results(tmp_path / "results", {**psnr, "k16_transpose": 40.0})  # an ablation never competes
    monkeypatch.setattr(sys, "argv", ["ship_ladder", "toy", "--results", str(results)])
    tool.main()
    record = json.loads((tmp_path / "models" / "toy_ladder.json").read_text())
    assert record["chosen_K"] == chosen
    assert [r["K"] for r in record["rows"]] == [8, 16, 32]
    assert [r["run"] for r in record["ablations"]] == ["k16_transpose"]
    assert record["rows"][0]["parameters"] < record["rows"][1]["parameters"] < record["rows"][2]["parameters"]


def test_shipping_a_model_that_did_not_come_back_is_refused(tmp_path, monkeypatch):
    tool = _tool()
    monkeypatch.setattr(tool, "MODELS", tmp_path / "models")
    (tmp_path / "models").mkdir()
    results = _results(tmp_path / "results", {"k8": 30.0})
    monkeypatch.setattr(sys, "argv", ["ship_ladder", "toy", "--results", str(results), "--ship"])
    with pytest.raises(SystemExit, match="did not come back"):
        tool.main()
    assert not (tmp_path / "models" / "toy.onnx").exists()
