"""Issue 29's smaller findings: each a clean refusal (one line, exit 2, nothing written) or the right advice."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from diviewer.cli import main
from diviewer.errors import DiviewerError


def test_train_refuses_a_decay_start_without_a_decay_or_beyond_the_run(tmp_path, capsys):
    pytest.importorskip("torch")
    sys.path.insert(0, str(Path(__file__).parents[1]))
    from train.test_trainer import make_dataset

    make_dataset(tmp_path / "data")  # 8 train frames: 2 steps per epoch at batch 4
    base = ["train", "--data", str(tmp_path / "data"), "--out", str(tmp_path / "run"), "--k", "4", "--ndf", "8",
            "--batch-size", "4", "--device", "cpu", "--epochs", "2", "--recipe", "paper"]  # the paper's: no decay
    for extra, needle in ((["--lr-decay-start", "1"], "--lr-decay-start: sets where a decay starts"),
                          (["--lr-decay", "cosine", "--lr-decay-start", "4"], "the run ends at step 4"),
                          (["--lr-decay", "cosine", "--lr-decay-start", "99"], "the decay would never start")):
        assert main(base + extra) == 2
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1, err
        assert not (tmp_path / "run").exists()  # refused before the run folder was made


def test_view_refuses_a_gi_resolution_beyond_the_gl_limits(ctx):
    from types import SimpleNamespace

    from diviewer.gl.context import max_render_size
    from diviewer.gl.neural import GISettings
    from diviewer.viewer.gi import GIControl

    renderer = SimpleNamespace(width=64, height=64)
    gi = GIControl(ctx, renderer, SimpleNamespace(), "model", GISettings())
    model = SimpleNamespace(resolution=(64, 64), multiple=16, shape_note=lambda w, h: "")
    mw, _ = max_render_size(ctx)
    # a fraction above the window (refused as a fraction: at most 1/1), beyond the context's limits, and within
    # them but too large to allocate (llvmpipe: no float RGBA target of 2 GiB or more)
    with pytest.raises(DiviewerError, match="--gi-res: .*not a fraction of the window from 1/16 to 1"):
        gi._size_for(model, f"{mw // 64 + 1}/1", (64, 64))
    with pytest.raises(DiviewerError, match=r"--gi-res: .*(WxH with 1 <= N <= \d+, got|larger than this GL context)"):
        gi._size_for(model, f"{mw + 1}x64", (64, 64))
    with pytest.raises(DiviewerError, match="--gi-res: .*(larger than this GL context allows|too large for)"):
        gi._size_for(model, "11600x11600", (64, 64))
    assert gi._size_for(model, "1/2", (64, 64)) == (32, 32)
    assert ctx.error == "GL_NO_ERROR"


def test_data_check_on_an_evaluation_set_names_evalset(tmp_path, capsys):
    from test_extremes_files import make_dataset

    ds = make_dataset(tmp_path / "es")
    manifest = json.loads((ds.root / "manifest.json").read_text())
    (ds.root / "manifest.json").write_text(json.dumps({**manifest, "kind": "evalset"}))
    ds.path(0, ".json").unlink()
    assert main(["data", "check", str(ds.root)]) == 1
    out = capsys.readouterr().out
    assert "run the same `diviewer evalset` again" in out and "diviewer capture" not in out, out
