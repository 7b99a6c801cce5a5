"""tools/experiments/model_timing.py: every model timed at every size, interleaved, and the record written."""

from __future__ import annotations

import json

from onnx_models import base_meta, direct_times
from tool_modules import load_tool


def test_each_model_is_timed_at_each_size_and_recorded(tmp_path):
    tool = load_tool("experiments/model_timing")
    a, b = tmp_path / "a.onnx", tmp_path / "b.onnx"
    for p in (a, b):
        direct_times(p, meta=base_meta())
    out = tmp_path / "t.json"
    result = tool.main([str(a), str(b), "--size", "16", "32", "--rounds", "2", "--runs", "1", "--out", str(out)])
    assert json.loads(out.read_text())["times"] == {str(k): v for k, v in result["times"].items()}
    for size in (16, 32):
        rows = result["times"][size]
        assert set(rows) == {str(a), str(b)}
        for t in rows.values():
            assert 0 < t["min_ms"] <= t["median_ms"] <= t["max_ms"]
    assert result["environment"]["cpu_count"] >= 1 and "onnxruntime" in result["environment"]["versions"]
