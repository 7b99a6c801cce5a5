"""`diviewer.render_frame`: the buffers `diviewer render` writes, returned as arrays instead; with a model, the
same neural image; a bad size refused before any GL work."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import diviewer
from diviewer import imageio
from diviewer.errors import DiviewerError

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "assets" / "models" / "cornell.onnx"


def test_the_frame_is_what_render_writes(gl_context, tmp_path):
    from diviewer.gl.renderer import BUFFERS
    from diviewer.render import render_to_dir

    scene = diviewer.load_scene("cornell")
    config = diviewer.sample_config(scene, 3, "train")
    frame = diviewer.render_frame(scene, config, size=(24, 16), model=MODEL, provider="cpu")
    assert set(frame) == {*BUFFERS, "neural"}
    assert frame["depth"].shape == (16, 24) and frame["neural"].shape == (16, 24, 3)
    render_to_dir("cornell", tmp_path / "r", res="24x16", seed=3, split="train", model=MODEL, provider="cpu")
    for name in (*BUFFERS, "neural"):
        written = imageio.read_exr(tmp_path / "r" / f"{name}.exr")
        np.testing.assert_allclose(frame[name], written.reshape(frame[name].shape), rtol=1e-6, atol=1e-6,
                                   err_msg=name)


def test_the_default_view_without_a_model(gl_context):
    frame = diviewer.render_frame("cornell", size=8)
    assert "neural" not in frame and frame["direct"].shape == (8, 8, 3)
    assert all(np.isfinite(v).all() for v in frame.values()) and frame["direct"].max() > 0


@pytest.mark.parametrize("size", [0, "0x8", "8x99999", (8, -1)])
def test_a_bad_size_is_a_user_error(size):
    with pytest.raises(DiviewerError, match="resolution"):
        diviewer.render_frame("cornell", size=size)


def test_the_public_api_is_light_until_used():
    """`import diviewer` and a scene load bring in no GL, no onnxruntime and no torch; every name of the API
    resolves, and a misspelt one is an AttributeError."""
    import subprocess
    import sys

    code = ("import sys, diviewer\n"
            "diviewer.load_scene('cornell')\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('torch', 'onnxruntime', 'moderngl')))\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == "[]", r.stdout + r.stderr
    assert all(callable(getattr(diviewer, name)) for name in diviewer.__all__ if name != "__version__")
    with pytest.raises(AttributeError):
        diviewer.render_frames  # noqa: B018


def test_the_buffers_are_the_renderers_frame(gl_context):
    """Without a model, `render_frame` is the renderer's own frame of that configuration, buffer for buffer."""

    from diviewer.gl.renderer import BUFFERS, Renderer
    from diviewer.scene import load_scene, sample_config

    cornell = load_scene("cornell")
    config = sample_config(cornell, 2, "test")
    got = diviewer.render_frame(cornell, config, (20, 12))
    with gl_context:  # current again: render_frame made and released its own context
        r = Renderer(gl_context, cornell, 20, 12)
        try:
            want = r.frame(config)
        finally:
            r.release()
    assert list(got) == list(BUFFERS) and got["depth"].shape == (12, 20) and got["direct"].shape == (12, 20, 3)
    for name in BUFFERS:
        np.testing.assert_array_equal(got[name], want[name])
