"""diviewer.contract.lean: the generator cut out of a self-contained model, and the numpy twins of the per-pixel work."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diviewer.contract.lean import LeanUnsupported, albedo_floor, generator_subgraph, lean_model, world_planes_np
from diviewer.contract.runtime import NeuralGI

onnx = pytest.importorskip("onnx")


@pytest.mark.parametrize("name", ["cornell", "sponza"])
def test_the_cut_is_the_generator_and_the_floor_the_trainers(name):
    from diviewer.data.scales import ALBEDO_FLOOR
    from diviewer.contract.encoding import Encoding
    from diviewer.contract.runtime import read_metadata

    model = onnx.load(f"assets/models/{name}.onnx")
    sub = generator_subgraph(model)
    assert [i.name for i in sub.graph.input] == ["encoded"] and [o.name for o in sub.graph.output] == ["raw"]
    planes = Encoding.from_dict(read_metadata(f"assets/models/{name}.onnx")["encoding"]).input_planes
    assert sub.graph.input[0].type.tensor_type.shape.dim[1].dim_value == planes
    convs = sum(n.op_type in ("Conv", "ConvTranspose") for n in model.graph.node)
    assert sum(n.op_type in ("Conv", "ConvTranspose") for n in sub.graph.node) == convs
    assert albedo_floor(model) == pytest.approx(2 * ALBEDO_FLOOR - 1, abs=1e-7)


def test_a_graph_without_a_generator_runs_unremarked(tmp_path):
    from onnx_models import direct_times

    with pytest.raises(LeanUnsupported, match="no generator"):
        generator_subgraph(onnx.load(str(direct_times(tmp_path / "m.onnx"))))
    assert lean_model(NeuralGI(direct_times(tmp_path / "m.onnx"))) == (None, "")


def test_a_generator_that_cannot_be_cut_says_why(tmp_path):
    """An encoding-1 generator (bench's untrained U-Net): no lean path, and the reason names the file."""
    from diviewer.bench.onnx_tools import untrained_generator
    from scenes import facing_plane

    path = tmp_path / "u.onnx"
    onnx.save(untrained_generator(8, 2, facing_plane(), 16), str(path))
    lean, why = lean_model(NeuralGI(path))
    assert lean is None and why == "u.onnx: no lean path (encoding version 1 (the cut is made for versions 2 to 4)); " \
        "the graph runs"


def test_the_lean_model_is_cut_once_per_loaded_model():
    graph = NeuralGI("assets/models/cornell.onnx")
    first = lean_model(graph)
    assert lean_model(graph) is first and first[0] is not None
    assert lean_model(first[0]) == (first[0], "")


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**16), w=st.integers(1, 9), h=st.integers(1, 9))
def test_world_planes_np_equals_trainings(seed, w, h):
    torch = pytest.importorskip("torch")
    from diviewer.scene.camera import camera_params
    from diviewer.train.world import world_planes

    rng = np.random.default_rng(seed)
    depth = rng.uniform(-1, 8, (1, 1, h, w)).astype(np.float32)
    normal = rng.uniform(-1.5, 1.5, (1, 3, h, w)).astype(np.float32)
    cam = camera_params(rng.uniform(-3, 3, 3), (0, 0, 0), (0, 1, 0), 50.0, w, h)[None].astype(np.float32)
    center, half = (0.1, 0.5, -0.2), (2.0, 1.5, 3.0)
    want = world_planes(*(torch.from_numpy(a) for a in (depth, normal, cam)), center, half).numpy()
    np.testing.assert_allclose(world_planes_np(depth, normal, cam, center, half), want, atol=1e-6)
