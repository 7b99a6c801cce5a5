"""`diviewer render --path`: every frame of a path as PNG + record, distinct frames along a moving path, the mp4 read
back (frame count and size), resuming after a kill frame by frame, labelled comparisons, and bad input refused in
one line before any work."""

from __future__ import annotations

import dataclasses
import json
import os
import time

import numpy as np
import pytest

from diviewer.cli import main
from diviewer.imageio import read_png
from diviewer.scene import load_scene
from diviewer.scene.camera_path import CameraPath, PathKey, write_path


@pytest.fixture(scope="module")
def cornell():
    return load_scene("cornell")


@pytest.fixture
def path_file(cornell, tmp_path):
    c = cornell.default.camera
    keys = [PathKey(0.5 * i, dataclasses.replace(c, position=tuple(np.add(c.position, [0.3 * np.sin(i), 0.1 * i,
                                                                                         -0.3 * i]))))
            for i in range(4)]
    f = tmp_path / "walk.json"
    write_path(f, CameraPath(tuple(keys), cornell.name, cornell.file_hash))
    return f


def _render(path_file, out, *extra):
    return main(["render", "--scene", "cornell", "--path", str(path_file), "--res", "40x30", "--out", str(out),
                 *map(str, extra)])


def test_every_frame_a_png_and_a_record_and_the_video_reads_back(ctx, path_file, tmp_path, capsys):
    import imageio.v2 as iio

    out = tmp_path / "out"
    assert _render(path_file, out, "--frames", 7, "--video", out / "walk.mp4", "--exr") == 0
    pngs = sorted((out / "frames").glob("*.png"))
    assert len(pngs) == 7
    images = [read_png(p) for p in pngs]
    assert all(im.shape == (30, 40, 3) for im in images)
    assert len({im.tobytes() for im in images}) == 7, "the camera moves: every frame differs"
    records = [json.loads(p.with_suffix(".json").read_text()) for p in pngs]
    assert [r["time"] for r in records] == pytest.approx([0.25 * i for i in range(7)])
    assert all(r["complete"] and r["scene"] == "cornell" and "camera" in r["config"] for r in records)
    assert (out / "frames" / "000003_direct.exr").is_file()
    reader = iio.get_reader(out / "walk.mp4")
    try:
        assert reader.count_frames() == 7
        assert tuple(reader.get_meta_data()["size"]) == (40, 30)
        assert reader.get_meta_data()["fps"] == pytest.approx(4.0)
        first = reader.get_data(0)
    finally:
        reader.close()
    assert first.shape == (30, 40, 3) and np.abs(first.astype(int) - images[0]).mean() < 12  # lossy, but the frame


def test_a_killed_render_resumes_frame_by_frame(ctx, path_file, tmp_path):
    out = tmp_path / "out"
    assert _render(path_file, out, "--frames", 5) == 0
    frames = out / "frames"
    kept = {p.name: p.stat().st_mtime_ns for p in frames.glob("00000[0134].png")}
    (frames / "000002.json").unlink()  # killed between the PNG and its record: drawn again
    (frames / "000004.json").write_text('{"index": 4')  # a record cut short: drawn again
    time.sleep(0.01)
    assert _render(path_file, out, "--frames", 5) == 0
    assert json.loads((frames / "000002.json").read_text())["complete"]
    assert json.loads((frames / "000004.json").read_text())["complete"]
    now = {p.name: p.stat().st_mtime_ns for p in frames.glob("00000[0134].png")}
    assert now["000000.png"] == kept["000000.png"] and now["000001.png"] == kept["000001.png"]
    assert now["000004.png"] != kept["000004.png"]
    # other settings into the same folder: refused, naming what differs
    assert _render(path_file, out, "--frames", 6) == 2


@pytest.mark.mitsuba
def test_compare_tiles_the_methods_with_labels(ctx, path_file, tmp_path):
    out = tmp_path / "cmp"
    assert _render(path_file, out, "--frames", 2, "--compare", "direct,reference", "--spp", 2) == 0
    im = read_png(out / "frames" / "000001.png")
    assert im.shape == (30 + 14, 80, 3)
    assert im[:14].max() > 200  # the caption's white text
    record = json.loads((out / "frames" / "000001.json").read_text())
    assert record["methods"] == ["direct", "reference"] and record["reference"]["spp"] >= 2


def _one_line_error(capsys, *parts):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    for p in parts:
        assert p in err, err


def test_bad_input_is_refused_before_any_work(path_file, tmp_path, capsys):
    out = tmp_path / "never"
    data = json.loads(path_file.read_text())
    cases = {
        "version": dict(data, version=3),
        "scene_hash": dict(data, scene_hash="f" * 64),
        "keys": dict(data, keys=[]),
        "keys[2].time": dict(data, keys=[data["keys"][0], data["keys"][1], dict(data["keys"][2], time=0.5)]),
        "keys[1].camera.fov": dict(data, keys=[data["keys"][0], dict(data["keys"][1],
                                                                   camera=dict(data["keys"][1]["camera"],
                                                                               fov=float("nan")))]),
    }
    for field, content in cases.items():
        bad = tmp_path / f"bad_{field}.json"
        bad.write_text(json.dumps(content))
        assert _render(bad, out, "--frames", 2) == 2
        _one_line_error(capsys, str(bad), f": {field}: ")
    assert _render(path_file, out, "--video", "/proc/walk.mp4") == 2
    _one_line_error(capsys, "--video", "/proc/walk.mp4")
    assert _render(path_file, out, "--video", tmp_path / "walk.avi") == 2
    _one_line_error(capsys, "--video", ".mp4")
    assert _render(path_file, out, "--compare", "direct,magic") == 2
    _one_line_error(capsys, "--compare")
    assert _render(path_file, out, "--compare", "neural") == 2
    _one_line_error(capsys, "--compare", "--model")
    assert _render(path_file, out, "--frames", 3, "--fps", 10) == 2
    _one_line_error(capsys, "--fps")
    assert main(["render", "--scene", "atrium", "--path", str(path_file), "--out", str(out)]) == 2
    _one_line_error(capsys, "scene_hash", "recorded in scene 'cornell'")
    assert main(["render", "--scene", "cornell", "--out", str(out), "--video", str(tmp_path / "v.mp4")]) == 2
    _one_line_error(capsys, "--video", "--path")
    assert not out.exists() and not os.path.exists("/proc/walk.mp4")


def test_reference_without_mitsuba_names_the_extra(path_file, tmp_path, capsys, monkeypatch):
    import builtins

    real = builtins.__import__

    def no_mitsuba(name, *a, **k):
        if name == "mitsuba" or name.startswith("mitsuba."):
            raise ImportError("No module named 'mitsuba'")
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_mitsuba)
    assert _render(path_file, tmp_path / "o", "--compare", "direct,reference") == 2
    _one_line_error(capsys, "mitsuba", "train")


def test_compare_with_the_neural_image(ctx, path_file, tmp_path):
    from diviewer.paths import models_dir

    out = tmp_path / "nn"
    assert _render(path_file, out, "--frames", 2, "--model", models_dir() / "cornell.onnx",
                   "--compare", "direct,neural") == 0
    im = read_png(out / "frames" / "000000.png")
    assert im.shape == (30 + 14, 80, 3)
    assert np.abs(im[14:, :40].astype(int) - im[14:, 40:]).mean() > 1.0  # the GI differs from the direct light
    record = json.loads((out / "frames" / "000000.json").read_text())
    assert record["neural"]["K"] and record["methods"] == ["direct", "neural"]
