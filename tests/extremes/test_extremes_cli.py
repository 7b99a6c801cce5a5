"""Every subcommand with bad arguments: one line naming the option or file, exit 2, no traceback,
nothing written; full disks and unwritable outputs are one line too."""

from __future__ import annotations

import errno
import os
import subprocess
import sys

import pytest

from diviewer.cli import main


@pytest.fixture
def files(tmp_path):
    (tmp_path / "afile").write_text("x")
    (tmp_path / "run.ckpt").write_bytes(b"ck")
    (tmp_path / "frame.json").write_text("{}")
    return tmp_path


# (arguments with {t} for the temporary folder, text the one error line must contain)
BAD = [
    ("render --out {t}/afile --res 8", "--out"),
    ("render --out {t}/afile/sub --res 8", "--out"),
    ("render --out {t}/o --res 0", "--res"),
    ("render --out {t}/o --res 8x", "--res"),
    ("render --out {t}/o --res -8", "--res"),
    ("render --out {t}/o --res 99999", "--res"),
    ("render --out {t}/o --res 16384", "--res"),
    ("render --out {t}/o --res 8 --seed -1", "--seed"),
    ("render --out {t}/o --res 8 --seed 4294967296", "--seed"),
    ("render --out {t}/o --res 8 --exposure nan", "--exposure"),
    ("render --out {t}/o --res 8 --exposure inf", "--exposure"),
    ("render --out {t}/o --res 8 --spp 0 --reference pt", "--spp"),
    ("render --out {t}/o --res 8 --config {t}/afile", "afile"),
    ("render --out {t}/o --res 8 --config {t}/missing.json", "missing.json"),
    ("render --out {t}/o --res 8 --scene {t}/nope.toml", "nope.toml"),
    ("render --out {t}/o --res 8 --scene nosuchscene", "nosuchscene"),
    ("render --out {t}/o --res 8 --model {t}/afile", "afile"),
    ("capture --out {t}/c --frames 2 --res 8 --splits a,b,c", "--splits"),
    ("capture --out {t}/c --frames 2 --res 8 --splits 1,-1,1", "--splits"),
    ("capture --out {t}/c --frames 2 --res 8 --splits 0,0,0", "--splits"),
    ("capture --out {t}/c --frames 2 --res 8 --splits nan,1,1", "--splits"),
    ("capture --out {t}/c --frames 2 --res 8 --splits 1,1", "--splits"),
    ("capture --out {t}/c --frames -3 --res 8", "--frames"),
    ("capture --out {t}/c --frames 0 --res 8", "--frames"),
    ("capture --out {t}/c --frames 2 --res 8 --seed -1", "--seed"),
    ("capture --out {t}/c --frames 2 --res 8 --thumbs -1", "--thumbs"),
    ("capture --out {t}/c --frames 2 --res 8 --spp 0", "--spp"),
    ("capture --out {t}/c --frames 2 --res 8 --max-depth 1", "--max-depth"),
    ("capture --out {t}/c --frames 2 --res 8 --shard 3/2", "--shard"),
    ("capture --out {t}/c --frames 2 --res 8 --shard x", "--shard"),
    ("capture --out {t}/afile --frames 2 --res 8", "--out"),
    ("capture --out {t}/c --frames 2 --res 0x8", "--res"),
    ("export {t}/run.ckpt --out {t}/run.ckpt", "--out"),
    ("export {t}/run.ckpt --out {t}/model.json", "--out"),
    ("export {t}/run.ckpt --out {t}", "--out"),
    ("export {t}/run.ckpt --out {t}/afile/m.onnx", "--out"),
    ("export {t}/missing.ckpt --out {t}/m.onnx", "missing.ckpt"),
    ("export {t}/run.ckpt --out {t}/m.onnx --verify-frames 0", "--verify-frames"),
    ("export {t}/run.ckpt --out {t}/m.onnx --verify-frames -2", "--verify-frames"),
    ("export --info {t}/afile", "afile"),
    ("export --info {t}/missing.onnx", "missing.onnx"),
    ("export", "export"),
    ("eval --model {t}/afile --data {t}", "manifest"),
    ("eval --model {t}/afile --data {t} --out {t}/afile/x.json", "--out"),
    ("eval --model {t}/afile --data {t} --out {t}", "--out"),
    ("data check {t}/afile", "afile"),
    ("data check {t}/missing", "missing"),
    ("data merge {t} --out {t}", "--out"),
    ("data merge {t}/missing --out {t}/m", "missing"),
    ("train --data {t} --out {t}/afile", "--out"),
    ("train --data {t} --out {t}/r --seed -1", "--seed"),
    ("train --data {t} --out {t}/r --epochs 0", "--epochs"),
    ("train --data {t} --out {t}/r --k 0", "--k"),
    ("train --data {t} --out {t}/r --batch-size -4", "--batch-size"),
    ("train --data {t} --out {t}/r --lr nan", "--lr"),
    ("train --data {t} --out {t}/r --lambda-l1 -1", "--lambda-l1"),
    ("train --data {t} --out {t}/r --num-workers -1", "--num-workers"),
    ("train --data {t} --out {t}/r --max-steps 0", "--max-steps"),
    ("train --data {t}/missing --out {t}/r", "missing"),
    ("view --frames 0", "--frames"),
    ("view --size 0 --frames 1", "--size"),
    ("view --size 12x --frames 1", "--size"),
    ("view --model {t}/afile --frames 1", "--model"),
    ("view --model {t}/missing.onnx --frames 1", "--model"),
    ("view --screenshot {t} --frames 1", "--screenshot"),
    ("view --screenshot {t}/afile/s.png --frames 1", "--screenshot"),
    # one rule for every writer (issue 29): the suffix required, never over another command's file
    ("baseline --data {t} --out {t}/lin.json", "--out"),
    ("baseline --data {t} --out {t}/m.onnx --max-frames 0", "--max-frames"),
    ("eval --model {t}/afile --data {t} --out {t}/run.ckpt", "--out"),
    ("bench --quick --plot {t}/p.json", "--plot"),
    ("bench --quick --json {t}/run.ckpt", "--json"),
    ("view --stats {t}/run.ckpt --frames 1", "--stats"),
    ("view --screenshot {t}/s.jpg --frames 1", "--screenshot"),
    ("train --data {t} --out {t}/r --recipe paper --lr-decay-start 10", "--lr-decay-start"),
]


def _snapshot(root):
    return sorted((str(p.relative_to(root)), p.stat().st_size) for p in root.rglob("*"))


@pytest.mark.slow
@pytest.mark.parametrize("argv,needle", BAD, ids=[a for a, _ in BAD])
def test_bad_arguments_are_one_line_and_exit_2(files, capsys, argv, needle):
    before = _snapshot(files)
    try:
        rc = main(argv.format(t=files).split())
    except SystemExit as exc:  # argparse's own usage errors: exit 2 with a usage line
        rc = exc.code
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "Traceback" not in err
    lines = [l for l in err.splitlines() if l.strip()]
    assert lines and needle in lines[-1], err
    if not lines[0].startswith("usage:"):
        assert len(lines) == 1, err
    assert _snapshot(files) == before  # nothing written


@pytest.mark.slow
def test_no_traceback_reaches_stderr_from_the_installed_command(files):
    """The same rule through a real process (the console entry point), for a sample of the cases."""
    for argv, needle in BAD[::9]:
        p = subprocess.run([sys.executable, "-m", "diviewer", *argv.format(t=files).split()], capture_output=True,
                           text=True, timeout=120, env={**os.environ, "PYTHONWARNINGS": "ignore"})
        assert p.returncode == 2 and "Traceback" not in p.stderr and needle in p.stderr, (argv, p.stderr)


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EDQUOT, errno.EACCES, errno.EROFS])
def test_disk_full_or_unwritable_while_merging_is_one_line(tmp_path, capsys, monkeypatch, code):
    import shutil

    from test_extremes_files import make_dataset

    src = make_dataset(tmp_path / "src")

    def fail(*args, **kwargs):
        raise OSError(code, os.strerror(code), str(args[1]))

    monkeypatch.setattr(shutil, "copyfile", fail)
    assert main(["data", "merge", str(src.root), "--out", str(tmp_path / "merged")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and os.strerror(code) in err and "Traceback" not in err


def test_programming_errors_are_not_hidden(monkeypatch):
    """Only the machine's OSErrors become one line; a bug still shows its traceback."""
    import diviewer.cli as cli
    import diviewer.commands.data as data

    def bug(args):
        raise OSError(errno.EBADF, "Bad file descriptor")

    monkeypatch.setitem(data.ACTIONS, "check", bug)
    with pytest.raises(OSError):
        cli.main(["data", "check", "x"])
