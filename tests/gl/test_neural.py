"""The neural GI pass at a GI resolution below the render's: downsampled inputs, joint bilateral upsample."""

from __future__ import annotations

import hashlib
import os

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.contract.runtime import NeuralGI
from scenes import facing_plane

pytest.importorskip("onnx")

W, H, F = 64, 48, 4  # render size and its ratio to the GI resolution
ALBEDO = 0.5
SUN = {"name": "sun", "type": "directional", "direction": [0.6, -0.3, -0.75], "irradiance": 3.0}
BULB = {"name": "bulb", "type": "point", "position": [0.8, 0.3, -0.5], "intensity": 5.0}


def _pass(ctx, tmp_path, gi=(W // F, H // F), scene=None, direct_samples: int = 1, **settings):
    """A renderer at W x H with a NeuralPass at ``gi`` of a model that returns twice its direct input, so that
    its indirect light (output - direct) is the direct light it was given."""
    from onnx_models import base_meta, direct_times

    from diviewer.gl.neural import GISettings, NeuralPass
    from diviewer.gl.renderer import Renderer

    scene = scene or facing_plane()
    meta = dict(base_meta(scene_hash=scene.file_hash), multiple=4, resolution=[W, H], direct_samples=direct_samples)
    model = NeuralGI(direct_times(tmp_path / "m.onnx", factor=2.0, meta=meta), scene=scene)
    renderer = Renderer(ctx, scene, W, H)
    return renderer, NeuralPass(ctx, renderer, model, gi, GISettings(**settings))


def _nearest(gi_h: int, gi_w: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns (rows top first) of the full-resolution pixels the nearest downsample gives the GI
    texels (rows top first): GL's texel (i, j), rows bottom first, takes pixel floor((i + 0.5) * F)."""
    bottom_first = ((np.arange(gi_h) + 0.5) * (H / gi_h)).astype(int)
    return (H - 1 - bottom_first)[::-1], ((np.arange(gi_w) + 0.5) * (W / gi_w)).astype(int)


def _write(renderer, depth, normal, irradiance) -> None:
    """Synthetic full-resolution buffers (rows bottom first, as GL's): the direct light is albedo x irradiance,
    so the GI texels' demodulated indirect light is ``irradiance`` sampled at the GI resolution."""
    albedo = np.full((H, W, 4), ALBEDO, np.float32)
    direct = albedo * np.asarray(irradiance, np.float32)[..., None]
    n4 = np.concatenate([normal, np.zeros((H, W, 1))], axis=-1)
    for name, a in (("depth", depth[..., None]), ("normal", n4), ("albedo", albedo), ("direct", direct),
                    ("emission", np.zeros((H, W, 4)))):
        renderer.textures[name].write(np.ascontiguousarray(a, dtype="f4").tobytes())


def _indirect(ctx, neural) -> np.ndarray:
    """The upsampled indirect light (albedo x irradiance), (H, W, 3), rows bottom first."""
    neural.run()
    tex = neural.composite(indirect_only=True)
    return np.frombuffer(tex.read(), np.float16).reshape(H, W, 4)[..., :3].astype(np.float32)


def _edge_case(ctx, tmp_path, which: str) -> None:
    renderer, neural = _pass(ctx, tmp_path)
    try:
        x = np.arange(W)[None, :].repeat(H, 0)
        right = x >= 30  # not on a GI texel boundary (every 4 pixels)
        depth = np.where(right, 2.0, 1.0) if which == "depth" else np.full((H, W), 1.5)
        normal = np.zeros((H, W, 3))
        normal[..., 2] = 1.0
        if which == "normal":
            normal[right] = (1.0, 0.0, 0.0)
        irradiance = np.where(right, 3.0, 1.0)
        _write(renderer, depth, normal, irradiance)
        got = _indirect(ctx, neural)[..., 0]
        expected = ALBEDO * irradiance
        # No bleeding across the edge: every pixel gets its own side's light, right up to the edge.
        np.testing.assert_allclose(got, expected, rtol=2e-3)
        # The GI grid itself straddles the edge: GI column 7 (pixels 28-31) sampled pixel 30, the right side,
        # so a bilinear upsample would have lit pixels 26-29 with the right side's light.
        assert neural.packed[0, 0, 7, 7] == pytest.approx(ALBEDO * 3.0)
    finally:
        neural.release()
        renderer.release()


@pytest.mark.parametrize("which", ["depth", "normal"])
def test_joint_bilateral_upsample_keeps_an_edge(ctx, tmp_path, which):
    """An edge in depth or in normals between two differently lit surfaces stays sharp at full resolution."""
    _edge_case(ctx, tmp_path, which)


def test_joint_bilateral_upsample_keeps_a_constant_constant(ctx, tmp_path):
    """Constant indirect light on a bumpy surface (random depths and normals) stays exactly constant."""
    renderer, neural = _pass(ctx, tmp_path)
    try:
        rng = np.random.default_rng(0)
        normal = rng.normal(size=(H, W, 3)) + (0.0, 0.0, 2.0)
        normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
        _write(renderer, rng.uniform(1.0, 3.0, (H, W)), normal, np.full((H, W), 0.7))
        got = _indirect(ctx, neural)
        np.testing.assert_allclose(got, ALBEDO * 0.7, rtol=2e-3)
    finally:
        neural.release()
        renderer.release()


def test_final_frame_is_full_resolution_direct_plus_upsampled_indirect(ctx, tmp_path):
    """On a lit plane the composite is direct + indirect at the render's resolution, and the network
    saw its inputs at the GI resolution (nearest pixel of each texel's centre)."""
    renderer, neural = _pass(ctx, tmp_path, scene=facing_plane(lights=[BULB]))
    try:
        frame = renderer.frame()
        neural.run()
        assert neural.packed.shape == (1, H // F, W // F, 10)
        rows, cols = _nearest(H // F, W // F)
        np.testing.assert_array_equal(neural.packed[0, ..., 7:], frame["direct"][rows][:, cols])
        final = np.frombuffer(neural.composite().read(), np.float16).reshape(H, W, 4)[::-1, :, :3]
        # The model doubles the direct light, so the indirect light equals the direct light here (a plane
        # lit by a near point light, smoothly varying: the upsample interpolates it).
        lit = frame["direct"].sum(-1) > 0
        assert lit.all() and np.ptp(frame["direct"][..., 0]) > 0.2 * frame["direct"][..., 0].max()
        np.testing.assert_allclose(final[lit], 2 * frame["direct"][lit], rtol=0.05, atol=1e-3)
    finally:
        neural.release()
        renderer.release()


def test_area_downsample_averages_the_footprint(ctx, tmp_path):
    renderer, neural = _pass(ctx, tmp_path, downsample="area")
    try:
        frame = renderer.frame()
        neural.run()
        mean = frame["direct"].reshape(H // F, F, W // F, F, 3).mean(axis=(1, 3))
        np.testing.assert_allclose(neural.packed[0, ..., 7:], mean, rtol=1e-5)
    finally:
        neural.release()
        renderer.release()


def test_a_model_of_the_area_light_gets_the_footprints_mean_direct_light_and_the_centres_surface(ctx, tmp_path):
    """direct_samples > 1 on the card (`diviewer.gl.area`): the packed direct light is the mean over the texel's
    footprint, depth, normal and albedo stay the centre pixel's (as the capture the model trained on holds them)."""
    renderer, neural = _pass(ctx, tmp_path, scene=_lit_scene([SUN]), direct_samples=4)
    try:
        frame = renderer.frame()
        neural.run()
        mean = frame["direct"].reshape(H // F, F, W // F, F, 3).mean(axis=(1, 3))
        np.testing.assert_allclose(neural.packed[0, ..., 7:], mean, rtol=1e-5, atol=1e-7)
        rows, cols = _nearest(H // F, W // F)
        np.testing.assert_array_equal(neural.packed[0, ..., 1:7],
                                      np.concatenate([frame["normal"], frame["albedo"]], -1)[rows][:, cols])
        assert not np.allclose(mean, frame["direct"][rows][:, cols])  # the shadow's edge: the two differ
    finally:
        neural.release()
        renderer.release()


def _lit_scene(lights, emission=(0.0, 0.0, 0.0)):
    """The facing plane with a box in front of it that casts a shadow on it; the box may glow."""
    import dataclasses

    scene = facing_plane(distance=3.0, fov=70.0, lights=lights,
                         extra_meshes={"blocker": {"shape": "box", "size": [0.6, 0.6, 0.6]}},
                         extra_objects=[{"name": "blocker", "mesh": "blocker", "material": "occ",
                                         "position": [0.1, 0.0, -1.5]}])
    occ = dataclasses.replace(scene.materials["occ"], emission=tuple(emission))
    return dataclasses.replace(scene, materials={**scene.materials, "occ": occ})


@pytest.mark.parametrize("lights,emission,downsample", [
    ([SUN], (0, 0, 0), "nearest"), ([BULB], (0, 0, 0), "nearest"), ([SUN], (0.5, 0.25, 0.0), "nearest"),
    ([], (0.5, 0.25, 0.0), "nearest"), ([], (0, 0, 0), "nearest"), ([SUN], (0, 0, 0), "area"),
])
def test_inline_direct_light_equals_the_direct_pass(ctx, tmp_path, lights, emission, downsample):
    """With the direct pass deferred, pack and upsample compute each pixel's direct light themselves
    (direct_inline.glsl): the network's inputs and the final frame are those of the direct pass's
    target, shadows (PCF), point lights and emission included, and the direct pass never runs. A pack that averages
    each texel's footprint ("area") reads every pixel's light itself: there the deferred direct pass runs instead
    (computed once, not in pack and upsample both), with the same result."""
    scene = _lit_scene(lights, emission)
    results = []
    for direct in (True, False):
        renderer, neural = _pass(ctx, tmp_path, scene=scene, downsample=downsample)
        try:
            renderer.render(direct=direct)
            neural.run()
            final = np.frombuffer(neural.composite().read(), np.float16).reshape(H, W, 4)[..., :3]
            inline = not direct and downsample != "area"
            assert neural.inline_direct is inline and renderer.direct_pending is inline
            results.append((neural.packed.copy(), final.astype(np.float32)))
        finally:
            neural.release()
            renderer.release()
    (packed_a, final_a), (packed_b, final_b) = results
    if lights or any(emission):
        assert packed_a[..., 7:].max() > 0 and (packed_a[..., 7:].sum(-1) == 0).any()  # lit and dark texels
    np.testing.assert_allclose(packed_b, packed_a, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(final_b, final_a, rtol=2e-3, atol=1e-4)


def test_two_lights_fall_back_to_the_direct_pass(ctx, tmp_path):
    """Inline direct light handles one light; with two the deferred direct pass runs before the pack."""
    renderer, neural = _pass(ctx, tmp_path, scene=_lit_scene([SUN, BULB]))
    try:
        renderer.render(direct=False)
        assert renderer.direct_pending
        neural.run()
        assert not neural.inline_direct and not renderer.direct_pending
        rows, cols = _nearest(H // F, W // F)
        np.testing.assert_array_equal(neural.packed[0, ..., 7:], renderer.read("direct")[rows][:, cols])
    finally:
        neural.release()
        renderer.release()


def test_pipelined_inference_shows_the_previous_frame(ctx, tmp_path):
    """One frame behind: after the first frame, each run shows the prediction of the frame before it."""
    renderer, neural = _pass(ctx, tmp_path, pipelined=True)
    try:
        outs = []
        for light in (1.0, 2.0, 4.0):
            _write(renderer, np.full((H, W), 1.5), np.broadcast_to([0.0, 0.0, 1.0], (H, W, 3)),
                   np.full((H, W), light))
            neural.run()
            outs.append(float(neural.image().mean()))
        # frame 1 waits for its own (2 x 0.5 x 1); frame 2 shows frame 1's again; frame 3 shows frame 2's
        assert outs == pytest.approx([1.0, 1.0, 2.0])
        assert neural.latency_ms > 0.0
    finally:
        neural.release()
        renderer.release()


def test_any_gi_size_runs_padded_to_the_models_stride(ctx, tmp_path):
    """A GI size that is not a multiple of the model's stride (4 here) is padded and cropped back by the
    runtime: the output has the GI size, and a per-pixel model's output lands on its own pixels."""
    renderer, neural = _pass(ctx, tmp_path, gi=(10, 13))
    try:
        renderer.frame()
        neural.run()
        assert neural.image().shape == (13, 10, 3)
        np.testing.assert_allclose(neural.image(), 2.0 * neural.packed[0][..., 7:10], rtol=1e-6)
        with pytest.raises(DiviewerError, match="at least 1x1"):
            neural.model.check_size(0, 12)
    finally:
        neural.release()
        renderer.release()


# --- golden: the shipped models' outputs on fixed GL frames are bit-identical to recorded hashes -------------------
# The frame's buffers, its conditioning and the neural pass (graph and lean path, the inline direct light, `diviewer
# render`'s area-sampled pass: the GI image and the composited frame) feed the network exactly the same numbers after
# any change to how they are made. Recorded on llvmpipe (the CI's GL); another driver skips, as does
# DIVIEWER_GOLDEN=0.
GOLDEN = {
    "cornell": {
        "buffers/0": "a66b2bd053ade0f3969a04aed77f14f80734105030fa94ec96fbfed6be84f415",
        "graph/0": "d2afc823406a79ecafc86e119462ce1937ee3cb3008fdee1953f8186ddbd7f9c",
        "lean/0": "496b6873d2f78f21bab2c511b992a44d2afd8a6bc7bab453297b9c671b76b25b",
        "inline/0": "d2afc823406a79ecafc86e119462ce1937ee3cb3008fdee1953f8186ddbd7f9c",
        "render/0": "c088c9bee9db223af72c8f5fbb68890964f87474bfca82a6243d400188ed4e4f",
        "buffers/1": "3cccb91c411224051b5609b671bdd11644c86fa08f72ec2e09c34b452a2b96d3",
        "graph/1": "c3a7902ed6238ff6100cf5b14316a344669c74a0965238fd038521eba3af0bc7",
        "lean/1": "1dc3f4151e461aa4becf017b6c3672fad7c6a0b1e6ffc19a511714f969b21818",
        "inline/1": "c3a7902ed6238ff6100cf5b14316a344669c74a0965238fd038521eba3af0bc7",
        "render/1": "23c3e1e05e975b3c28e5d212e40391b89071e961ef7928ac077c663cd8b56d4e",
    },
    "sponza": {
        "buffers/0": "2551178370742a339856e193f8318124e526f5e34d14ae90fdbf125a59d0a47f",
        "graph/0": "d10ffd99b882232b143bc70d685e565627fa4e8d372415097ca84b11fcb309fe",
        "lean/0": "61920d2b611721f48cdbcd2b31d6d772f661acec1259f49581dd6b57da667bfd",
        "inline/0": "d10ffd99b882232b143bc70d685e565627fa4e8d372415097ca84b11fcb309fe",
        "render/0": "9f5c585adf2a106d511fa24ca0ab04927d62b736a70e16d978f8e672dae55d90",
        "buffers/1": "29983a80d2698fa6c1a27b80cacef6e7170b70002d64d5f7ea9362eae85bcb0f",
        "graph/1": "049c094bac544bcf5eafafc6d71969fa70026e119a84c32acd0c7740d743ce91",
        "lean/1": "b76a4684400002fe75a2e059c795df8eaede50a7d2803d4b7b63d3ae6b132d7f",
        "inline/1": "049c094bac544bcf5eafafc6d71969fa70026e119a84c32acd0c7740d743ce91",
        "render/1": "7163bdc5e881113068e2fbbfd1cfff17923cf36086cabf643b051be9e3e1ecae",
    },
}
"""(scene, path) -> sha256 of the GI image and of the composited frame at 64 x 64 (and `diviewer render`'s GI image), the scene's default configuration
and its test configuration 3."""


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def frame_hashes(ctx, name: str) -> dict[str, str]:
    from diviewer.gl.neural import GISettings, NeuralPass
    from diviewer.gl.renderer import Renderer
    from diviewer.render import model_pass
    from diviewer.contract.runtime import NeuralGI
    from diviewer.scene import load_scene, sample_config

    scene = load_scene(name)
    net = NeuralGI(f"assets/models/{name}.onnx", scene=scene)
    point = NeuralGI(f"assets/models/{name}.onnx", scene=scene)
    point.direct_samples = 1  # read as a model of the direct light at each pixel's centre: the inline direct light
    renderer = Renderer(ctx, scene, 64, 64)
    passes = {p: NeuralPass(ctx, renderer, net, None, GISettings(lean=p == "lean")) for p in ("graph", "lean")}
    passes["inline"] = NeuralPass(ctx, renderer, point, None, GISettings(lean=False))
    out = {}
    try:
        for k, config in enumerate((scene.default, sample_config(scene, 3, "test"))):
            out[f"buffers/{k}"] = _digest(*renderer.frame(config).values())
            for path, p in passes.items():
                renderer.render(config, direct=path != "inline")
                p.run(**p.inputs_for(scene, config))
                assert p.inline_direct == (path == "inline")
                final = np.frombuffer(p.composite().read(), np.float16)
                out[f"{path}/{k}"] = _digest(p.image(), final)
            neural = model_pass(ctx, scene, renderer, net, config)  # `diviewer render`'s
            try:
                out[f"render/{k}"] = _digest(neural.image())
            finally:
                neural.release()
    finally:
        for p in passes.values():
            p.release()
        renderer.release()
    return out


@pytest.mark.skipif(os.environ.get("DIVIEWER_GOLDEN") == "0", reason="golden hashes switched off")
@pytest.mark.parametrize("name", ["cornell", "sponza"])
def test_shipped_models_bit_identical(ctx, name):
    if "llvmpipe" not in ctx.info.get("GL_RENDERER", "").lower():
        pytest.skip("hashes recorded on llvmpipe")
    assert frame_hashes(ctx, name) == GOLDEN[name]
