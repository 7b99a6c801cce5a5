"""A full disk during capture, evalset, train, render or bench: one line naming the user's file, exit 2, and
nothing half-written left where a resume would trust it.

Two ways: a real small tmpfs (mounted in a user and mount namespace with ``unshare -rm``; skipped, with the
reason, where the machine does not allow it) and, everywhere, a monkeypatched write raising OSError(ENOSPC).
"""

from __future__ import annotations

import errno
import functools
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.faults import write_error
import pytest

ROOT = Path(__file__).resolve().parents[1]
NO_SPACE = os.strerror(errno.ENOSPC)


@functools.lru_cache(maxsize=1)
def _tmpfs_refused() -> str | None:
    """Why a test cannot mount a small tmpfs here (None: it can)."""
    if shutil.which("unshare") is None:
        return "no unshare(1) on this machine"
    with tempfile.TemporaryDirectory() as d:
        p = subprocess.run(["unshare", "-rm", "sh", "-c", 'mount -t tmpfs -o size=64k tmpfs "$0"', d],
                           capture_output=True, text=True, timeout=60)
    if p.returncode != 0:
        return f"cannot mount a tmpfs in a user namespace here: {p.stderr.strip() or p.returncode}"
    return None


def on_small_disk(tmp_path: Path, size_kb: int, argv: list[str], fill: bool = False) -> tuple[subprocess.CompletedProcess,
                                                                                                Path, Path]:
    """Run ``python -m diviewer argv`` (``{disk}`` in argv: the small disk) with a tmpfs of ``size_kb`` KiB.

    Returns the process, the mount point (as named in the messages) and a copy of what the disk held at the end.
    """
    reason = _tmpfs_refused()
    if reason:
        pytest.skip(reason)
    disk, kept = tmp_path / "disk", tmp_path / "kept"
    disk.mkdir()
    kept.mkdir()
    filler = 'dd if=/dev/zero of="$mnt/.filler" bs=1k 2>/dev/null; ' if fill else ""
    script = (f'mnt="$1"; kept="$2"; shift 2; mount -t tmpfs -o size={size_kb}k tmpfs "$mnt" || exit 97; {filler}'
              '"$@"; rc=$?; rm -f "$mnt/.filler"; cp -a "$mnt"/. "$kept"/; exit $rc')
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
           "PYTHONWARNINGS": "ignore"}
    args = [a.replace("{disk}", str(disk)) for a in argv]
    p = subprocess.run(["unshare", "-rm", "sh", "-c", script, "sh", str(disk), str(kept), sys.executable, "-m",
                        "diviewer", *args], capture_output=True, text=True, timeout=600, env=env)
    if p.returncode == 97:
        pytest.skip(f"cannot mount a tmpfs here: {p.stderr.strip()}")
    return p, disk, kept


def _one_line_naming(stderr: str, under: Path) -> str:
    """The error line: the last of stderr (progress bars come before it), naming a file under ``under``."""
    assert "Traceback" not in stderr, stderr
    line = stderr.strip().splitlines()[-1]
    assert NO_SPACE in line and f"{under}{os.sep}" in line, stderr
    named = line.split("error: ", 1)[1].split(": ", 1)[0]
    assert not Path(named).name.startswith("."), line  # the user's file, never a temporary one
    return named


def _no_temporary_files(root: Path) -> None:
    left = [p for p in root.rglob(".*") if p.name != ".diviewer.lock"]
    assert left == [], left


# ---------------------------------------------------------------------------------------------
# A real full disk


def test_capture_on_a_full_disk_stops_cleanly_and_resumes(gl_context, tmp_path):
    argv = ["capture", "--frames", "40", "--res", "16", "--gt", "vxgi", "--vxgi-res", "16", "--thumbs", "0",
            "--out", "{disk}/data"]
    p, disk, kept = on_small_disk(tmp_path, 320, argv)  # the manifest fits, a dozen frames do, 40 do not
    assert p.returncode == 2, p.stderr
    named = _one_line_naming(p.stderr, disk / "data" / "frames")
    from diviewer.data.dataset import Dataset

    _no_temporary_files(kept)
    ds = Dataset(kept / "data")
    problems = ds.check()
    assert problems and all(pr.problem == "missing" for pr in problems), problems  # complete or absent, never half
    assert Path(named).stem.isdigit() and int(Path(named).stem) in {pr.index for pr in problems}
    from diviewer.cli import main

    assert main([a.replace("{disk}", str(kept)) for a in argv]) == 0  # space again: the same command finishes
    assert Dataset(kept / "data").check() == []


def test_render_on_a_full_disk_writes_nothing(gl_context, tmp_path):
    p, disk, kept = on_small_disk(tmp_path, 64, ["render", "--res", "64", "--out", "{disk}/r"], fill=True)
    assert p.returncode == 2, p.stderr
    _one_line_naming(p.stderr, disk / "r")
    assert [q for q in kept.rglob("*") if q.is_file()] == []  # all or nothing: the files are renamed together


def test_train_on_a_full_disk_leaves_no_half_checkpoint(tmp_path):
    torch = pytest.importorskip("torch")
    from train.test_trainer import make_dataset

    make_dataset(tmp_path / "data")
    argv = ["train", "--data", str(tmp_path / "data"), "--out", "{disk}/run", "--no-world-inputs", "--k", "4", "--ndf", "8", "--epochs", "1",
            "--batch-size", "4", "--lr-decay", "none", "--device", "cpu"]
    p, disk, kept = on_small_disk(tmp_path, 1024, argv)  # metrics fit, a 1.4 MB checkpoint does not
    assert p.returncode == 2, p.stderr
    named = _one_line_naming(p.stderr, disk / "run")
    assert named.endswith(".ckpt"), named
    _no_temporary_files(kept)
    for ckpt in kept.rglob("*.ckpt"):  # whatever checkpoint is there is whole
        torch.load(ckpt, weights_only=True, map_location="cpu")


def test_evalset_on_a_full_disk_stops_cleanly(tmp_path):
    pytest.importorskip("mitsuba")
    argv = ["evalset", "--out", "{disk}/es", "--frames-per-split", "2", "--res", "16", "--spp", "8", "--ladder", "1,2"]
    p, disk, kept = on_small_disk(tmp_path, 48, argv)  # the manifest and a frame or two, not four
    assert p.returncode == 2, p.stderr
    _one_line_naming(p.stderr, disk / "es")
    _no_temporary_files(kept)
    if (kept / "es" / "manifest.json").is_file():
        from diviewer.data.dataset import Dataset

        assert all(pr.problem == "missing" for pr in Dataset(kept / "es").check())


def test_bench_results_on_a_full_disk_are_one_line(gl_context, tmp_path):
    pytest.importorskip("onnx")
    p, disk, kept = on_small_disk(tmp_path, 64, ["bench", "--quick", "--json", "{disk}/b.json"], fill=True)
    assert p.returncode == 2, p.stderr
    assert _one_line_naming(p.stderr, disk) == str(disk / "b.json")
    assert list(kept.iterdir()) == []


# ---------------------------------------------------------------------------------------------
# A monkeypatched write, everywhere


def _full_after(n: int, real, written: list):
    """``real`` (np.save-like: file, data) writing half and raising ENOSPC from the n-th call on."""
    def save(f, arr, *args, **kwargs):
        written.append(f)
        if len(written) >= n:
            f.write(b"\x93NUMPY half a frame")
            raise OSError(errno.ENOSPC, NO_SPACE)  # no file name: the writer must say which file
        return real(f, arr, *args, **kwargs)
    return save


def _last_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return err.strip().splitlines()[-1]


def test_capture_full_disk_monkeypatched(gl_context, tmp_path, capsys, monkeypatch):
    from diviewer.cli import main
    from diviewer.data.dataset import Dataset

    argv = ["capture", "--frames", "6", "--res", "16", "--gt", "vxgi", "--vxgi-res", "16", "--thumbs", "0",
            "--out", str(tmp_path / "data")]
    monkeypatch.setattr(np, "save", _full_after(3, np.save, []))
    assert main(argv) == 2
    line = _last_line(capsys)
    assert NO_SPACE in line and f"{tmp_path / 'data' / 'frames'}{os.sep}000002.npy" in line, line
    monkeypatch.undo()
    _no_temporary_files(tmp_path)
    problems = Dataset(tmp_path / "data").check()
    assert [pr.index for pr in problems] == [2, 3, 4, 5] and all(pr.problem == "missing" for pr in problems)
    assert main(argv) == 0 and Dataset(tmp_path / "data").check() == []


def test_evalset_full_disk_monkeypatched(tmp_path, capsys, monkeypatch):
    pytest.importorskip("mitsuba")
    from diviewer.cli import main

    monkeypatch.setattr(np, "save", _full_after(2, np.save, []))
    argv = ["evalset", "--out", str(tmp_path / "es"), "--frames-per-split", "1", "--res", "16", "--spp", "4",
            "--ladder", "1"]
    assert main(argv) == 2
    line = _last_line(capsys)
    assert NO_SPACE in line and f"{tmp_path / 'es' / 'frames'}{os.sep}" in line, line
    _no_temporary_files(tmp_path)


def test_train_full_disk_monkeypatched(tmp_path, capsys, monkeypatch):
    torch = pytest.importorskip("torch")
    from train.test_trainer import make_dataset

    from diviewer.cli import main

    make_dataset(tmp_path / "data")

    def full(obj, f, *args, **kwargs):
        f.write(b"PK half a checkpoint")
        raise OSError(errno.ENOSPC, NO_SPACE)

    monkeypatch.setattr(torch, "save", full)
    out = tmp_path / "run"
    rc = main(["train", "--data", str(tmp_path / "data"), "--out", str(out), "--no-world-inputs", "--k", "4", "--ndf", "8", "--epochs", "1",
                "--lr-decay", "none",
               "--batch-size", "4", "--device", "cpu", "--max-steps", "1"])
    line = _last_line(capsys)
    assert rc == 2 and NO_SPACE in line and f"{out}{os.sep}" in line and ".ckpt" in line, line
    assert not list(out.glob("*.ckpt")) and not (out / ".diviewer.lock").exists()
    _no_temporary_files(tmp_path)


def test_bench_full_disk_monkeypatched(gl_context, tmp_path, capsys, monkeypatch):
    pytest.importorskip("onnx")
    from diviewer.cli import main

    real = Path.write_text

    def full(self, *args, **kwargs):
        if self.parent == tmp_path:
            raise OSError(errno.ENOSPC, NO_SPACE)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", full)
    assert main(["bench", "--quick", "--json", str(tmp_path / "b.json")]) == 2
    line = _last_line(capsys)
    assert NO_SPACE in line and str(tmp_path / "b.json") in line, line
    assert list(tmp_path.iterdir()) == []


def test_write_error_maps_only_the_machines_faults(tmp_path, monkeypatch):
    import diviewer.faults as faults

    tmp, final = tmp_path / ".a.npy.123.npy", tmp_path / "a.npy"
    # numpy's tofile on a full disk: an OSError with no errno
    monkeypatch.setattr(faults, "disk_full", lambda folder: True)
    fault = write_error(OSError("4096 requested and 1984 written"), {tmp: final})
    assert fault.errno == errno.ENOSPC and fault.filename == str(final)
    monkeypatch.setattr(faults, "disk_full", lambda folder: False)
    assert write_error(OSError("4096 requested and 1984 written"), {tmp: final}) is None
    assert write_error(DiviewerError("a bad scene"), {tmp: final}) is None  # a user error stays itself
    assert write_error(ValueError("a bug"), {tmp: final}) is None  # and a bug keeps its traceback
    renamed = write_error(OSError(errno.EACCES, "Permission denied", str(tmp)), {tmp: final})
    assert renamed.filename == str(final)
