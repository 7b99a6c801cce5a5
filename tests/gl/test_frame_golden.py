"""The shipped models' outputs on fixed GL frames are bit-identical to recorded hashes: the frame's buffers, its
conditioning and the neural pass (graph and lean path, the GI image and the composited frame) feed the network
exactly the same numbers after any refactoring of how they are made. Hashes recorded on llvmpipe (the CI's GL); a
driver whose float arithmetic differs skips rather than fails (``DIVIEWER_GOLDEN=0``)."""

from __future__ import annotations

import hashlib
import os

import numpy as np
import pytest

pytest.importorskip("onnx")

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
    from diviewer.runtime import NeuralGI
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
            neural, area = model_pass(ctx, scene, renderer, net, config, None)  # `diviewer render`'s
            try:
                out[f"render/{k}"] = _digest(neural.image())
            finally:
                neural.release()
                if area is not None:
                    area.release()
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
