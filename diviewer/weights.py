"""How an exported model stores its weights: float32, or float16 behind a Cast (``export --half-weights``), and
the way back for tools that read weights as initializers. onnx only; no onnxruntime, no torch."""

from __future__ import annotations

import numpy as np

HALF_WEIGHTS_MIN_SIZE = 64
"""Weight tensors of fewer elements stay float32 in ``store_weights_half`` (biases, scales: nothing to save)."""


def store_weights_half(model) -> int:
    """Rewrite ``model`` (an onnx ModelProto) in place so that every float32 initializer of at least
    `HALF_WEIGHTS_MIN_SIZE` elements is stored as float16 and cast back to float32 by a Cast node ahead of the
    graph, under its old name (the nodes that read it are unchanged): ``export --half-weights``. onnxruntime
    folds the casts as it loads the model, so it runs the float32 graph. Returns how many were rewritten."""
    from onnx import TensorProto, helper, numpy_helper

    graph = model.graph
    kept, casts = [], []
    for init in graph.initializer:
        if init.data_type != TensorProto.FLOAT or int(np.prod(init.dims)) < HALF_WEIGHTS_MIN_SIZE:
            kept.append(init)
            continue
        half = numpy_helper.from_array(numpy_helper.to_array(init).astype(np.float16), f"{init.name}.fp16")
        kept.append(half)
        casts.append(helper.make_node("Cast", [half.name], [init.name], to=TensorProto.FLOAT,
                                      name=f"{init.name}.to_fp32"))
    nodes = list(graph.node)
    del graph.initializer[:]
    graph.initializer.extend(kept)
    del graph.node[:]
    graph.node.extend(casts + nodes)
    return len(casts)


def weights_to_float32(model):
    """A copy of ``model`` with every float16-stored weight (``store_weights_half``: a float16 initializer that
    only a Cast to float32 reads) as the float32 initializer the Cast made, and the Cast gone: the graph a
    float32 export writes, for tools that read weights as initializers (fp16 conversion, int8 quantisation).
    A model without such weights comes back as an unchanged copy."""
    import onnx
    from onnx import TensorProto, numpy_helper

    m = onnx.ModelProto()
    m.CopyFrom(model)
    g = m.graph
    inits = {i.name: i for i in g.initializer}
    readers: dict[str, int] = {}
    for n in g.node:
        for i in n.input:
            readers[i] = readers.get(i, 0) + 1
    folded, drop = {}, set()
    for n in g.node:
        if (n.op_type == "Cast" and len(n.input) == 1 and n.input[0] in inits and readers[n.input[0]] == 1
                and inits[n.input[0]].data_type == TensorProto.FLOAT16
                and any(a.name == "to" and a.i == TensorProto.FLOAT for a in n.attribute)):
            a = numpy_helper.to_array(inits[n.input[0]]).astype(np.float32)
            folded[n.output[0]] = numpy_helper.from_array(a, n.output[0])
            drop.add(n.input[0])
    if not folded:
        return m
    keep_nodes = [n for n in g.node if not (n.op_type == "Cast" and n.output[0] in folded)]
    keep_inits = [i for i in g.initializer if i.name not in drop] + list(folded.values())
    del g.node[:]
    g.node.extend(keep_nodes)
    del g.initializer[:]
    g.initializer.extend(keep_inits)
    return m


__all__ = ["HALF_WEIGHTS_MIN_SIZE", "store_weights_half", "weights_to_float32"]
