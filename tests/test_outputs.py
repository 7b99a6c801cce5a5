"""The one rule of every writer (diviewer.outputs): the suffix required, never over a model, a card, a checkpoint,
a dataset's or an evaluation set's manifest and frames or a training run's files, checked before the work; and
write faults that name the user's file, never a temporary one."""

from __future__ import annotations

import errno
import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.outputs import check_output_dir, check_output_file, folder_kind, owner, staged

sys.path.insert(0, str(Path(__file__).parent / "extremes"))
from test_extremes_files import make_dataset  # noqa: E402


def _snapshot(root: Path) -> dict:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(root.rglob("*"))}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A dataset, an evaluation-set manifest, a training run, a model with its card: other commands' files."""
    t = tmp_path_factory.mktemp("outputs")
    from diviewer.cli import main

    make_dataset(t / "data", frames=8, width=16, height=16)
    es = make_dataset(t / "es", frames=2, width=16, height=16)
    manifest = json.loads((es.root / "manifest.json").read_text())
    (es.root / "manifest.json").write_text(json.dumps({**manifest, "kind": "evalset"}))
    other = make_dataset(t / "other", frames=2, width=16, height=16)  # a capture of another scene file
    manifest = json.loads((other.root / "manifest.json").read_text())
    (other.root / "manifest.json").write_text(json.dumps({**manifest, "scene": "elsewhere", "scene_hash": "0" * 64}))
    (t / "run").mkdir()
    for name in ("last.ckpt", "best.ckpt", "metrics.csv", "curves.png"):
        (t / "run" / name).write_bytes(b"x")
    assert main(["baseline", "--data", str(t / "data"), "--out", str(t / "lin.onnx")]) == 0
    (t / "old.ckpt").write_bytes(b"x")
    (t / "notes.json").write_text("{}")
    make_build_folder(t / "w", t / "lin.onnx")
    (t / "js").mkdir()
    (t / "js" / "build.json").write_text('{"name": "another tool\'s build file"}')
    (t / "damaged").mkdir()
    (t / "damaged" / "build.json").write_text('{"format": "diviewer-build", "stag')
    return t


def make_build_folder(w: Path, model: Path) -> None:
    """A build's work folder as `diviewer build` leaves it: its state, ladder record and scores, a K's model with its
    card and test scores, the chosen model shipped into the folder with what ships beside it (recorded in the
    state), and a file of the user's."""
    import shutil

    from diviewer.builder.state import BuildState

    (w / "models").mkdir(parents=True)
    for name in ("ladder.json", "evalset_eval.json"):
        (w / name).write_text("{}")
    shutil.copyfile(model, w / "models" / "x_k8.onnx")
    shutil.copyfile(model.with_suffix(".json"), w / "models" / "x_k8.json")
    (w / "models" / "x_k8_test.json").write_text("{}")
    shutil.copyfile(model, w / "x.onnx")
    shutil.copyfile(model.with_suffix(".json"), w / "x.json")
    for name in ("x_ladder.json", "x_curves.png", "x_metrics.csv", "x_ladder_curves.png", "scores.txt"):
        (w / name).write_text("{}")
    state = BuildState(w / "build.json", {"scene": "x"})
    state.finish("pick", w, [w / "ladder.json"])
    state.finish("ship", w, [w / "x.onnx", w / "x.json", w / "x_ladder.json", w / "scores.txt"])
    (w / "mine.json").write_text("{}")


def test_each_folder_is_known_by_whose_it_is(files):
    assert folder_kind(files / "data") == "dataset" and folder_kind(files / "es") == "evalset"
    assert folder_kind(files / "run") == "run" and folder_kind(files) is None
    assert folder_kind(files / "w") == "build" and folder_kind(files / "w" / "models") is None


@pytest.mark.parametrize("name, kind", [("lin.onnx", "model"), ("lin.json", "model"), ("old.ckpt", "checkpoint"),
                                        ("data/manifest.json", "dataset"), ("data/frames/000000.npy", "dataset"),
                                        ("data/frames/new.json", "dataset"), ("es/frames/000001.json", "evalset"),
                                        ("es/summary.json", "evalset"), ("data/summary.json", None),
                                        ("es/frames.zip", "evalset"), ("data/frames.zip", None),
                                        ("run/last.ckpt", "checkpoint"), ("run/metrics.csv", "run"),
                                        ("run/curves.png", "run"), ("notes.json", None), ("new.json", None),
                                        ("data/report.json", None),
                                        # a build's work folder: its own files, what it recorded, what it shipped
                                        ("w/build.json", "build"), ("w/ladder.json", "build"),
                                        ("w/evalset_eval.json", "build"), ("w/replaced_eval.json", "build"),
                                        ("w/models/x_k8_test.json", "build"), ("w/models/new.onnx", "build"),
                                        ("w/x.onnx", "build"), ("w/x_ladder_curves.png", "build"),
                                        ("w/scores.txt", "build"), ("w/.diviewer.lock", "lock"),
                                        ("w/mine.json", None), ("w/new.json", None),
                                        ("lin_ladder.json", "build"), ("lin_metrics.csv", "build"),
                                        ("other_ladder.json", None), ("js/build.json", None),
                                        ("js/ladder.json", None), ("damaged/build.json", "build")])
def test_owner_names_other_commands_files(files, name, kind):
    found = owner(files / name)
    assert (found[0] if found else None) == kind


def test_a_command_replaces_its_own_kind_and_no_other(files):
    assert check_output_file(files / "lin.onnx", suffix=".onnx", replaces="model") == files / "lin.onnx"
    with pytest.raises(DiviewerError, match="lin.onnx is a model, which this command must not overwrite"):
        check_output_file(files / "lin.onnx", "--json")
    with pytest.raises(DiviewerError, match="expected a .json file name"):
        check_output_file(files / "r.png", "--out", suffix=".json")
    with pytest.raises(DiviewerError, match="a frame of the dataset"):
        check_output_file(files / "data" / "frames" / "000000.npy", replaces="model")
    assert check_output_file(files / "notes.json", suffix=".json") == files / "notes.json"  # nobody's: rewritten


def test_folders_of_another_kind_and_folders_inside_a_dataset_are_refused(files):
    assert check_output_dir(files / "data", writes="dataset") == files / "data"  # resumed
    assert check_output_dir(files / "run", writes="run") == files / "run"
    with pytest.raises(DiviewerError, match="is a dataset .diviewer capture wrote it., not a training run folder"):
        check_output_dir(files / "data", writes="run")
    with pytest.raises(DiviewerError, match="is an evaluation set"):
        check_output_dir(files / "es", writes="dataset")
    with pytest.raises(DiviewerError, match="lies inside the dataset"):
        check_output_dir(files / "data" / "frames" / "x", writes="render")
    assert check_output_dir(files / "data", "--out") == files / "data"  # no kind given: only writability


BAD = [  # (argv, needle): each refused before any work, nothing written
    ("baseline --data {t}/data --out {t}/lin2.json", "expected a .onnx file name"),  # was: the card over the model
    ("baseline --data {t}/data --out {t}/data/manifest.json", "expected a .onnx"),
    ("baseline --data {t}/data --out {t}/data/frames/x.onnx", "a frame of the dataset"),
    ("baseline --data {t}/data --out {t}/m.onnx --max-frames 0", "--max-frames: must be a whole number from 1"),
    ("baseline --data {t}/data --out {t}/m.onnx --max-frames -3", "--max-frames: must be a whole number from 1"),
    ("eval --model {t}/lin.onnx --data {t}/data --out {t}/lin.json", "is a model card"),
    ("eval --model {t}/lin.onnx --data {t}/data --out {t}/lin.onnx", "expected a .json"),
    ("eval --model {t}/lin.onnx --data {t}/data --out {t}/data/manifest.json", "the manifest of the dataset"),
    ("eval --model {t}/lin.onnx --data {t}/data --out {t}/old.ckpt", "expected a .json"),
    ("eval --model {t}/lin.onnx --data {t}/data --out {t}", "is a folder"),
    ("bench --quick --json {t}/lin.json", "is a model card"),
    ("bench --quick --json {t}/es/manifest.json", "the manifest of the evaluation set"),
    ("bench --quick --plot {t}/run/curves.png", "a file of the training run"),
    ("bench --quick --plot {t}/plot.json", "expected a .png"),
    ("bench --quick --calib-data {t}/other", "is a capture of scene 'elsewhere'"),
    ("view --frames 1 --screenshot {t}/lin.png", "lin.json is a model card"),
    ("view --frames 1 --screenshot {t}/shot.onnx", "expected a .png"),
    ("view --frames 1 --stats {t}/lin.json", "is a model card"),
    ("render --res 16 --out {t}/data", "is a dataset"),
    ("render --res 16 --out {t}/run", "is a training run folder"),
    ("capture --frames 2 --res 16 --out {t}/run", "is a training run folder"),
    ("capture --frames 2 --res 16 --out {t}/es", "is an evaluation set"),
    ("capture --frames 2 --res 16 --out {t}/data/frames", "lies inside the dataset"),
    ("evalset --frames-per-split 1 --res 16 --out {t}/data", "is a dataset"),
    ("train --data {t}/data --out {t}/data", "is a dataset"),
    ("train --data {t}/data --out {t}/es/sub", "lies inside the evaluation set"),
    ("data merge {t}/data --out {t}/run", "is a training run folder"),
    # a build's state and ladder record, and every other file it owns, by each writer that names a file
    ("eval --model {t}/lin.onnx --data {t}/data --out {t}/w/build.json", "a file of the build"),
    ("eval --model {t}/lin.onnx --data {t}/data --out {t}/w/ladder.json", "a file of the build"),
    ("eval --model {t}/lin.onnx --data {t}/data --out {t}/w/models/x_k8_test.json", "a file of the build"),
    ("bench --quick --json {t}/w/build.json", "a file of the build"),
    ("bench --quick --json {t}/w/ladder.json", "a file of the build"),
    ("bench --quick --json {t}/w/x_ladder.json", "a file of the build"),
    ("bench --quick --plot {t}/w/x_curves.png", "shipped with the model"),
    ("view --frames 1 --stats {t}/w/build.json", "a file of the build"),
    ("view --frames 1 --stats {t}/w/ladder.json", "a file of the build"),
    ("view --frames 1 --screenshot {t}/w/build.png", "build.json is a file of the build"),
    ("view --frames 1 --screenshot {t}/w/ladder.png", "ladder.json is a file of the build"),
    ("view --frames 1 --screenshot {t}/w/x_ladder_curves.png", "shipped with the model"),
    ("export {t}/old.ckpt --out {t}/w/build.onnx", "build.json is a file of the build"),
    ("export {t}/old.ckpt --out {t}/w/x.onnx", "x.onnx is a file of the build"),
    ("baseline --data {t}/data --out {t}/w/build.onnx", "build.json is a file of the build"),
    ("baseline --data {t}/data --out {t}/w/ladder.onnx", "ladder.json is a file of the build"),
    ("baseline --data {t}/data --out {t}/w/models/x_k8.onnx", "a file of the build"),
    ("capture --frames 2 --res 16 --out {t}/w", "is a build work folder"),
    ("train --data {t}/data --out {t}/w", "is a build work folder"),
]


@pytest.mark.parametrize("argv, needle", BAD)
def test_every_writer_refuses_other_commands_files_before_the_work(files, capsys, argv, needle):
    from diviewer.cli import main

    before = _snapshot(files)
    rc = main(argv.format(t=files).split())
    err = capsys.readouterr().err
    assert rc == 2 and needle in err and err.count("\n") == 1 and "Traceback" not in err, err
    assert _snapshot(files) == before


def test_baseline_writes_its_model_and_card_and_replaces_its_own(files, tmp_path):
    from diviewer.cli import main
    from diviewer.contract.runtime import read_metadata

    out = tmp_path / "b.onnx"
    for _ in range(2):  # the second run replaces the first run's model and card
        assert main(["baseline", "--data", str(files / "data"), "--out", str(out), "--max-frames", "2"]) == 0
        assert read_metadata(out)["kind"] == "linear_baseline"
        assert json.loads(out.with_suffix(".json").read_text())["fit"]["frames"] == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.json", "b.onnx"]


def test_a_full_disk_names_the_users_file_not_the_temporary_one(tmp_path, monkeypatch):
    from diviewer import imageio

    target = tmp_path / "a.exr"

    class Full:  # what OpenEXR raises on a full disk: the temporary name and "No space left on device."
        def __init__(self, header, channels):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *a):
            return False

        def write(self, name):
            raise RuntimeError(f'Failed to write pixel data to image file "{name}". No space left on device.')

    import OpenEXR

    monkeypatch.setattr(OpenEXR, "File", Full)
    with pytest.raises(OSError) as exc:
        imageio.write_exr(target, np.zeros((4, 4, 3), np.float32))
    assert exc.value.errno == errno.ENOSPC and exc.value.filename == str(target)
    assert list(tmp_path.iterdir()) == []  # the temporary file is gone


def test_staged_writes_name_the_final_file(tmp_path):
    final = tmp_path / "out" / "frame.json"
    with pytest.raises(OSError) as exc:
        with staged() as stage:
            tmp = stage(final)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(tmp))
    assert exc.value.filename == str(final) and list((tmp_path / "out").iterdir()) == []


def test_bench_refuses_a_plot_without_matplotlib_before_the_work(monkeypatch, capsys, tmp_path):
    import importlib.util

    from diviewer.cli import main

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "matplotlib" else real(name, *a))
    rc = main(["bench", "--quick", "--plot", str(tmp_path / "p.png")])
    err = capsys.readouterr().err
    assert rc == 2 and "'matplotlib'" in err and "diviewer[bench]" in err and "torch" not in err, err
    assert list(tmp_path.iterdir()) == []


def test_json_by_rows_reads_back_the_same_with_each_record_on_a_line():
    from diviewer.outputs import dumps_rows, strict

    record = {"splits": {"a": {"frames": [{"psnr": 30.5, "ssim": 0.9, "name": "x"}, {"psnr": float("inf")}],
                               "curve": [1, 2.5, None, True], "empty": {}, "none": []}},
              "z_first": 1, "a_after": np.float32(0.5)}
    text = dumps_rows(record)
    back = json.loads(text)
    assert back["splits"]["a"]["frames"] == [{"psnr": 30.5, "ssim": 0.9, "name": "x"}, {"psnr": None}]
    assert list(back) == ["splits", "z_first", "a_after"] and back["a_after"] == 0.5  # key order, numpy scalars
    lines = text.splitlines()
    assert any(line.strip() == '{"psnr": 30.5, "ssim": 0.9, "name": "x"},' for line in lines)  # a record a line
    assert any(line.strip() == '"curve": [1, 2.5, null, true],' for line in lines)
    assert any(line.strip() == '"empty": {},' for line in lines)
    assert len(text) < len(json.dumps(strict(record), indent=1))
    assert dumps_rows(3.0) == "3.0" and dumps_rows([]) == "[]"
    keyed = {3: [{2: "a"}], 2.5: {}, True: [[1]], None: [{}]}  # non-string keys, as json.dumps writes them
    assert json.loads(dumps_rows(keyed)) == json.loads(json.dumps(keyed))
