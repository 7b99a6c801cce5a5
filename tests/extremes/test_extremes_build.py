"""`diviewer build` against a hostile user: every bad option refused before the first stage (in a dry run too) with
nothing written, no model replaced that the build was not told to replace, and one build per work folder."""

from __future__ import annotations

import json
import os
import shutil
import socket
import sys
import zipfile
from pathlib import Path

import pytest

from diviewer.cli import main
from diviewer.paths import models_dir

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from builder.test_pipeline import TINY_RECIPE  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def _snapshot(root: Path) -> dict:
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in sorted(root.rglob("*"))} if root.exists() else {}


@pytest.fixture
def recipe(tmp_path) -> Path:
    path = tmp_path / "tiny.toml"
    path.write_text(TINY_RECIPE)
    return path


def _partial_evalset(tmp_path: Path, keep: int) -> Path:
    """cornell's compact evaluation set with only its first ``keep`` frames."""
    src, dst = ROOT / "assets" / "evalsets" / "cornell", tmp_path / "partial"
    dst.mkdir()
    shutil.copyfile(src / "manifest.json", dst / "manifest.json")
    with zipfile.ZipFile(src / "frames.zip") as full, zipfile.ZipFile(dst / "frames.zip", "w") as part:
        for name in sorted(full.namelist())[:2 * keep]:  # each frame: NAME.hi.npy and NAME.lo.npy
            part.writestr(name, full.read(name))
    return dst


def _refused(argv: list[str], capsys, tmp_path: Path) -> str:
    """Run ``argv`` as a run and as a dry run: each exits 2 with one line, and nothing under tmp_path changes."""
    before = _snapshot(tmp_path)
    lines = []
    for extra in ([], ["--dry-run"]):
        assert main([*argv, *extra]) == 2
        out, err = capsys.readouterr()
        assert err.count("\n") == 1 and "Traceback" not in err, err
        assert "[1/" not in out, "no stage ran"
        lines.append(err.strip())
    assert lines[0] == lines[1] and _snapshot(tmp_path) == before
    return lines[0]


@pytest.mark.parametrize("extra, needle", [
    (["--ks", "100000"], "--ks: must be a whole number from 1 to 256, got 100000"),
    (["--ks", "4", "0"], "--ks: must be a whole number from 1 to 256, got 0"),
    (["--device", "cuda:x"], "--device: must be auto, cpu, cuda or cuda:N, got 'cuda:x'"),
    (["--device", "tpu"], "--device: must be auto, cpu, cuda or cuda:N"),
    (["--replace-worse"], "--replace-worse: --replace-worse applies to a model replaced in the folder --ship names"),
])
def test_a_bad_option_is_refused_before_the_first_stage(tmp_path, capsys, recipe, extra, needle):
    line = _refused(["build", "--scene", "cornell", "--recipe", str(recipe), "--work", str(tmp_path / "w"), *extra],
                    capsys, tmp_path)
    assert needle in line, line
    assert not (tmp_path / "w").exists()


def test_cuda_on_a_machine_without_it_is_refused_before_the_first_stage(tmp_path, capsys, recipe):
    pytest.importorskip("torch")
    from diviewer.train.distributed import cuda_device_count

    if cuda_device_count() > 8:
        pytest.skip("this machine has more than 8 CUDA devices")
    device = "cuda" if cuda_device_count() == 0 else "cuda:8"
    line = _refused(["build", "--scene", "cornell", "--recipe", str(recipe), "--work", str(tmp_path / "w"),
                     "--device", device], capsys, tmp_path)
    assert "--device" in line and "torch sees" in line, line


def test_folders_that_cannot_hold_a_build_are_refused(tmp_path, capsys, recipe):
    (tmp_path / "afile").write_text("mine")
    base = ["build", "--scene", "cornell", "--recipe", str(recipe)]
    line = _refused([*base, "--work", str(tmp_path / "w"), "--ship", str(tmp_path / "afile")], capsys, tmp_path)
    assert "--ship" in line and "afile is a file; give a folder" in line
    line = _refused([*base, "--work", str(tmp_path / "afile")], capsys, tmp_path)
    assert "--work" in line and "afile is a file" in line
    evalset = ROOT / "assets" / "evalsets" / "cornell"
    line = _refused([*base, "--work", str(evalset)], capsys, tmp_path)
    assert "--work" in line and "is an evaluation set" in line
    line = _refused([*base, "--work", str(tmp_path / "w"), "--ship", str(evalset)], capsys, tmp_path)
    assert "--ship" in line and "is an evaluation set" in line
    line = _refused([*base, "--work", str(tmp_path / "w"), "--ship", str(evalset / "models")], capsys, tmp_path)
    assert "--ship" in line and "lies inside the evaluation set" in line
    other = tmp_path / "other"
    other.mkdir()
    (other / "build.json").write_text(json.dumps({"format": "diviewer-build", "plan": {}, "stages": {}}))
    line = _refused([*base, "--work", str(tmp_path / "w"), "--ship", str(other)], capsys, tmp_path)
    assert "--ship" in line and "is a build work folder (diviewer build wrote it)" in line


@pytest.mark.parametrize("keep", [0, 3])
def test_a_partial_evaluation_set_is_refused_before_the_first_stage(tmp_path, capsys, recipe, keep):
    evalset = _partial_evalset(tmp_path, keep)
    total = len(json.loads((evalset / "manifest.json").read_text())["frame_list"])
    line = _refused(["build", "--scene", "cornell", "--recipe", str(recipe), "--work", str(tmp_path / "w"),
                     "--evalset", str(evalset)], capsys, tmp_path)
    assert f"--evalset: the evaluation set is incomplete: {keep} of {total} frames present" in line, line
    assert "--partial" not in line, "build has no --partial"


def test_split_fractions_that_leave_no_test_frame_are_refused_before_the_capture(tmp_path, capsys):
    recipe = tmp_path / "r.toml"
    recipe.write_text(TINY_RECIPE.replace("split_fractions = [0.5, 0.25, 0.25]", "split_fractions = [0.9, 0.1, 0.0]"))
    line = _refused(["build", "--scene", "cornell", "--recipe", str(recipe), "--work", str(tmp_path / "w")],
                    capsys, tmp_path)
    assert "capture.split_fractions" in line and "0 test" in line and "r.toml" in line, line


def test_a_build_without_ship_ships_into_its_work_folder_even_for_a_shipped_scene(tmp_path, monkeypatch, capsys,
                                                                                 recipe):
    """The hostile case: `diviewer build --scene cornell` (a shipped scene) replaced assets/models/cornell.onnx."""
    import diviewer.builder.plan as plan_module

    seen = {}
    real = plan_module.make_plan

    def spy(*args, **kwargs):
        seen["plan"] = real(*args, **kwargs)
        return seen["plan"]

    monkeypatch.setattr(plan_module, "make_plan", spy)
    shipped = _snapshot(models_dir())
    for scene in ("cornell", "sponza"):
        work = tmp_path / scene
        assert main(["build", "--scene", scene, "--recipe", str(recipe), "--work", str(work), "--dry-run"]) == 0
        assert seen["plan"].ship == work, scene
        assert "replaces" not in capsys.readouterr().out
    assert _snapshot(models_dir()) == shipped


def test_a_model_the_build_did_not_make_is_replaced_only_with_ship(tmp_path, capsys, recipe):
    """A model file already in the work folder (the user's, or a build's before this one's state): refused without
    --ship; with --ship the plan says it replaces it, and how it decides."""
    work = tmp_path / "w"
    work.mkdir()
    for suffix in (".onnx", ".json"):
        shutil.copyfile(models_dir() / f"cornell{suffix}", work / f"cornell{suffix}")
    argv = ["build", "--scene", "cornell", "--recipe", str(recipe), "--work", str(work)]
    line = _refused(argv, capsys, tmp_path)
    assert str(work / "cornell.onnx") in line and "--ship" in line and "replaces a model only when told" in line, line
    assert main([*argv, "--ship", str(work), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert f"ship replaces {work / 'cornell.onnx'}" in out and "only if it scores at least as well" in out
    assert main([*argv, "--ship", str(work), "--replace-worse", "--dry-run"]) == 0
    assert "whatever the scores (--replace-worse)" in capsys.readouterr().out
    assert main([*argv, "--ship", str(models_dir()), "--dry-run"]) == 0
    assert f"ship replaces {models_dir() / 'cornell.onnx'}" in capsys.readouterr().out


def test_a_second_build_into_the_same_folder_is_refused_at_once_naming_the_first(tmp_path, capsys, recipe):
    from diviewer.locks import run_lock

    work = tmp_path / "w"
    argv = ["build", "--scene", "cornell", "--recipe", str(recipe), "--work", str(work)]
    with run_lock(work, "build", option="--work"):  # the first build, holding the folder
        assert main(argv) == 2
        out, err = capsys.readouterr()
        assert "[1/" not in out
        line = err.strip()
        assert "--work" in line and "another run is writing here: diviewer build" in line
        assert f"pid {os.getpid()} on host {socket.gethostname()}" in line, line
        assert main([*argv, "--dry-run"]) == 0  # the dry run says so, and does nothing
        assert "would refuse the work folder now: another run is writing there: diviewer build" in (
            capsys.readouterr().out)
    assert not work.exists(), "the lock's folder, made for it and left empty, is gone with it"
