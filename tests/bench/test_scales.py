"""`diviewer bench --render-scales`: the viewer's frame at each render scale, timed and scored against scale 1 (and
the path-traced truth), in the JSON and the table; bad scales refused before any work."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest
from hypothesis import given, settings as hsettings, strategies as st

from diviewer.bench.core import BenchSettings
from diviewer.errors import DiviewerError


def _rows(ctx, settings, ds=None, variants=(), net_of=None, notes=None):
    from diviewer.bench.runner import gl_timing_mode
    from diviewer.bench.scales import scale_rows
    from diviewer.scene import load_scene, sample_config

    scene = load_scene("cornell")
    configs = [sample_config(scene, 7000 + i, "test") for i in range(settings.frames)]
    return scale_rows(ctx, gl_timing_mode(ctx, "sync"), settings, scene, ds, list(variants), net_of, configs,
                      [] if notes is None else notes, lambda *_: None)


def test_a_lower_scale_scores_lower_on_hard_edges_and_scale_1_is_the_reference(ctx):
    """Cornell's direct light (hard shadow edges and silhouettes, no model): each lower scale is further from the
    scale-1 frame in every view; scale 1 is that frame itself (inf); 2 supersamples. The shading size is the
    viewer's round(s x window), and every row is timed per stage."""
    notes: list[str] = []
    out = _rows(ctx, BenchSettings(resolutions=(32,), frames=3, warmup=0, render_scales=(0.25, 0.5, 1.0, 2.0)),
                notes=notes)
    rows = {r["scale"]: r for r in out["rows"]}
    assert [rows[s]["shading_resolution"] for s in (0.25, 0.5, 1.0, 2.0)] == [[8, 8], [16, 16], [32, 32], [64, 64]]
    assert all(r["resolution"] == [32, 32] and r["gi_resolution"] is None and r["vs_truth"] is None
               for r in rows.values())
    assert all(math.isinf(v) for v in rows[1.0]["vs_scale1"]["per_view"])
    low, mid, high = (rows[s]["vs_scale1"]["per_view"] for s in (0.25, 0.5, 2.0))
    assert len(low) == 4  # the default view and 3 timed configurations (no evaluation set)
    assert all(a < b < math.inf for a, b in zip(low, mid)), (low, mid)
    assert all(math.isfinite(v) for v in high)
    assert rows[0.25]["vs_scale1"]["median"] < rows[0.5]["vs_scale1"]["median"]
    for r in rows.values():
        t = r["timing"]
        assert {"shadows", "gbuffer", "composite"} <= set(t["stages"]) and t["frame"]["median"] > 0
    assert any("direct light only" in n for n in notes)


def test_the_shipped_model_at_each_scale_runs_its_gi_at_the_viewers_size_and_meets_the_truth(ctx):
    """With the shipped model and its compact evaluation set: the GI runs at the size the viewer's ``--gi-res model``
    gives (the same at every scale), and each scale is scored against the path-traced truth at the set's size,
    where scale 1 is closer than 0.4."""
    from diviewer.bench.core import _open_evalset, _variants, model_paths
    from diviewer.bench.scales import model_gi_size
    from diviewer.contract.runtime import NeuralGI
    from diviewer.scene import load_scene

    scene = load_scene("cornell")
    settings = BenchSettings(resolutions=(48,), frames=2, warmup=0, eval_frames=1, render_scales=(0.4, 1.0))
    notes: list[str] = []
    ds = _open_evalset(settings, scene, notes)
    paths = [p for p in model_paths(settings, scene) if p.stem == "cornell"]
    if ds is None or not paths:
        pytest.fail(f"the shipped cornell model and compact evaluation set are part of the tree: {notes}")
    variants = [{"kind": "neural", "path": paths[0], "source": str(paths[0]), "precision": "fp32"}]
    net = NeuralGI(paths[0], scene=scene)
    out = _rows(ctx, settings, ds, variants, lambda v: net, notes)
    rows = {r["scale"]: r for r in out["rows"]}
    gi = list(model_gi_size(net, 48, 48))
    assert rows[0.4]["gi_resolution"] == rows[1.0]["gi_resolution"] == gi == list(model_gi_size(net, 19, 48))
    assert rows[0.4]["shading_resolution"] == [19, 19]
    side = ds.bench_frames()[1][0]
    for r in rows.values():
        assert r["vs_truth"]["resolution"] == [side, side] and len(r["vs_truth"]["per_view"]) == 2
        assert 15 < r["vs_truth"]["min"] <= r["vs_truth"]["median"] < 60
        assert "inference" in r["timing"]["stages"]
    assert rows[0.4]["vs_truth"]["median"] < rows[1.0]["vs_truth"]["median"]
    assert out["model"] == str(paths[0]) and len(out["frames"]) == 2


@pytest.mark.slow
def test_render_scale_rows_are_in_the_json_and_the_table(tmp_path):
    """`bench --render-scales` adds its section to the JSON (strict: scale 1 against itself is null) and its rows
    to the printed table; without the option there is no section."""
    out = tmp_path / "b.json"
    r = subprocess.run([sys.executable, "-m", "diviewer", "bench", "--quick", "--gi-steps", "--vxgi-grids",
                        "--untrained-k", "--eval-frames", "1", "--pt-frames", "1", "--render-scales", "0.5", "1",
                        "--json", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "render scales (dynamic resolution" in r.stdout and "dB vs truth" in r.stdout
    result = json.loads(out.read_text())
    assert result["settings"]["render_scales"] == [0.5, 1.0]
    rows = result["render_scales"]["rows"]
    assert [(row["scale"], row["resolution"], row["shading_resolution"]) for row in rows] == [
        (0.5, [32, 32], [16, 16]), (1.0, [32, 32], [32, 32])]
    assert rows[1]["vs_scale1"]["min"] is None and rows[1]["vs_scale1"]["median"] is None  # inf: identical
    assert math.isfinite(rows[0]["vs_scale1"]["median"]) and rows[0]["vs_truth"]["median"] > 0
    assert rows[0]["timing"]["frame"]["median"] > 0 and rows[0]["timing"]["frame"]["p95"] > 0


@hsettings(max_examples=30, deadline=None)
@given(st.floats(allow_nan=True, allow_infinity=True))
def test_a_render_scale_is_taken_in_0_to_2_and_refused_elsewhere_naming_the_option(s):
    settings = BenchSettings(render_scales=(1.0, s))
    if 0.0 < s <= 2.0:
        settings.check()
        return
    with pytest.raises(DiviewerError) as exc:
        settings.check()
    assert exc.value.field == "--render-scales"


def test_a_scale_that_shades_beyond_the_size_cap_is_refused():
    from diviewer.fieldspec import MAX_SIZE

    with pytest.raises(DiviewerError) as exc:
        BenchSettings(resolutions=(MAX_SIZE,), render_scales=(1.0, 1.5)).check()
    assert exc.value.field == "--render-scales" and "1.5" in str(exc.value)
    BenchSettings(resolutions=(MAX_SIZE,), render_scales=(0.5, 1.0)).check()


@pytest.mark.parametrize("value", ["0", "2.5", "-0.5", "nan"])
def test_bench_refuses_a_bad_render_scale_before_any_work(value, capsys):
    from diviewer.cli import main

    assert main(["bench", "--render-scales", "0.5", value]) == 2
    err = capsys.readouterr().err
    assert "--render-scales" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
