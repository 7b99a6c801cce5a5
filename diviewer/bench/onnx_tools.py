"""ONNX models for the benchmark without torch: untrained generators (the cost curve of K), their FLOP count,
fp16 <-> fp32 conversion of exported models, and int8 static quantisation (onnxruntime.quantization).

The untrained generator mirrors diviewer.train.networks.UnetGenerator with its defaults (the paper's):
Conv 4x4/2 encoders with widths K, 2K, 4K, 8K, 8K, ..., LeakyReLU(0.2) except on the bottleneck;
ReLU + ConvTranspose 4x4/2 decoders, the skip concatenated first, tanh last. Batch norm in eval mode is
an affine map that onnxruntime folds into the convolution, so it is a bias here; dropout is absent at
inference. Around the network the graph does what an exported model does at the same cost order:
NHWC -> NCHW, the generator, an elementwise decode and the direct light added back (``indirect`` target).
The elementwise encoding of the inputs is left out: it is tens of operations per pixel against the
generator's hundreds of thousands (see ``generator_flops``).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from diviewer.contract.encoding import INPUT_CHANNEL_COUNT, INPUT_CHANNELS, OUTPUT_CHANNELS, input_channel_slices
from diviewer.errors import DiviewerError, missing_extra
from diviewer.contract.runtime import (CAMERA_NAME, INPUT_NAME, LIGHT_NAME, LIGHT_SCALE_NAME, META_KEY, MODEL_FORMAT, OUTPUT_NAME,
                              model_edge_guard)
from diviewer.contract.weights import weights_to_float32

OPSET = 17
UPSAMPLE_MACS = {"transpose": 4, "resize": 9}
"""Multiply-adds per output pixel and (input, output) channel pair of a decoder's x2 upsampling:
ConvTranspose 4x4/2 touches each output pixel with 2x2 of its 16 taps; nearest x2 + Conv 3x3 with 9."""


def _onnx():
    try:
        import onnx
    except ImportError as exc:
        raise missing_extra("onnx", "bench") from exc
    return onnx


def widths(K: int, levels: int) -> list[int]:
    """Encoder output widths of the U-Net: K * min(2**i, 8)."""
    return [K * min(2 ** i, 8) for i in range(levels)]


def network_inputs(card: dict) -> int:
    """The planes a model card's generator takes into its first layer: its encoding's inputs (the buffers, the
    world planes, the lights' planes) and the Fourier features of the world position (``world_frequencies``)."""
    from diviewer.contract.encoding import Encoding

    enc = card.get("encoding")
    base = Encoding.from_dict(enc).input_planes if enc else INPUT_CHANNEL_COUNT
    return base + 6 * int(card.get("world_frequencies") or 0)


def generator_flops(K: int, levels: int, width: int, height: int, in_channels: int = INPUT_CHANNEL_COUNT,
                    out_channels: int = OUTPUT_CHANNELS, upsample: str = "transpose") -> dict:
    """FLOPs of one generator frame: 2 x the multiply-adds of its convolutions (elementwise layers not counted).

    Encoder i (output at 1/2^(i+1)): out_px * c_out * c_in * 16. Decoder k (output at 1/2^(levels-1-k)):
    transpose: out_px * c_in * c_out * 4; resize: out_px * c_in * c_out * 9; shuffle (Conv 3x3 to 4 c_out
    at the input resolution): in_px * c_in * 4 c_out * 9.

    Returns:
        ``{"flops": int, "macs": int, "layers": [(name, macs), ...]}``.
    """
    if width % 2 ** levels or height % 2 ** levels:
        raise ValueError(f"{width}x{height} is not a multiple of 2**{levels}")
    w = widths(K, levels)
    layers = []
    for i in range(levels):
        c_in = in_channels if i == 0 else w[i - 1]
        px = (width >> (i + 1)) * (height >> (i + 1))
        layers.append((f"down{i}", px * w[i] * c_in * 16))
    for k in range(levels):
        c_in = w[levels - 1] if k == 0 else 2 * w[levels - 1 - k]
        c_out = out_channels if k == levels - 1 else w[levels - 2 - k]
        out_px = (width >> (levels - 1 - k)) * (height >> (levels - 1 - k))
        if upsample == "shuffle":
            macs = out_px // 4 * c_in * 4 * c_out * 9
        elif upsample in UPSAMPLE_MACS:
            macs = out_px * c_in * c_out * UPSAMPLE_MACS[upsample]
        else:
            raise ValueError(f"unknown upsample {upsample!r}")
        layers.append((f"up{k}", macs))
    macs = sum(m for _, m in layers)
    return {"flops": 2 * macs, "macs": macs, "layers": layers}


def untrained_generator(K: int, levels: int, scene, resolution: int, fp16: bool = False, seed: int = 0):
    """An untrained U-Net (random weights) as an ONNX model under the runtime's contract, flagged ``untrained``."""
    onnx = _onnx()
    from onnx import TensorProto, helper, numpy_helper

    rng = np.random.default_rng(seed)
    dtype = np.float16 if fp16 else np.float32
    inits, nodes = [], []

    def const(name, arr, dt=dtype):
        inits.append(numpy_helper.from_array(np.asarray(arr, dtype=dt), name))
        return name

    def weight(name, shape):  # pix2pix's init: N(0, 0.02)
        return const(name, rng.normal(0.0, 0.02, shape))

    direct = input_channel_slices()["direct"]
    const("d_start", [direct.start], np.int64), const("d_end", [direct.stop], np.int64)
    const("axis3", [3], np.int64)
    nodes.append(helper.make_node("Slice", [INPUT_NAME, "d_start", "d_end", "axis3"], ["direct"]))
    nodes.append(helper.make_node("Transpose", [INPUT_NAME], ["nchw"], perm=[0, 3, 1, 2]))
    x = "nchw"
    if fp16:
        nodes.append(helper.make_node("Cast", [x], ["nchw_h"], to=TensorProto.FLOAT16))
        x = "nchw_h"
    w = widths(K, levels)
    skips = []
    for i in range(levels):
        c_in = INPUT_CHANNEL_COUNT if i == 0 else w[i - 1]
        nodes.append(helper.make_node("Conv", [x, weight(f"down{i}.w", (w[i], c_in, 4, 4)), weight(f"down{i}.b", (w[i],))],
                                      [f"down{i}"], kernel_shape=[4, 4], strides=[2, 2], pads=[1, 1, 1, 1]))
        x = f"down{i}"
        if i < levels - 1:
            nodes.append(helper.make_node("LeakyRelu", [x], [f"down{i}.act"], alpha=0.2))
            x = f"down{i}.act"
        skips.append(x)
    x = skips.pop()
    for k in range(levels):
        if k > 0:
            nodes.append(helper.make_node("Concat", [skips.pop(), x], [f"cat{k}"], axis=1))
            x = f"cat{k}"
        c_in = w[levels - 1] if k == 0 else 2 * w[levels - 1 - k]
        c_out = OUTPUT_CHANNELS if k == levels - 1 else w[levels - 2 - k]
        nodes.append(helper.make_node("Relu", [x], [f"up{k}.relu"]))
        nodes.append(helper.make_node("ConvTranspose", [f"up{k}.relu", weight(f"up{k}.w", (c_in, c_out, 4, 4)),
                                                        weight(f"up{k}.b", (c_out,))],
                                      [f"up{k}"], kernel_shape=[4, 4], strides=[2, 2], pads=[1, 1, 1, 1]))
        x = f"up{k}"
    nodes.append(helper.make_node("Tanh", [x], ["encoded"]))
    x = "encoded"
    if fp16:
        nodes.append(helper.make_node("Cast", [x], ["encoded_f"], to=TensorProto.FLOAT))
        x = "encoded_f"
    nodes.append(helper.make_node("Transpose", [x], ["encoded_nhwc"], perm=[0, 2, 3, 1]))
    nodes.append(helper.make_node("Mul", ["encoded_nhwc", const("decode_scale", 0.1, np.float32)], ["indirect"]))
    nodes.append(helper.make_node("Add", ["direct", "indirect"], [OUTPUT_NAME]))
    inp = helper.make_tensor_value_info(INPUT_NAME, TensorProto.FLOAT, ["N", "H", "W", INPUT_CHANNEL_COUNT])
    out = helper.make_tensor_value_info(OUTPUT_NAME, TensorProto.FLOAT, ["N", "H", "W", OUTPUT_CHANNELS])
    model = helper.make_model(helper.make_graph(nodes, f"untrained_unet_K{K}", [inp], [out], inits),
                              opset_imports=[helper.make_opsetid("", OPSET)])
    model.ir_version = 8
    meta = {"format": MODEL_FORMAT, "kind": "untrained", "input": INPUT_NAME, "output": OUTPUT_NAME, "layout": "NHWC",
            "channels": [list(c) for c in INPUT_CHANNELS], "resolution": [resolution, resolution],
            "multiple": 2 ** levels, "K": K, "levels": levels, "upsample": "transpose", "target": "indirect",
            "encoding": {"version": 1}, "precision": "fp16" if fp16 else "fp32",
            "scene": scene.name, "scene_hash": scene.file_hash, "dataset_hash": "untrained (random weights)",
            "description": "untrained U-Net for timing only (random weights, no accuracy)"}
    set_meta(model, meta)
    onnx.checker.check_model(model)
    return model


def get_meta(model) -> dict:
    props = {p.key: p.value for p in model.metadata_props}
    if META_KEY not in props:
        raise DiviewerError("the model has no diviewer metadata", field=META_KEY)
    return json.loads(props[META_KEY])


def set_meta(model, meta: dict) -> None:
    """Replace the model's diviewer metadata, keeping its other properties."""
    keep = [(p.key, p.value) for p in model.metadata_props if p.key != META_KEY]
    del model.metadata_props[:]
    for k, v in keep + [(META_KEY, json.dumps(meta, sort_keys=True))]:
        entry = model.metadata_props.add()
        entry.key, entry.value = k, v


def to_fp32(model):
    """An fp16 export as fp32: float16 weights, constants, casts and value types become float32 (same graph)."""
    onnx = _onnx()
    from onnx import TensorProto, numpy_helper

    m = onnx.ModelProto()
    m.CopyFrom(model)
    g = m.graph
    for i, init in enumerate(g.initializer):
        if init.data_type == TensorProto.FLOAT16:
            g.initializer[i].CopyFrom(numpy_helper.from_array(numpy_helper.to_array(init).astype(np.float32), init.name))
    for node in g.node:
        for a in node.attribute:
            if node.op_type == "Cast" and a.name == "to" and a.i == TensorProto.FLOAT16:
                a.i = TensorProto.FLOAT
            if a.type == onnx.AttributeProto.TENSOR and a.t.data_type == TensorProto.FLOAT16:
                a.t.CopyFrom(numpy_helper.from_array(numpy_helper.to_array(a.t).astype(np.float32), a.t.name))
    for vi in list(g.value_info) + list(g.input) + list(g.output):
        if vi.type.tensor_type.elem_type == TensorProto.FLOAT16:
            vi.type.tensor_type.elem_type = TensorProto.FLOAT
    meta = get_meta(m)
    set_meta(m, {**meta, "precision": "fp32", "converted_from": meta.get("precision")})
    return m


FP16_OPS = ("Conv", "ConvTranspose", "Relu", "LeakyRelu", "Tanh", "Concat", "BatchNormalization",
            "InstanceNormalization", "Resize", "DepthToSpace", "Identity", "Dropout")
"""The generator's operators, converted to fp16; the encoding and decoding stay fp32 (as ``export --fp16``)."""


GENERATOR_PREFIX = "/netG/"
"""The exporter's name prefix of the generator's nodes (``LeanGI.netG``)."""


def _generator_to_fp16(model):
    """The generator of a diviewer export (its nodes named ``/netG/...``) in float16, as ``export --fp16`` writes
    it: its float weights halved, one Cast to float16 on each tensor it takes from the encoding, one Cast back on
    each it gives to the decoding; the rest of the graph (the encoding, its NaN guard's If) untouched. None for
    a graph without such nodes."""
    onnx = _onnx()
    from onnx import TensorProto, helper, numpy_helper

    m = onnx.ModelProto()
    m.CopyFrom(model)
    g = m.graph
    net = [n for n in g.node if n.name.startswith(GENERATOR_PREFIX)]
    if not net:
        return None
    inside = {o for n in net for o in n.output}
    inits = {i.name: i for i in g.initializer}
    users = {}
    for n in g.node:
        for i in n.input:
            users.setdefault(i, set()).add(n.name.startswith(GENERATOR_PREFIX))
    for name, init in inits.items():  # weights only the generator reads
        if init.data_type == TensorProto.FLOAT and users.get(name) == {True}:
            init.CopyFrom(numpy_helper.from_array(numpy_helper.to_array(init).astype(np.float16), name))
    casts, renamed = [], {}
    for n in net:
        for k, i in enumerate(n.input):
            if i and i not in inside and i not in inits:  # an encoded tensor: into float16 once
                if i not in renamed:
                    renamed[i] = f"{i}_fp16"
                    casts.append(helper.make_node("Cast", [i], [renamed[i]], name=f"{i}_to_fp16", to=TensorProto.FLOAT16))
                n.input[k] = renamed[i]
    outside = {i for n in g.node if not n.name.startswith(GENERATOR_PREFIX) for i in n.input} | {o.name for o in g.output}
    for n in net:
        for k, o in enumerate(n.output):
            if o in outside:  # back to float32 for the decoding, under the name it reads
                n.output[k] = f"{o}_fp16"
                casts.append(helper.make_node("Cast", [n.output[k]], [o], name=f"{o}_to_fp32", to=TensorProto.FLOAT))
    keep = [vi for vi in g.value_info if vi.name not in inside]
    del g.value_info[:]
    g.value_info.extend(keep)
    # each Cast right after the node that makes its input (at the start for a graph input): still in order
    after: dict[str, list] = {}
    for c in casts:
        after.setdefault(c.input[0], []).append(c)
    nodes = [c for i in g.input for c in after.pop(i.name, [])]
    for n in g.node:
        nodes += [n] + [c for o in n.output for c in after.pop(o, [])]
    del g.node[:]
    g.node.extend(nodes)
    return m


def to_fp16(model):
    """An fp32 export as fp16: a diviewer export's generator in fp16 (``_generator_to_fp16``), else
    onnxruntime.transformers.float16 with the non-generator operators kept fp32."""
    model = weights_to_float32(model)  # an fp32 export with float16-stored weights: its float32 graph first
    lean = _generator_to_fp16(model)
    if lean is not None:
        meta = get_meta(lean)
        set_meta(lean, {**meta, "precision": "fp16", "converted_from": meta.get("precision")})
        return lean
    from onnxruntime.transformers.float16 import convert_float_to_float16

    blocked = sorted({n.op_type for n in model.graph.node} - set(FP16_OPS))
    m = convert_float_to_float16(model, keep_io_types=True, op_block_list=blocked)
    meta = get_meta(m)
    set_meta(m, {**meta, "precision": "fp16", "converted_from": meta.get("precision")})
    return m


CALIB_PERCENTILE = 99.5
"""int8 activation ranges: this percentile of each activation over the calibration frames. The shipped cornell model
on its compact evaluation set, int8 against fp32, tone-mapped PSNR per split: min-max -4.9 to -8.6 dB; percentile
99.999 -3.9 to -7.2, 99.99 -2.9 to -5.6, 99.9 -1.9 to -4.1, 99.5 -0.3 to -1.9, 99.0 -0.5 to -2.8
(the int8 calibration sweep, docs/experiments.md)."""


def quantize_int8(fp32_path: Path, out_path: Path, calibration: list[tuple],
                  percentile: float | None = CALIB_PERCENTILE) -> Path:
    """Static int8 quantisation (QDQ, per-channel weights) of the convolutions, calibrated on ``calibration``
    ((1, H, W, 10) buffers, padded to the model's stride as the runtime pads them, each with its frame's
    `diviewer.contract.conditioning.Conditioning` under the model's encoding: its light scale, camera and lights,
    fed where it has them); the encoding and decoding stay float. Each activation's range is its ``percentile``
    over the calibration frames (None: its extremes) (CALIB_PERCENTILE)."""
    onnx = _onnx()
    from onnxruntime.quantization import (CalibrationDataReader, CalibrationMethod, QuantFormat, QuantType,
                                          quantize_static)

    from diviewer.contract.conditioning import stacked
    from diviewer.contract.padding import pad_camera_params, pad_nhwc

    # float16-stored weights (export --half-weights) folded back: the quantiser reads each weight as an initializer
    plain = weights_to_float32(onnx.load(str(fp32_path)))
    meta = get_meta(plain)
    multiple = int(meta.get("multiple", 1))  # padded as the runtime pads (a 228x128 model runs at 256x128)
    guard = model_edge_guard(meta)  # and its column guard (a 128x128 frame of a crop-trained model at 256x128)

    class Reader(CalibrationDataReader):
        def __init__(self):
            self.it = iter(calibration)

        def get_next(self):
            item = next(self.it, None)
            if item is None:
                return None
            n, h, w = item[0].shape[:3]
            feed = {INPUT_NAME: pad_nhwc(item[0], multiple, guard)}
            scale, camera, lights = stacked([item[1]])
            if camera is not None:  # the camera of the padded frame, as the runtime shifts it
                camera = pad_camera_params(camera, w, h, multiple, guard)
            for name, value in ((LIGHT_SCALE_NAME, scale), (CAMERA_NAME, camera), (LIGHT_NAME, lights)):
                if value is not None:
                    feed[name] = np.repeat(value, n, axis=0)
            return feed

    root = logging.getLogger()
    level = root.level
    root.setLevel(logging.ERROR)  # quantize_static's advice to pre-process, at every call
    try:
        quantize_static(plain, str(out_path), Reader(), quant_format=QuantFormat.QDQ,
                        op_types_to_quantize=["Conv", "ConvTranspose"], per_channel=True,
                        activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8,
                        **({} if percentile is None else {"calibrate_method": CalibrationMethod.Percentile,
                                                          "extra_options": {"CalibPercentile": float(percentile)}}))
    finally:
        root.setLevel(level)
    m = onnx.load(str(out_path))
    set_meta(m, {**meta, "precision": "int8", "quantization": {"format": "QDQ", "ops": ["Conv", "ConvTranspose"],
                                                               "calibration_frames": len(calibration),
                                                               "calibration": "min-max" if percentile is None
                                                               else f"percentile {percentile:g}"}})
    onnx.save(m, str(out_path))
    return out_path
