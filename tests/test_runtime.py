"""The onnxruntime model wrapper: metadata checks and refusals, and the GL neural pass end to end."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.runtime import NeuralGI, choose_providers, pack_buffers, read_metadata

from onnx_models import base_meta, direct_times
from scenes import facing_plane

pytest.importorskip("onnx")


def test_model_runs_and_reports_metadata(tmp_path):
    path = direct_times(tmp_path / "m.onnx")
    model = NeuralGI(path)
    assert model.provider == "CPUExecutionProvider" and model.multiple == 16
    x = np.random.default_rng(0).random((32, 48, 10), dtype=np.float32)
    y = model.run(x)
    assert y.shape == (32, 48, 3)
    np.testing.assert_allclose(y, 2 * x[..., 7:10], rtol=1e-6)
    assert read_metadata(path)["scene"] == "plane"


@pytest.mark.parametrize("case,words", [
    ("no_meta", "no diviewer metadata"),
    ("wrong_channels", "input channels"),
    ("graph_channels", "input channels"),
    ("newer_encoding", "newer"),
    ("missing_field", "lacks"),
    ("truncated", "truncated"),
])
def test_bad_models_are_refused_with_the_reason(tmp_path, case, words):
    path = tmp_path / "m.onnx"
    meta = base_meta()
    if case == "no_meta":
        direct_times(path, with_meta=False)
    elif case == "wrong_channels":
        direct_times(path, meta={**meta, "channels": [["depth", 1], ["normal", 3], ["albedo", 3]]})
    elif case == "graph_channels":
        direct_times(path, channels=7)
    elif case == "newer_encoding":
        direct_times(path, meta={**meta, "encoding": {"version": 999}})
    elif case == "missing_field":
        direct_times(path, meta={k: v for k, v in meta.items() if k != "scene_hash"})
    elif case == "truncated":
        direct_times(path)
        path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    with pytest.raises(DiviewerError) as info:
        NeuralGI(path)
    assert words in str(info.value) and str(path) in str(info.value)


def test_model_for_another_scene_is_refused(tmp_path):
    scene = facing_plane()
    path = direct_times(tmp_path / "m.onnx", meta=base_meta(scene_hash="f" * 64, scene="cornell"))
    with pytest.raises(DiviewerError, match="trained for scene 'cornell'"):
        NeuralGI(path, scene=scene)
    ok = direct_times(tmp_path / "ok.onnx", meta=base_meta(scene_hash=scene.file_hash))
    NeuralGI(ok, scene=scene)


def test_size_must_be_a_multiple(tmp_path):
    model = NeuralGI(direct_times(tmp_path / "m.onnx"))
    with pytest.raises(DiviewerError, match="multiples of 16"):
        model.run(np.zeros((1, 20, 32, 10), np.float32))


def test_provider_choice():
    assert choose_providers(["CPUExecutionProvider"]) == ["CPUExecutionProvider"]
    assert choose_providers(["CPUExecutionProvider", "CUDAExecutionProvider", "TensorrtExecutionProvider"])[0] == \
        "TensorrtExecutionProvider"
    assert choose_providers(["CPUExecutionProvider", "CUDAExecutionProvider"], "cpu") == ["CPUExecutionProvider"]
    with pytest.raises(DiviewerError, match="not available"):
        choose_providers(["CPUExecutionProvider"], "cuda")


def test_gl_neural_pass_end_to_end(ctx, tmp_path):
    """scene -> GL buffers -> packed on the GPU -> ONNX -> texture -> composite: finite, right size."""
    from diviewer.gl.neural import NeuralPass
    from diviewer.gl.display import DisplayPass
    from diviewer.gl.renderer import Renderer

    scene = facing_plane(lights=[{"name": "sun", "type": "directional", "direction": [0.3, -0.4, -1.0],
                                  "irradiance": 2.0}])
    model = NeuralGI(direct_times(tmp_path / "m.onnx", meta=base_meta(scene_hash=scene.file_hash)), scene=scene)
    renderer = Renderer(ctx, scene, 48, 32)
    neural = NeuralPass(ctx, renderer, model)
    comp = DisplayPass(ctx, renderer.shaders)
    try:
        frame = renderer.frame()
        tex = neural.run()
        # the GPU packing equals the CPU packing of the read-back buffers, bit for bit
        np.testing.assert_array_equal(neural.packed[0], pack_buffers(frame))
        np.testing.assert_allclose(neural.image(), 2 * frame["direct"], rtol=1e-6)
        assert set(neural.timings) == {"readback", "inference", "upload"}
        # the texture holds rows top first; composited with flip_y it shows the right way up at any size
        out = ctx.texture((96, 64), 4)
        fbo = ctx.framebuffer([out])
        comp.run(tex, fbo, flip_y=True)
        shown = np.flipud(np.frombuffer(fbo.read(components=3), np.uint8).reshape(64, 96, 3))
        expected = comp.to_ldr(2 * frame["direct"])
        np.testing.assert_allclose(shown[::2, ::2].astype(int), expected.astype(int), atol=2)
        from diviewer.gl.context import unbind_framebuffer
        unbind_framebuffer(ctx)
        fbo.release()
        out.release()
    finally:
        comp.release()
        neural.release()
        renderer.release()


def test_nan_and_inf_in_buffers_stay_visible_not_fatal(ctx, tmp_path):
    """A broken buffer reaches the model as is; the runtime does not crash on it."""
    model = NeuralGI(direct_times(tmp_path / "m.onnx"))
    x = np.zeros((16, 16, 10), np.float32)
    x[0, 0, 7] = np.nan
    x[1, 1, 8] = np.inf
    y = model.run(x)
    assert y.shape == (16, 16, 3) and np.isfinite(y[2:, 2:]).all()


def test_render_with_model_writes_neural_exr(gl_context, tmp_path):
    """`diviewer render --model` writes neural.exr beside the buffers; another scene's model is refused."""
    from diviewer.cli import main
    from diviewer.imageio import read_exr
    from diviewer.scene import load_scene

    cornell = load_scene("cornell")
    path = direct_times(tmp_path / "m.onnx", meta={**base_meta(scene_hash=cornell.file_hash, scene="cornell"),
                                                    "resolution": [48, 32]})
    out = tmp_path / "r"
    assert main(["render", "--scene", "cornell", "--model", str(path), "--out", str(out)]) == 0
    neural, direct = read_exr(out / "neural.exr"), read_exr(out / "direct.exr")
    assert neural.shape == (32, 48, 3), "defaults to the model's resolution"
    np.testing.assert_allclose(neural, 2 * direct, rtol=1e-6)
    assert (out / "neural.png").is_file()
    assert main(["render", "--scene", "atrium", "--model", str(path), "--out", str(tmp_path / "a")]) == 2
    assert main(["render", "--scene", "cornell", "--model", str(path), "--res", "40", "--out", str(tmp_path / "b")]) == 2
