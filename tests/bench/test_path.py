"""`diviewer bench --path`: a camera path timed frame by frame (per stage, median and p95, every frame kept), and
its temporal stability against the path tracer on the path's first frames."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from diviewer.cli import main
from diviewer.scene import load_scene
from diviewer.scene.camera_path import CameraPath, PathKey, write_path


@pytest.fixture
def path_file(tmp_path):
    cornell = load_scene("cornell")
    c = cornell.default.camera
    keys = [PathKey(0.4 * i, dataclasses.replace(c, position=tuple(np.add(c.position, [0.2 * i, 0.0, -0.2 * i]))))
            for i in range(3)]
    f = tmp_path / "walk.json"
    write_path(f, CameraPath(tuple(keys), cornell.name, cornell.file_hash))
    return f


@pytest.mark.mitsuba
def test_bench_times_the_path_frame_by_frame(ctx, path_file, tmp_path, capsys):
    out = tmp_path / "b.json"
    assert main(["bench", "--scene", "cornell", "--path", str(path_file), "--frames", "4", "--warmup", "1",
                 "--res", "32", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["kind"] == "path_bench" and result["frames"] == 4
    assert result["times"] == pytest.approx([0.0, 0.8 / 3, 1.6 / 3, 0.8])
    direct = result["rows"][0]
    assert direct["label"] == "direct light only" and len(direct["per_frame"]) == 4
    assert {"median", "p95"} <= direct["timing"]["frame"].keys() and "gbuffer" in direct["timing"]["stages"]
    assert all(f["frame"] > 0 for f in direct["per_frame"])
    temporal = result["temporal"]
    assert temporal["frames"] == 4 and temporal["reference_spp"] == 16 and "direct" in temporal["methods"]
    assert "direct light only" in capsys.readouterr().out


def test_bench_path_refuses_bad_input_before_any_work(path_file, tmp_path, capsys):
    data = json.loads(path_file.read_text())
    data["keys"][1]["time"] = 0.0
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    assert main(["bench", "--scene", "cornell", "--path", str(bad)]) == 2
    assert "bad.json: keys[1].time:" in capsys.readouterr().err
    assert main(["bench", "--scene", "atrium", "--path", str(path_file)]) == 2
    assert "scene_hash" in capsys.readouterr().err
    assert main(["bench", "--scene", "cornell", "--path", str(path_file), "--plot", str(tmp_path / "p.png")]) == 2
    assert "--plot" in capsys.readouterr().err
