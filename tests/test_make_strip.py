"""tools/make_strip.py: a rendered path's frames side by side, evenly chosen, never over an existing file."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest

from tool_modules import load_tool

make_strip = load_tool("make_strip")


def _walk(folder, n=5, shape=(6, 4)):
    (folder / "frames").mkdir(parents=True)
    for i in range(n):
        iio.imwrite(folder / "frames" / f"{i:06d}.png", np.full((*shape, 3), 40 * i, np.uint8))
    return folder


def test_the_strip_holds_the_chosen_frames_in_order(tmp_path):
    walk = _walk(tmp_path / "walk")
    out = tmp_path / "strip.png"
    assert make_strip.main([str(walk), "--out", str(out), "--frames", "3"]) == 0
    image = iio.imread(out)
    assert image.shape == (6, 12, 3)
    assert [image[0, 4 * k, 0] for k in range(3)] == [0, 80, 160]  # frames 0, 2 and 4


def test_all_frames_by_default_and_nothing_overwritten(tmp_path):
    walk = _walk(tmp_path / "walk", n=2)
    out = tmp_path / "strip.png"
    make_strip.main([str(walk), "--out", str(out)])
    assert iio.imread(out).shape == (6, 8, 3)
    before = out.read_bytes()
    with pytest.raises(SystemExit, match="exists"):
        make_strip.main([str(walk), "--out", str(out)])
    assert out.read_bytes() == before


def test_an_empty_folder_or_mixed_sizes_are_refused(tmp_path):
    (tmp_path / "empty" / "frames").mkdir(parents=True)
    with pytest.raises(SystemExit, match="no frames"):
        make_strip.main([str(tmp_path / "empty"), "--out", str(tmp_path / "a.png")])
    walk = _walk(tmp_path / "walk", n=1)
    iio.imwrite(walk / "frames" / "000001.png", np.zeros((3, 3, 3), np.uint8))
    with pytest.raises(SystemExit, match="differ in size"):
        make_strip.main([str(walk), "--out", str(tmp_path / "b.png")])
    assert not (tmp_path / "a.png").exists() and not (tmp_path / "b.png").exists()
