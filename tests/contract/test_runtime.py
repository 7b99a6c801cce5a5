"""The onnxruntime model wrapper: metadata checks and refusals, the shipped models, and the GL neural pass."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from diviewer.contract.encoding import input_channel_slices
from diviewer.errors import DiviewerError
from diviewer.paths import models_dir
from diviewer.contract.runtime import NeuralGI, choose_providers, pack_buffers, read_metadata

from onnx_models import base_meta, direct_times, random_buffers
from scenes import facing_plane

# The hand-built test models need the `onnx` package (train extra); the runtime itself needs only
# onnxruntime, so the tests of shipped models and of provider choice run without it.
needs_onnx = pytest.mark.skipif(importlib.util.find_spec("onnx") is None,
                                reason="builds a test model with onnx (pip install 'diviewer[train]')")
DIRECT = input_channel_slices()["direct"]
SHIPPED = sorted(Path(models_dir()).glob("*.onnx"))


@needs_onnx
def test_model_runs_and_reports_metadata(tmp_path):
    path = direct_times(tmp_path / "m.onnx")
    model = NeuralGI(path)
    assert model.provider == "CPUExecutionProvider" and model.multiple == 16
    x = np.random.default_rng(0).random((32, 48, 10), dtype=np.float32)
    y = model.run(x)
    assert y.shape == (32, 48, 3)
    np.testing.assert_allclose(y, 2 * x[..., DIRECT], rtol=1e-6)
    assert read_metadata(path)["scene"] == "plane"


@needs_onnx
def test_worker_threads_sleep_between_runs_unless_asked_to_spin(tmp_path):
    # Spinning onnxruntime threads take the cores the next frame's GL passes need on a software
    # rasterizer (tools/experiments/frame_probe.py --compare spin); the same answers either way.
    path = direct_times(tmp_path / "m.onnx")
    sleeping, spinning = NeuralGI(path), NeuralGI(path, spin=True)
    key = "session.intra_op.allow_spinning"
    assert sleeping.session.get_session_options().get_session_config_entry(key) == "0"
    with pytest.raises(Exception, match=key):  # onnxruntime's default (spin) is left alone
        spinning.session.get_session_options().get_session_config_entry(key)
    x = np.random.default_rng(1).random((16, 16, 10), dtype=np.float32)
    np.testing.assert_array_equal(sleeping.run(x), spinning.run(x))


@needs_onnx
@pytest.mark.parametrize("case,words", [
    ("no_meta", "no diviewer metadata"),
    ("wrong_channels", "input channels"),
    ("graph_channels", "input channels"),
    ("newer_encoding", "newer"),
    ("missing_field", "lacks"),
    ("truncated", "truncated"),
    ("lights_missing", "broken encoding"),
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
    elif case == "lights_missing":  # encoding 4 without its light count: the graph's light input has no size
        direct_times(path, meta={**meta, "encoding": {"version": 4, "world_center": [0, 0, 0],
                                                      "world_half": [1, 1, 1]}})
    elif case == "missing_field":
        direct_times(path, meta={k: v for k, v in meta.items() if k != "scene_hash"})
    elif case == "truncated":
        direct_times(path)
        path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    with pytest.raises(DiviewerError) as info:
        NeuralGI(path)
    assert words in str(info.value) and str(path) in str(info.value)


@needs_onnx
def test_model_for_another_scene_is_refused(tmp_path):
    scene = facing_plane()
    path = direct_times(tmp_path / "m.onnx", meta=base_meta(scene_hash="f" * 64, scene="cornell"))
    with pytest.raises(DiviewerError, match="trained for scene 'cornell'"):
        NeuralGI(path, scene=scene)
    ok = direct_times(tmp_path / "ok.onnx", meta=base_meta(scene_hash=scene.file_hash))
    NeuralGI(ok, scene=scene)


def test_any_size_is_padded_to_the_stride_and_cropped_back():
    """A shipped model (stride 128) at sizes that are not multiples of it: the output has the frame's size, is
    finite, and each pixel equals that pixel of a run on the frame padded by hand (diviewer.contract.padding)."""
    from diviewer.contract.padding import crop_nhwc, pad_nhwc

    model = NeuralGI(SHIPPED[0])  # a shipped model: no onnx package needed
    m = model.multiple
    from diviewer.contract.padding import pad_camera_params

    scale = 1.0 if model.light_scaled else None  # encoding 2 takes each frame's light scale
    view = {"position": (0.0, 1.0, 3.4), "target": (0.0, 1.0, 0.0), "up": (0.0, 1.0, 0.0), "fov": 40.0}
    rng = np.random.default_rng(0)
    for h, w in [(24, 24), (20, 36), (40, 12), (12, m)]:  # a frame that fills the stride: its column guard
        x = random_buffers(rng, h, w)
        cam = NeuralGI.camera(view, w, h) if model.world else None  # encoding 3 takes each frame's camera
        y = model.run(x, light_scale=scale, camera=cam)
        assert y.shape == (h, w, 3) and np.all(np.isfinite(y))
        g = model.edge_guard
        padded = pad_nhwc(x[None], m, g)
        assert padded.shape[1] % m == 0 and padded.shape[2] % m == 0 and padded.shape[2] >= w + 2 * g
        # the padded frame's camera: the frame's, its rays clamped to the frame (the runtime's pad_camera_params)
        if cam is None:
            y_pad = model.run(padded, light_scale=scale)
        else:  # the graph itself on the padded frame and the padded frame's camera (run() would widen its rays)
            feeds = {"buffers": padded, "light_scale": np.full(1, scale, np.float32),
                     "camera": pad_camera_params(cam, w, h, m, g)[None]}
            y_pad = model.session.run(["radiance"], feeds)[0]
        np.testing.assert_array_equal(y, crop_nhwc(np.maximum(y_pad, 0), h, w, m, g)[0])


def test_a_model_trained_on_random_width_crops_guards_its_columns_and_a_whole_frame_one_does_not(tmp_path):
    """The guard comes from the aspect crops the model's recipe record trained with (diviewer.contract.padding.edge_guard);
    an explicit ``guard`` overrides it, and a negative one is refused naming the field."""
    from diviewer.contract.padding import EDGE_GUARD

    whole = direct_times(tmp_path / "whole.onnx")
    crops = direct_times(tmp_path / "crops.onnx",
                         meta={**base_meta(), "recipe": {"train": {"aspect_crops": [0.5625, 1.7778]}}})
    assert NeuralGI(whole).edge_guard == 0 and NeuralGI(crops).edge_guard == EDGE_GUARD > 0
    assert NeuralGI(crops, guard=0).edge_guard == 0 and NeuralGI(whole, guard=3).edge_guard == 3
    with pytest.raises(DiviewerError, match="guard"):
        NeuralGI(crops, guard=-1)
    x = random_buffers(np.random.default_rng(1), 16, 16)  # fills the stride of 16: guarded, run at 16x48
    np.testing.assert_allclose(NeuralGI(crops).run(x), 2.0 * x[..., input_channel_slices()["direct"]], rtol=1e-6)
    assert [m.edge_guard for m in map(NeuralGI, SHIPPED)] == [
        EDGE_GUARD if _aspect_crops(p) else 0 for p in SHIPPED]


def _aspect_crops(path):
    return ((read_metadata(path).get("recipe") or {}).get("train") or {}).get("aspect_crops")


def test_the_guard_changes_what_a_crop_trained_network_sees_only_at_widths_the_stride_barely_pads():
    """A shipped crop-trained model: at a width the stride pads by EDGE_GUARD or more a side the guard changes
    nothing; at a width that fills the stride it runs the frame with replicated columns beside it."""
    from diviewer.contract.padding import EDGE_GUARD

    path = next((p for p in SHIPPED if _aspect_crops(p) and read_metadata(p)["encoding"].get("version", 1) < 4), None)
    if path is None:
        pytest.skip("no shipped crop-trained model without light inputs")
    guarded, bare = NeuralGI(path), NeuralGI(path, guard=0)
    m = guarded.multiple
    view = {"position": (0.0, 1.0, 3.4), "target": (0.0, 1.0, 0.0), "up": (0.0, 1.0, 0.0), "fov": 40.0}
    rng = np.random.default_rng(2)

    def both(w):
        x = random_buffers(rng, 8, w)
        extra = {"light_scale": 1.0, "camera": NeuralGI.camera(view, w, 8) if guarded.world else None}
        return guarded.run(x, **extra), bare.run(x, **extra)

    np.testing.assert_array_equal(*both(m - 2 * EDGE_GUARD))  # padded by EDGE_GUARD a side either way
    assert not np.array_equal(*both(m))


def test_pack_shader_refuses_a_layout_it_does_not_write(ctx):
    """pack.glsl writes 1 depth and 3 normal/albedo/direct components: other counts fail to compile."""
    import moderngl

    from diviewer.gl.neural import PACK_DEFINES
    from diviewer.gl.shaders import ShaderCache

    shaders = ShaderCache(ctx)
    try:
        shaders.compute("pack.glsl", PACK_DEFINES)  # the encoding's layout compiles
        with pytest.raises(moderngl.Error, match="channel counts differ"):
            shaders.compute("pack.glsl", {**PACK_DEFINES, "IN_NORMAL_N": 2})
    finally:
        shaders.release()


def test_provider_choice():
    assert choose_providers(["CPUExecutionProvider"]) == ["CPUExecutionProvider"]
    assert choose_providers(["CPUExecutionProvider", "CUDAExecutionProvider", "TensorrtExecutionProvider"])[0] == \
        "TensorrtExecutionProvider"
    assert choose_providers(["CPUExecutionProvider", "CUDAExecutionProvider"], "cpu") == ["CPUExecutionProvider"]
    with pytest.raises(DiviewerError, match="not available"):
        choose_providers(["CPUExecutionProvider"], "cuda")


@needs_onnx
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


@needs_onnx
def test_nan_and_inf_in_buffers_stay_visible_not_fatal(ctx, tmp_path):
    """The runtime does not sanitise: a NaN or Inf the model returns stays in the frame, exactly where
    it arose, and the display flags it (magenta) instead of hiding a broken buffer. (An exported model's
    own encoding maps NaN inputs of the network to 0; what its graph returns is passed on as is.)"""
    from diviewer.gl.display import DisplayPass
    from diviewer.gl.renderer import Renderer

    model = NeuralGI(direct_times(tmp_path / "m.onnx"))  # radiance = 2 * direct
    rng = np.random.default_rng(0)
    x = rng.random((16, 16, 10), dtype=np.float32)
    x[0, 0, DIRECT.start] = np.nan
    x[1, 1, DIRECT.start + 1] = np.inf
    y = model.run(x)
    assert y.shape == (16, 16, 3)
    assert np.isnan(y[0, 0, 0]) and np.isposinf(y[1, 1, 1])
    broken = ~np.isfinite(y).all(axis=-1)
    assert np.argwhere(broken).tolist() == [[0, 0], [1, 1]], "nothing else turned non-finite"
    np.testing.assert_allclose(y[~broken], 2 * x[..., DIRECT][~broken], rtol=1e-6)
    r = Renderer(ctx, facing_plane(), 16, 16)
    comp = DisplayPass(ctx, r.shaders)
    try:
        shown = comp.to_ldr(y)
        assert tuple(shown[0, 0]) == (255, 0, 255) and tuple(shown[1, 1]) == (255, 0, 255)
        assert not (shown[~broken] == (255, 0, 255)).all(axis=-1).any()
    finally:
        comp.release()
        r.release()


def test_models_are_shipped():
    assert [p.stem for p in SHIPPED if not p.with_suffix(".json").is_file()] == [] and SHIPPED, "each with its card"


@pytest.mark.slow
@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_shipped_model_runs_a_frame_of_its_scene(ctx, path):
    """Each shipped model loads for its scene and turns a GL frame into finite radiance of the frame's size;
    the GPU's packing of that frame is the encoding's channel layout, bit for bit."""
    from diviewer.gl.neural import NeuralPass
    from diviewer.gl.renderer import Renderer
    from diviewer.scene import load_scene, sample_config

    meta = read_metadata(path)
    scene = load_scene(meta["scene"])
    model = NeuralGI(path, scene=scene, provider="cpu")
    w, h = model.multiple, model.multiple  # the smallest frame it takes
    renderer = Renderer(ctx, scene, w, h)
    neural = NeuralPass(ctx, renderer, model)
    try:
        config = sample_config(scene, 0, "test")
        frame = renderer.frame(config)
        neural.run(**neural.inputs_for(scene, config))
        np.testing.assert_array_equal(neural.packed[0], pack_buffers(frame))
        out = neural.image()
        assert out.shape == (h, w, 3) and out.dtype == np.float32
        assert np.isfinite(out).all() and out.max() > 0
    finally:
        neural.release()
        renderer.release()


@needs_onnx
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


@needs_onnx
def test_a_shape_the_model_never_saw_is_said_not_silent(gl_context, tmp_path, capsys):
    """A model knows the frame shapes it was trained on (its recipe's aspect crops, else its resolution's shape):
    `render --model` at another shape still runs, says so and records it; at a trained shape nothing is said. The
    shipped cornell model trained on 9:16 to 16:9; a model of square frames (a toy of cornell's scene file) on
    squares only; the per-pixel linear baseline on every shape."""
    from diviewer.cli import main
    from diviewer.paths import models_dir
    from diviewer.scene import load_scene

    toy = direct_times(tmp_path / "square.onnx", meta=base_meta(load_scene("cornell").file_hash, "cornell"))
    crops, square = NeuralGI(models_dir() / "cornell.onnx"), NeuralGI(toy)
    linear = NeuralGI(models_dir() / "cornell_linear.onnx")
    assert crops.trained_aspects == pytest.approx((9 / 16, 16 / 9)) and square.trained_aspects == (1.0, 1.0)
    assert crops.shape_note(228, 128) == crops.shape_note(72, 128) == "" and square.shape_note(33, 32) == ""
    assert crops.shape_note(300, 128).startswith("the model was trained on frames of width/height 0.562 to 1.78 only")
    assert "at 228x128 (1.78) its GI is extrapolated" in square.shape_note(228, 128)
    assert linear.shape_note(300, 128) == linear.shape_note(32, 300) == ""
    for res, said in (("48x32", True), ("32x32", False)):
        out = tmp_path / res
        assert main(["render", "--scene", "cornell", "--model", str(toy), "--res", res, "--out", str(out)]) == 0
        record = json.loads((out / "frame.json").read_text())["neural"]
        err = capsys.readouterr().err
        assert ("shape_note" in record) == said and ("its GI is extrapolated" in err) == said


@pytest.mark.parametrize("res", ["40x40", "56x24", "24x44"])
def test_render_with_model_at_any_shape(gl_context, tmp_path, res):
    """`render --res WxH --model` at a square and two other shapes, none a multiple of the models' strides
    (16 for the toy, 128 for the shipped cornell model): finite output of the asked shape, each pixel the
    model's own (the toy returns 2 x direct, so a misplaced crop would show)."""
    from diviewer.cli import main
    from diviewer.imageio import read_exr
    from diviewer.paths import models_dir
    from diviewer.scene import load_scene

    cornell = load_scene("cornell")
    w, h = (int(v) for v in res.split("x"))
    toy = direct_times(tmp_path / "m.onnx", meta=base_meta(scene_hash=cornell.file_hash, scene="cornell"))
    for name, model in (("toy", toy), ("shipped", models_dir() / "cornell.onnx")):
        out = tmp_path / name
        assert main(["render", "--scene", "cornell", "--model", str(model), "--res", res, "--out", str(out)]) == 0
        neural = read_exr(out / "neural.exr")
        assert neural.shape == (h, w, 3) and np.all(np.isfinite(neural))
        if name == "toy":
            np.testing.assert_allclose(neural, 2 * read_exr(out / "direct.exr"), rtol=1e-6)
