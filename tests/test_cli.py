"""The `diviewer` command: render writes the buffers; user errors exit 2 without a traceback."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import venv
from pathlib import Path

import numpy as np
import pytest

from diviewer.cli import main
from diviewer.imageio import read_exr, read_png

ROOT = Path(__file__).resolve().parents[1]
FILES = ["depth.exr", "normal.exr", "albedo.exr", "direct.exr", "depth.png", "normal.png", "albedo.png",
         "direct.png", "frame.json"]


@pytest.mark.slow
@pytest.mark.parametrize("scene", ["cornell", "sponza", "atrium"])
def test_render_writes_buffers_and_frame_json(gl_context, tmp_path, scene):
    out = tmp_path / scene
    assert main(["render", "--scene", scene, "--res", "64", "--out", str(out)]) == 0
    for f in FILES:
        assert (out / f).is_file(), f
    depth, normal, albedo, direct = (read_exr(out / f"{n}.exr") for n in ("depth", "normal", "albedo", "direct"))
    assert depth.shape == (64, 64) and normal.shape == albedo.shape == direct.shape == (64, 64, 3)
    assert np.all(np.isfinite(direct)) and direct.max() > 0
    valid = depth > 0
    np.testing.assert_allclose(np.linalg.norm(normal[valid], axis=-1), 1.0, atol=1e-3)
    assert read_png(out / "direct.png").shape == (64, 64, 3)
    record = json.loads((out / "frame.json").read_text())
    assert record["scene"] == scene and record["resolution"] == [64, 64]
    assert {"camera", "lights", "objects"} <= set(record["config"])


def test_render_again_from_frame_json_gives_same_buffers(gl_context, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    assert main(["render", "--scene", "cornell", "--res", "48x32", "--seed", "11", "--out", str(a)]) == 0
    assert main(["render", "--scene", "cornell", "--res", "48x32", "--config", str(a / "frame.json"),
                 "--out", str(b)]) == 0
    for n in ("depth", "normal", "albedo", "direct"):
        np.testing.assert_array_equal(read_exr(a / f"{n}.exr"), read_exr(b / f"{n}.exr"))
    assert read_exr(a / "depth.exr").shape == (32, 48)
    # a different seed is a different frame
    c = tmp_path / "c"
    assert main(["render", "--scene", "cornell", "--res", "48x32", "--seed", "12", "--out", str(c)]) == 0
    assert not np.array_equal(read_exr(a / "direct.exr"), read_exr(c / "direct.exr"))


def test_render_meters_the_exposure_of_a_scene_that_asks_for_it_and_records_it(gl_context, tmp_path):
    """A scene file with ``auto_exposure = true``: render's PNGs are shown at the viewer's meter of the frame, the
    same for the same frame, recorded in frame.json (and a reference render from it takes it over); --exposure
    still wins; the scene's identity does not change."""
    from diviewer.scene import load_scene
    from diviewer.exposure import SHOWN, metered_ev

    text = (ROOT / "assets" / "scenes" / "cornell.toml").read_text()
    auto = tmp_path / "auto.toml"
    auto.write_text(text.replace('exposure = 0.0\n', 'exposure = 0.0\nauto_exposure = true\n', 1))
    plain = tmp_path / "plain.toml"
    plain.write_text(text)
    assert load_scene(auto).auto_exposure and not load_scene(plain).auto_exposure
    assert load_scene(auto).file_hash == load_scene(plain).file_hash  # display only
    records = []
    for name in ("a", "b"):
        assert main(["render", "--scene", str(auto), "--res", "48x32", "--seed", "3", "--out", str(tmp_path / name)]) == 0
        records.append(json.loads((tmp_path / name / "frame.json").read_text())["display"])
    direct = read_exr(tmp_path / "a" / "direct.exr")
    clipped = records[0].pop("clipped")
    assert records[0] == {"exposure": round(metered_ev(direct, SHOWN), 4), "tonemap": "aces", "metered": "direct"}
    assert records[1].pop("clipped") == clipped and records[1] == records[0] and 0 <= clipped["direct"] <= 1
    assert records[0]["exposure"] != 0.0  # metered, not the file's 0 EV
    assert main(["render", "--scene", str(auto), "--res", "48x32", "--seed", "3", "--exposure", "-1",
                 "--out", str(tmp_path / "c")]) == 0
    fixed = json.loads((tmp_path / "c" / "frame.json").read_text())["display"]
    assert fixed.pop("clipped").keys() == {"direct"} and fixed == {"exposure": -1.0, "tonemap": "aces"}
    assert main(["render", "--scene", str(plain), "--res", "48x32", "--seed", "3", "--out", str(tmp_path / "d")]) == 0
    assert json.loads((tmp_path / "d" / "frame.json").read_text())["display"]["exposure"] == 0.0
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('exposure = 0.0\n', 'exposure = 0.0\nauto_exposure = "yes"\n', 1))
    assert main(["render", "--scene", str(bad), "--out", str(tmp_path / "e")]) == 2


@pytest.mark.slow
def test_bad_scene_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[camera]\nfov = 200\n")
    r = subprocess.run([sys.executable, "-m", "diviewer", "render", "--scene", str(bad), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert str(bad) in r.stderr and "camera.fov" in r.stderr
    assert not (tmp_path / "o").exists(), "nothing is written for a bad scene"


def test_bad_resolution_and_unknown_scene(tmp_path, capsys):
    assert main(["render", "--scene", "cornell", "--res", "0", "--out", str(tmp_path)]) == 2
    assert "--res" in capsys.readouterr().err
    assert main(["render", "--scene", "nope", "--out", str(tmp_path)]) == 2
    assert "cornell" in capsys.readouterr().err


@pytest.mark.slow
def test_wheel_installs_and_renders_from_another_directory(tmp_path):
    """`pip install .` (not editable) gives a diviewer that finds its shaders and scenes."""
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(wheels),
                    str(ROOT)], check=True)
    (wheel,) = wheels.glob("diviewer-*.whl")
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    py = env_dir / "bin" / "python"
    # Dependencies come from this environment (no download); the project itself only from the wheel.
    site = next(Path(p) for p in sys.path if p.endswith("site-packages"))
    (next((env_dir / "lib").glob("python*/site-packages")) / "deps.pth").write_text(str(site) + "\n")
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)], check=True)
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    where = subprocess.run([str(py), "-c", "import diviewer, sys; print(diviewer.__file__)"], cwd=work, env=env,
                           capture_output=True, text=True, check=True).stdout.strip()
    assert where.startswith(str(env_dir)), f"diviewer imported from {where}, not the wheel"
    r = subprocess.run([str(env_dir / "bin" / "diviewer"), "render", "--scene", "atrium", "--res", "32", "--out", "o"],
                       cwd=work, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert (work / "o" / "direct.exr").is_file() and (work / "o" / "frame.json").is_file()


@pytest.mark.slow
def test_viewer_runtime_and_render_work_without_torch(gl_context, tmp_path):
    """Everything outside train/ (viewer, runtime, render, gl, scene, data, metrics) imports and runs
    without the train extra (torch, mitsuba): every such module is imported with both blocked, and
    the shipped model renders a frame through the runtime."""
    from diviewer.paths import models_dir

    model = Path(models_dir()) / "cornell.onnx"
    code = (
        "import importlib, pkgutil, sys\n"
        "sys.modules['torch'] = None\n"  # any `import torch` now raises ImportError
        "sys.modules['mitsuba'] = None\n"
        "import diviewer\n"
        "names = [m.name for m in pkgutil.walk_packages(diviewer.__path__, 'diviewer.')\n"
        "         if not m.name.startswith('diviewer.train') and not m.name.endswith('__main__')]\n"
        "assert {'diviewer.viewer.app', 'diviewer.contract.runtime', 'diviewer.render'} <= set(names), names\n"
        "for name in names:\n"
        "    importlib.import_module(name)\n"
        "from diviewer.cli import main\n"
        f"rc = main(['render', '--scene', 'cornell', '--res', '32', '--out', {str(tmp_path / 'o')!r}])\n"
        "assert rc == 0, rc\n"
        f"rc = main(['render', '--scene', 'cornell', '--model', {str(model)!r}, '--out', {str(tmp_path / 'n')!r}])\n"
        "assert rc == 0, rc\n"
        f"rc = main(['export', {str(tmp_path / 'x.ckpt')!r}, '--out', {str(tmp_path / 'x.onnx')!r}])\n"
        "assert rc == 2, rc\n"
        "assert 'torch' not in [m for m in sys.modules if sys.modules[m] is not None]\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "pip install 'diviewer[train]'" in r.stderr, "export names the extra to install"
    assert (tmp_path / "n" / "neural.exr").is_file()


def test_frame_json_with_a_loaded_mesh_file_renders_again(gl_context, tmp_path):
    """A viewer screenshot after loading a mesh file records it; render --config loads it again."""
    import trimesh

    from diviewer.frames import scene_for_frame_json
    from diviewer.scene import load_scene
    from diviewer.scene.loader import add_mesh_file

    trimesh.creation.icosphere(2, radius=0.3).export(tmp_path / "ball.ply")
    scene = load_scene("cornell")
    scene2, key, _ = add_mesh_file(scene, tmp_path / "ball.ply")
    config = scene2.default.replace_object("center", mesh=key)
    a = tmp_path / "a"
    a.mkdir()
    record = {"scene": "cornell", "scene_hash": scene.file_hash, "config": config.to_dict(),
              "user_meshes": {key: str(tmp_path / "ball.ply")}}
    (a / "shot.json").write_text(json.dumps(record))
    assert key in scene_for_frame_json(scene, a / "shot.json").meshes
    out = tmp_path / "b"
    assert main(["render", "--scene", "cornell", "--res", "32", "--config", str(a / "shot.json"), "--out", str(out)]) == 0
    assert json.loads((out / "frame.json").read_text())["config"]["objects"][-1]["mesh"] == key
    again = tmp_path / "c"  # and the frame.json it wrote renders again too
    assert main(["render", "--scene", "cornell", "--res", "32", "--config", str(out / "frame.json"), "--out", str(again)]) == 0


def test_written_files_get_ordinary_permissions(tmp_path):
    from diviewer.imageio import write_text

    old = os.umask(0o022)
    try:
        write_text(tmp_path / "a.txt", "x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644


@pytest.mark.mitsuba
@pytest.mark.slow
@pytest.mark.skipif(any(importlib.util.find_spec(m) is None for m in ("torch", "mitsuba", "onnx")),
                    reason="the pipeline needs the train extra: pip install 'diviewer[train]'")
def test_capture_train_export_runtime_smoke(gl_context, tmp_path):
    """The whole pipeline shrunk, through the CLI: capture -> train a few steps -> export -> a runtime frame."""
    data, run, model, out = tmp_path / "data", tmp_path / "run", tmp_path / "m.onnx", tmp_path / "frame"
    assert main(["capture", "--scene", "cornell", "--frames", "6", "--res", "32", "--spp", "4", "--max-depth", "3",
                 "--splits", "0.5,0.25,0.25", "--out", str(data)]) == 0
    assert main(["train", "--data", str(data), "--out", str(run), "--k", "4", "--ndf", "8", "--batch-size", "2",
                 "--epochs", "1", "--device", "cpu"]) == 0
    assert (run / "best.ckpt").is_file() and (run / "metrics.csv").is_file()
    assert main(["export", str(run / "best.ckpt"), "--out", str(model), "--verify-frames", "1"]) == 0
    assert main(["render", "--scene", "cornell", "--model", str(model), "--out", str(out)]) == 0
    neural, direct = read_exr(out / "neural.exr"), read_exr(out / "direct.exr")
    assert neural.shape == direct.shape == (32, 32, 3), "rendered at the model's resolution"
    assert np.isfinite(neural).all()


def test_an_existing_output_file_is_overwritten_and_one_under_a_file_is_refused(tmp_path):
    from diviewer.errors import DiviewerError
    from diviewer.outputs import check_output_dir, check_output_file

    existing = tmp_path / "shot.png"
    existing.write_bytes(b"old")
    assert check_output_file(existing, "--screenshot") == existing  # rewritten, as a rerun does
    assert check_output_file(tmp_path / "new" / "deeper" / "a.json") == tmp_path / "new" / "deeper" / "a.json"
    with pytest.raises(DiviewerError, match=r"shot.png is a file, so .*x.json cannot be created under it") as e:
        check_output_file(existing / "x.json", "--out")
    assert e.value.field == "--out"
    with pytest.raises(DiviewerError, match="is a folder"):
        check_output_file(tmp_path, "--out")
    assert check_output_dir(tmp_path / "run") == tmp_path / "run"
    with pytest.raises(DiviewerError, match="is a file; give a folder"):
        check_output_dir(existing)


@pytest.mark.parametrize("command", ["render", "capture", "evalset", "bench", "view"])
def test_scene_help_lists_every_shipped_scene_from_the_assets_folder(command, capsys):
    from diviewer.paths import shipped_scenes

    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps the help text
    assert {"cornell", "sponza", "atrium"} <= set(shipped_scenes())
    assert f"shipped scene name ({', '.join(shipped_scenes())})" in text
