"""diviewer.bench.lean and the bench's two inference paths: each path's inference as a ratio to bare generators."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("onnx")


def test_both_paths_get_a_ratio_to_the_bare_generator():
    from diviewer.bench.core import bare_ratio_lines

    def row(path, ms):
        return {"kind": "neural", "label": f"m K=16 fp32 {path}", "K": 16, "levels": 7, "resolution": [128, 128],
                "gi_resolution": [128, 128], "inference_path": path, "timing": {"stages": {"inference": {"median": ms}}}}

    bare = {"kind": "untrained", "label": "untrained K=16 fp32", "K": 16, "levels": 7, "resolution": [128, 128],
            "gi_resolution": [128, 128], "untrained": True, "timing": {"stages": {"inference": {"median": 4.0}}}}
    rows = [row("lean", 5.0), row("graph", 10.0), bare]
    lines = bare_ratio_lines(rows)
    assert rows[0]["bare_ratio"] == pytest.approx(1.25) and rows[1]["bare_ratio"] == pytest.approx(2.5)
    assert any("lean" in line and "1.25 x" in line for line in lines)
    assert any("graph" in line and "2.50 x" in line for line in lines)


def test_bench_paths_are_checked():
    from diviewer.bench import BenchSettings
    from diviewer.errors import DiviewerError

    with pytest.raises(DiviewerError, match="lean and/or graph"):
        BenchSettings(paths=("fast",)).check()
    with pytest.raises(DiviewerError, match="lean and/or graph"):
        BenchSettings(paths=()).check()


def test_run_paths_times_the_lean_and_graph_path_against_both_bare_generators(gl_context, tmp_path):
    """One round of one frame on the shipped cornell model: both paths, both bare generators, every ratio."""
    from diviewer.bench.lean import main

    out = tmp_path / "lean.json"
    with gl_context:
        assert main(["--scene", "cornell", "--res", "32", "--frames", "1", "--warmup", "0", "--rounds", "1",
                     "--json", str(out), "assets/models/cornell.onnx"]) == 0
    result = json.loads(out.read_text())
    (row,) = result["rows"]
    assert row["K"] == 16 and row["lean_note"] is None and row["input_planes"] == 16
    assert row["network_input"] == [128, 128] and row["edge_guard"] == 8
    for key in ("lean_over_bare", "lean_over_bare_padded", "graph_over_bare", "graph_over_bare_padded"):
        assert row[key] > 0
    assert set(row["stages"]["lean"]) >= {"readback", "inference", "upload", "frame"}
    assert result["command"].startswith("python -m diviewer.bench.lean --scene cornell")
