"""Tests for the figures of diviewer.train.report: a run's curves.png and a ladder's curves on one figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from diviewer.train.report import draw_curves, draw_ladder_curves, read_metrics, write_metrics

PIL = pytest.importorskip("PIL")
from PIL import Image  # noqa: E402

LINE_COLOURS = [(31, 119, 180), (255, 127, 14), (44, 160, 44)]


def _rows(steps: int, level: float) -> list[dict]:
    return [{"epoch": float(i), "step": 100 * i, "loss_G_L1": 1.0 / i, "val_psnr_tm": level + i,
             "val_ssim_tm": 0.5 + i / (4 * steps), "val_mse": 1e-3 / i, "val_mse_tm": 1e-2 / i,
             "val_ssim": 0.9} for i in range(1, steps + 1)]


def _colours(path: Path) -> set[tuple[int, int, int]]:
    with Image.open(path) as im:
        assert im.format == "PNG"
        px = np.asarray(im.convert("RGB")).reshape(-1, 3)
    return {tuple(int(v) for v in c) for c in np.unique(px, axis=0)}


def _panel_colours(path: Path, panels: int) -> list[set[tuple[int, int, int]]]:
    with Image.open(path) as im:
        a = np.asarray(im.convert("RGB"))
    w = a.shape[1] // panels
    return [{tuple(int(v) for v in c) for c in np.unique(a[:, i * w:(i + 1) * w].reshape(-1, 3), axis=0)}
            for i in range(panels)]


def test_a_ladder_draws_every_k_in_each_of_its_three_panels(tmp_path):
    out = tmp_path / "ladder_curves.png"
    draw_ladder_curves({"K = 8": _rows(6, 30.0), "K = 16": _rows(4, 31.0), "K = 32": _rows(5, 29.0)}, out)
    with Image.open(out) as im:
        assert im.size == (3 * 420, 330)
    for colours in _panel_colours(out, 3):  # each panel: a line (and a legend entry) per K
        assert set(LINE_COLOURS) <= colours


def test_a_k_without_rows_yet_keeps_its_legend_and_the_others_are_drawn(tmp_path):
    """A K whose run has not validated yet (no metrics.csv) is named in the legend; its neighbours plot."""
    out = tmp_path / "ladder_curves.png"
    draw_ladder_curves({"K = 8": _rows(3, 30.0), "K = 16": read_metrics(tmp_path / "missing.csv")}, out)
    assert set(LINE_COLOURS[:2]) <= _colours(out)


def test_a_ladder_of_runs_without_any_rows_says_so_rather_than_failing(tmp_path):
    out = tmp_path / "ladder_curves.png"
    draw_ladder_curves({"K = 8": [], "K = 16": []}, out)
    colours = _colours(out)
    assert LINE_COLOURS[0] in colours and (44, 160, 44) not in colours


def test_a_runs_curves_read_back_from_its_metrics_csv(tmp_path):
    """curves.png from the rows metrics.csv holds, a run without a discriminator included (its panel says so)."""
    write_metrics(tmp_path / "metrics.csv", _rows(5, 30.0))
    rows = read_metrics(tmp_path / "metrics.csv")
    assert [r["step"] for r in rows] == [100.0, 200.0, 300.0, 400.0, 500.0]
    draw_curves(rows, tmp_path / "curves.png", best_epoch=4.0, stop_epoch=5.0)
    panels = _panel_colours(tmp_path / "curves.png", 4)
    assert set(LINE_COLOURS[:2]) <= panels[0] and set(LINE_COLOURS[:2]) <= panels[1]
    assert (214, 39, 40) in panels[0]  # the red stop line
    assert LINE_COLOURS[2] in panels[2]  # G rec
    assert not set(LINE_COLOURS) & panels[3]  # no netD: a grey sentence, no line
