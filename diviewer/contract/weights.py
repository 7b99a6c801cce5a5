"""How an exported model stores its weights: float32, float16 behind a Cast (``export --half-weights``), or the
convolutions' as int8 with a scale per output channel (``export --int8-weights``), and the way back for tools that
read weights as initializers. onnx only; no onnxruntime, no torch."""

from __future__ import annotations

import numpy as np

HALF_WEIGHTS_MIN_SIZE = 64
"""Weight tensors of fewer elements stay float32 in ``store_weights_half`` (biases, scales: nothing to save)."""


def store_weights_half(model) -> int:
    """Rewrite ``model`` (an onnx ModelProto) in place so that every float32 initializer of at least
    `HALF_WEIGHTS_MIN_SIZE` elements is stored as float16 and cast back to float32 by a Cast node ahead of the
    graph, under its old name (the nodes that read it are unchanged): ``export --half-weights``. onnxruntime
    folds the casts as it loads the model, so it runs the float32 graph. Returns how many were rewritten."""
    return _store(model, int8=set())[0]


def store_weights_int8(model, names: set[str] | None = None) -> int:
    """``export --int8-weights``: rewrite ``model`` in place so that the weight of every convolution but the
    first and the last (`int8_weight_names`) is stored as int8, symmetric, with one float32 scale per output
    channel (its largest |w| maps to 127), and rebuilt ahead of the graph under its old name by a Cast to float32
    and a Mul by the scales; every other float32 initializer of at least `HALF_WEIGHTS_MIN_SIZE` elements, the two
    end layers' weights among them, is stored as float16 as `store_weights_half` stores it. onnxruntime folds
    both as it loads the model, so it runs the float32 graph, on weights rounded to 1/254 of their channel's
    range. The ends stay float16: the first layer reads the raw world position and normal, and int8 there cost
    cornell's 16:9 frames 0.02 of tone-mapped SSIM (docs/training.md). ``names``: other weights to store as int8
    (an experiment's). Returns how many were stored as int8."""
    return _store(model, int8=int8_weight_names(model) if names is None else names)[1]


def int8_weight_names(model) -> set[str]:
    """The weights ``--int8-weights`` stores as int8: those of every Conv and ConvTranspose (their second input,
    an initializer) but the first and the last in the graph's order."""
    inits = {i.name for i in model.graph.initializer}
    names = [n.input[1] for n in model.graph.node
             if n.op_type in ("Conv", "ConvTranspose") and len(n.input) > 1 and n.input[1] in inits]
    return set(names[1:-1])


def _int8_channels(w: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric int8 of ``w`` with one scale per index of ``axis`` (its output channels), shaped to broadcast."""
    others = tuple(i for i in range(w.ndim) if i != axis)
    scale = (np.abs(w).max(axis=others, keepdims=True) / 127.0).astype(np.float32)
    scale[scale == 0] = 1.0  # an all-zero channel stays zero
    return np.clip(np.rint(w / scale), -127, 127).astype(np.int8), scale


def _store(model, int8: set[str]) -> tuple[int, int]:
    """`store_weights_half` and `store_weights_int8`: ``int8`` names the weights stored as int8; (float16 count,
    int8 count)."""
    from onnx import TensorProto, helper, numpy_helper

    graph = model.graph
    transposed = {n.input[1] for n in graph.node if n.op_type == "ConvTranspose" and len(n.input) > 1}
    kept, ahead, halves, eights = [], [], 0, 0
    for init in graph.initializer:
        if init.name in int8:  # Conv weights are (out, in, kh, kw); ConvTranspose's (in, out, kh, kw)
            q, scale = _int8_channels(numpy_helper.to_array(init), 1 if init.name in transposed else 0)
            kept += [numpy_helper.from_array(q, f"{init.name}.int8"),
                     numpy_helper.from_array(scale, f"{init.name}.scale")]
            ahead += [helper.make_node("Cast", [f"{init.name}.int8"], [f"{init.name}.int8_fp32"], to=TensorProto.FLOAT,
                                       name=f"{init.name}.to_fp32"),
                      helper.make_node("Mul", [f"{init.name}.int8_fp32", f"{init.name}.scale"], [init.name],
                                       name=f"{init.name}.scaled")]
            eights += 1
        elif init.data_type == TensorProto.FLOAT and int(np.prod(init.dims)) >= HALF_WEIGHTS_MIN_SIZE:
            half = numpy_helper.from_array(numpy_helper.to_array(init).astype(np.float16), f"{init.name}.fp16")
            kept.append(half)
            ahead.append(helper.make_node("Cast", [half.name], [init.name], to=TensorProto.FLOAT,
                                          name=f"{init.name}.to_fp32"))
            halves += 1
        else:
            kept.append(init)
    nodes = list(graph.node)
    del graph.initializer[:]
    graph.initializer.extend(kept)
    del graph.node[:]
    graph.node.extend(ahead + nodes)
    return halves, eights


def weights_to_float32(model):
    """A copy of ``model`` with every float16-stored weight (``store_weights_half``: a float16 initializer that
    only a Cast to float32 reads) and every int8-stored one (``store_weights_int8``: an int8 initializer cast to
    float32 and multiplied by its scales) as the float32 initializer those nodes made, and the nodes gone: the graph
    a float32 export writes, for tools that read weights as initializers (fp16 conversion, int8 quantisation).
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
    folded, drop, gone = {}, set(), set()
    cast_of = {}  # an int8 weight's Cast: its output -> the Cast node
    for n in g.node:
        if not (n.op_type == "Cast" and len(n.input) == 1 and n.input[0] in inits and readers[n.input[0]] == 1
                and any(a.name == "to" and a.i == TensorProto.FLOAT for a in n.attribute)):
            continue
        if inits[n.input[0]].data_type == TensorProto.FLOAT16:
            a = numpy_helper.to_array(inits[n.input[0]]).astype(np.float32)
            folded[n.output[0]] = numpy_helper.from_array(a, n.output[0])
            drop.add(n.input[0])
            gone.add(n.output[0])
        elif inits[n.input[0]].data_type == TensorProto.INT8 and readers.get(n.output[0]) == 1:
            cast_of[n.output[0]] = n
    for n in g.node:  # store_weights_int8's Mul of the cast int8 weight by its scales
        if n.op_type == "Mul" and len(n.input) == 2 and n.input[0] in cast_of and n.input[1] in inits:
            cast = cast_of[n.input[0]]
            a = (numpy_helper.to_array(inits[cast.input[0]]).astype(np.float32)
                 * numpy_helper.to_array(inits[n.input[1]]).astype(np.float32))
            folded[n.output[0]] = numpy_helper.from_array(a, n.output[0])
            drop.update((cast.input[0], n.input[1]))
            gone.update((cast.output[0], n.output[0]))
    if not folded:
        return m
    keep_nodes = [n for n in g.node if n.output[0] not in gone]  # outputs are unique: the graph is SSA
    keep_inits = [i for i in g.initializer if i.name not in drop] + list(folded.values())
    del g.node[:]
    g.node.extend(keep_nodes)
    del g.initializer[:]
    g.initializer.extend(keep_inits)
    return m


__all__ = ["HALF_WEIGHTS_MIN_SIZE", "int8_weight_names", "store_weights_half", "store_weights_int8",
           "weights_to_float32"]
