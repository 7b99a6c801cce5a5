"""The lean path (the generator alone in onnxruntime, the encoding in pack.glsl, the decoding in decode.glsl) gives the
self-contained graph's radiance on GL frames of both shipped scenes, with the shipped models."""

from __future__ import annotations

import numpy as np
import pytest

from diviewer.contract.lean import lean_model
from diviewer.contract.runtime import NeuralGI

pytest.importorskip("onnx")

TOLERANCE = 1e-4
"""Largest |lean - graph| over the frame's peak radiance (export's fp16 tolerance is 1e-2; measured on llvmpipe:
2e-6 on the frames, 4e-7 on the broken buffers; the margin is for GPUs' approximate exp and log)."""

SIZES = ((48, 48, (48, 48)), (64, 48, (40, 30)))  # render size, GI size (the second pads to the stride)


@pytest.fixture(scope="module", params=["cornell", "sponza"])
def models(request):
    from diviewer.scene import load_scene

    scene = load_scene(request.param)
    graph = NeuralGI(f"assets/models/{request.param}.onnx", scene=scene)
    lean, why = lean_model(graph)
    assert lean is not None, why
    return scene, graph, lean


def _frames(ctx, scene, graph, lean, w, h, gi, configs, edit=None, scale=None):
    """Both paths' GI-resolution radiance and composited frames of ``configs`` (``edit(renderer)`` after each
    render: buffers written by hand; ``scale``: the light scale fed instead of the frame's)."""
    from diviewer.gl.neural import GISettings, NeuralPass
    from diviewer.gl.renderer import Renderer

    renderer = Renderer(ctx, scene, w, h)
    passes = [NeuralPass(ctx, renderer, graph, gi, GISettings(lean=lean_path)) for lean_path in (False, True)]
    assert [p.inference_path for p in passes] == ["graph", "lean"] and passes[1].model is lean
    out = []
    try:
        for config in configs:
            renderer.render(config)
            if edit is not None:
                edit(renderer)
            pair = []
            for p in passes:
                inputs = p.inputs_for(scene, config)
                if scale is not None:
                    inputs["light_scale"] = scale
                p.run(**inputs)
                final = p.composite()
                pair.append((p.image(), np.frombuffer(final.read(), np.float16).reshape(h, w, 4)[..., :3]))
            out.append(pair)
    finally:
        for p in passes:
            p.release()
        renderer.release()
    return out


def _close(a, b, tol=TOLERANCE):
    assert np.array_equal(np.isfinite(a), np.isfinite(b))
    ok = np.isfinite(a)
    peak = max(float(np.max(np.abs(a[ok]), initial=0.0)), 1e-6)
    err = float(np.max(np.abs(a[ok] - b[ok].astype(np.float32)), initial=0.0))
    assert err <= tol * peak, f"{err / peak:.3g} of the peak {peak:.3g}"


@pytest.mark.parametrize("w, h, gi", SIZES)
def test_lean_equals_graph_on_gl_frames(ctx, models, w, h, gi):
    from diviewer.scene import sample_config

    scene, graph, lean = models
    configs = [scene.default, sample_config(scene, 3, "test"), sample_config(scene, 11, "train")]
    for (img_g, fin_g), (img_l, fin_l) in _frames(ctx, scene, graph, lean, w, h, gi, configs):
        assert img_g.max() > 0.0
        _close(img_g, img_l)
        _close(fin_g.astype(np.float32), fin_l, tol=2e-3)  # half-float frames: one fp16 step on top


def test_lean_model_keeps_the_graph_checks(models):
    """The lean model is the graph model's metadata and sizes, and its generator is the bare one's operators."""
    _, graph, lean = models
    assert lean.meta is graph.meta and lean.multiple == graph.multiple and lean.edge_guard == graph.edge_guard
    assert not lean.generator_ops & {"Log", "Exp", "Clip", "IsNaN", "If", "Where", "Abs", "Div", "Transpose"}
    assert {"Conv", "Tanh"} <= lean.generator_ops
    assert [i.name for i in lean.generator.get_inputs()] == ["encoded"]
    assert lean.generator.get_inputs()[0].shape[1] == lean.enc.input_planes


EXTREMES = {
    "background": lambda r: r.textures["depth"].write(np.zeros(r.textures["depth"].size[::-1], "f4").tobytes()),
    "nan_direct": lambda r: _poke(r, "direct", np.nan),
    "inf_direct": lambda r: _poke(r, "direct", np.inf),
    "nan_normal": lambda r: _poke(r, "normal", np.nan),
    "inf_depth": lambda r: _poke(r, "depth", np.inf),
    "nan_depth": lambda r: _poke(r, "depth", np.nan),
    "nan_albedo": lambda r: _poke(r, "albedo", np.nan),
}


def _poke(renderer, name: str, value: float) -> None:
    """Every 7th texel of a buffer set to ``value`` (the rest as rendered)."""
    tex = renderer.textures[name]
    a = np.frombuffer(tex.read(), np.float32).reshape(tex.height, tex.width, -1).copy()
    a.reshape(-1, a.shape[-1])[::7] = value
    tex.write(a.tobytes())


@pytest.mark.parametrize("case", sorted(EXTREMES))
def test_lean_sanitises_like_the_graph(ctx, models, case):
    scene, graph, lean = models
    (img_g, _), (img_l, _) = _frames(ctx, scene, graph, lean, 32, 32, (32, 32), [scene.default], EXTREMES[case])[0]
    _close(img_g, img_l)


@pytest.mark.parametrize("scale", [0.0, 1e30])
def test_lean_at_zero_and_huge_light(ctx, models, scale):
    """A light scale of 0 (no light: the network's input and output 0) and of 1e30, as the graph."""
    scene, graph, lean = models
    (img_g, _), (img_l, _) = _frames(ctx, scene, graph, lean, 32, 32, (32, 32), [scene.default], scale=scale)[0]
    _close(img_g, img_l)


def test_a_generator_without_a_lean_path_runs_its_graph_and_says_why(ctx, tmp_path):
    """An encoding-1 generator (bench's untrained U-Net): the pass runs its graph, its note says why."""
    import onnx
    from scenes import facing_plane

    from diviewer.bench.onnx_tools import untrained_generator
    from diviewer.gl.neural import NeuralPass
    from diviewer.gl.renderer import Renderer

    scene = facing_plane()
    onnx.save(untrained_generator(8, 2, scene, 16), str(tmp_path / "u.onnx"))
    model = NeuralGI(tmp_path / "u.onnx", scene=scene)
    renderer = Renderer(ctx, scene, 16, 16)
    p = NeuralPass(ctx, renderer, model, (16, 16))
    try:
        assert p.inference_path == "graph" and p.model is model
        assert "no lean path" in p.path_note and "u.onnx" in p.path_note
        p.run()
        assert np.isfinite(p.image()).all()
    finally:
        p.release()
        renderer.release()
