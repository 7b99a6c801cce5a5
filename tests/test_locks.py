"""One run per output folder (diviewer.locks): a second capture, evalset or train into a folder refuses at once,
naming the owner; a killed run's lock is taken over; capture shards with disjoint frames share a folder."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from diviewer.errors import DiviewerError
from diviewer.locks import lock_path, run_lock, shard_part, shards_overlap

ROOT = Path(__file__).resolve().parents[1]

# A process that takes the lock of a folder, says so on stdout, and holds it until killed. Ctrl-C (SIGINT) stops it
# as it stops a run in a terminal, even where the suite itself runs as a background job (which ignores SIGINT,
# and a child inherits that).
HOLDER = textwrap.dedent("""
    import signal, sys, time
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from diviewer.locks import run_lock, shard_part
    folder, command, k, n = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    with run_lock(folder, command, shard_part(k, n)):
        print("held", flush=True)
        time.sleep(600)
""")


def _env() -> dict:
    return {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}


def _hold(folder: Path, command: str = "capture", shard: tuple[int, int] = (1, 1)) -> subprocess.Popen:
    """Start a real process holding ``folder``'s lock; returns once it holds it."""
    p = subprocess.Popen([sys.executable, "-c", HOLDER, str(folder), command, *map(str, shard)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    line = p.stdout.readline()
    if line.strip() != "held":
        p.kill()
        raise AssertionError(f"the holder did not take the lock: {line!r} {p.stderr.read()}")
    return p


def _stop(p: subprocess.Popen, sig=signal.SIGINT) -> None:
    p.send_signal(sig)
    p.wait(timeout=30)


def test_a_second_run_into_a_held_folder_refuses_at_once_naming_the_owner(tmp_path):
    folder = tmp_path / "data"
    holder = _hold(folder, "capture")
    try:
        info = json.loads(lock_path(folder).read_text())
        assert info["pid"] == holder.pid and info["host"] == socket.gethostname() and info["command"] == "capture"
        t0 = time.monotonic()
        with pytest.raises(DiviewerError) as exc:
            with run_lock(folder, "train"):
                pass
        assert time.monotonic() - t0 < 5  # at once, not after a wait
        msg = str(exc.value)
        assert f"pid {holder.pid}" in msg and socket.gethostname() in msg and "diviewer capture" in msg
        assert "--out" in msg and "\n" not in msg
    finally:
        _stop(holder)
    assert not lock_path(folder).exists()  # a run that ends removes its lock file
    with run_lock(folder, "train") as path:  # and the folder is free again
        assert json.loads(path.read_text())["pid"] == os.getpid()


def test_a_killed_runs_lock_is_taken_over(tmp_path):
    folder = tmp_path / "run"
    holder = _hold(folder, "train")
    _stop(holder, signal.SIGKILL)  # no clean-up ran: the file stays, the kernel dropped the flock
    assert lock_path(folder).is_file() and json.loads(lock_path(folder).read_text())["pid"] == holder.pid
    with run_lock(folder, "train") as path:
        assert json.loads(path.read_text())["pid"] == os.getpid()
    assert not lock_path(folder).exists()


def test_a_folder_made_before_locks_existed_is_resumed(tmp_path):
    """A dataset folder with no lock file (a capture of an earlier version, still resumable) is simply taken."""
    folder = tmp_path / "data"
    (folder / "frames").mkdir(parents=True)
    (folder / "manifest.json").write_text("{}")
    with run_lock(folder, "capture"):
        pass
    assert sorted(p.name for p in folder.iterdir()) == ["frames", "manifest.json"]


def test_a_refused_run_leaves_no_empty_folder(tmp_path):
    with pytest.raises(RuntimeError):
        with run_lock(tmp_path / "new", "evalset"):
            raise RuntimeError("refused before writing")
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("a, b, overlap", [((1, 2), (2, 2), False), ((1, 2), (1, 2), True), ((1, 1), (2, 4), True),
                                           ((1, 2), (2, 4), False), ((1, 2), (3, 4), True), ((2, 3), (1, 2), True),
                                           ((1, 4), (2, 4), False)])
def test_shards_overlap_when_they_share_a_frame(a, b, overlap):
    assert shards_overlap(shard_part(*a), shard_part(*b)) is overlap
    frames = 48  # the rule against the frames themselves
    fa = {i for i in range(frames) if i % a[1] == a[0] - 1}
    fb = {i for i in range(frames) if i % b[1] == b[0] - 1}
    assert bool(fa & fb) is overlap


def test_disjoint_shards_share_a_folder_and_overlapping_runs_refuse(tmp_path):
    folder = tmp_path / "data"
    one = _hold(folder, "capture", (1, 2))
    try:
        with run_lock(folder, "capture", shard_part(2, 2)):  # the other half: allowed
            pass
        for part in (None, shard_part(1, 2), shard_part(3, 4)):  # the whole, the same shard, an overlapping one
            with pytest.raises(DiviewerError, match=rf"shard 1/2\), pid {one.pid}"):
                with run_lock(folder, "capture", part):
                    pass
        with pytest.raises(DiviewerError, match=f"pid {one.pid}"):  # another command: refused
            with run_lock(folder, "evalset"):
                pass
    finally:
        _stop(one)
    with run_lock(folder, "capture"):  # the shard ended: the whole capture may run
        pass


def _capture(out: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "diviewer", "capture", "--frames", "6", "--res", "16", "--gt", "vxgi",
                             "--vxgi-res", "16", "--thumbs", "0", "--out", str(out), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())


def test_two_captures_into_one_folder_one_refuses(gl_context, tmp_path):
    """Two real `diviewer capture` processes started together into one folder (with different settings: the
    issue's case mixed their frames under one manifest): one finishes, the other refuses in one line."""
    out = tmp_path / "data"
    a, b = _capture(out, "--seed", "1"), _capture(out, "--seed", "2")
    results = [(p.wait(timeout=300), p.stderr.read()) for p in (a, b)]
    codes = sorted(rc for rc, _ in results)
    refused = next((err for rc, err in results if rc == 2), "")
    # Both may also start far enough apart that the second finds the first's manifest and refuses it as another
    # dataset: either way exactly one capture wrote the folder.
    assert codes == [0, 2], results
    assert ("another run is writing here" in refused or "a different dataset is already there" in refused), refused
    assert "Traceback" not in refused and len([l for l in refused.splitlines() if "error" in l]) == 1
    from diviewer.data.dataset import Dataset

    ds = Dataset(out)
    assert ds.check() == [] and not lock_path(out).exists()
    winner = next(p for p, (rc, _) in zip((a, b), results) if rc == 0)
    assert ds.manifest["seed"] == (1 if winner is a else 2)


def test_a_capture_refuses_while_another_holds_the_folder(gl_context, tmp_path):
    out = tmp_path / "data"
    holder = _hold(out, "capture")
    try:
        p = _capture(out)
        rc, err = p.wait(timeout=120), p.stderr.read()
    finally:
        _stop(holder)
    assert rc == 2 and f"pid {holder.pid}" in err and "Traceback" not in err, err
    assert not (out / "manifest.json").exists()  # refused before writing anything


@pytest.mark.parametrize("argv", [["train", "--data", "{t}/data", "--out", "{t}/out", "--k", "4"],
                                  ["evalset", "--out", "{t}/out", "--frames-per-split", "1", "--res", "16"]])
def test_train_and_evalset_refuse_a_held_folder(tmp_path, capsys, argv):
    """The issue's two trainings into one folder (best.ckpt of one K, last.ckpt of another): the second refuses."""
    from diviewer.cli import main

    if argv[0] == "train":
        pytest.importorskip("torch")
    out = tmp_path / "out"
    holder = _hold(out, argv[0])
    try:
        rc = main([a.format(t=tmp_path) for a in argv])
    finally:
        _stop(holder)
    err = capsys.readouterr().err
    assert rc == 2 and f"pid {holder.pid}" in err and f"diviewer {argv[0]}" in err and err.count("\n") == 1, err
    assert not out.exists()  # nothing was written, and the holder's lock is gone with it
