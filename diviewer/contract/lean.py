"""The lean inference path: the same network as a self-contained model, with onnxruntime running the generator alone.

A model from ``diviewer export`` is self-contained: its graph takes the raw buffers (and the light scale, camera
and lights) and computes the per-pixel work around the generator (netG) as dozens of element-wise nodes: the NaN
guard, the encoding, the world-space and light planes, the decoding and the composition with the direct light
(`diviewer.train.graph.LeanGI`). ``LeanModel`` cuts, at load time, the generator's subgraph out of that graph
(from the encoded input tensor, the first convolution's input, to netG's raw tanh output) and does the per-pixel
work elsewhere: on the GPU in ``encode.glsl`` (after ``pack.glsl``) and ``decode.glsl`` (decoding and
composition), or on the CPU in numpy (``run``, for callers with buffers in memory and for the check at load).
Shipped models keep working unchanged: the file is not rewritten.

``lean_model(net)`` returns the lean model, or None and the reason it cannot (fp16 precision, encoding version 1, a
cut that holds other operators, or a lean run that differs from the graph's on the probe frame): the caller then runs
the graph (``NeuralGI``) and says why. A graph with no generator at all (a linear baseline) runs as it is, unremarked.
"""

from __future__ import annotations

import math

import numpy as np

from diviewer.contract.encoding import Encoding
from diviewer.contract.padding import crop_slice, pad_camera_params, pad_nhwc, padded_size
from diviewer.timing import StageTimer

GENERATOR_OPS = frozenset({"Conv", "ConvTranspose", "Relu", "LeakyRelu", "Concat", "Tanh", "Cast", "Mul", "Add",
                           "Constant", "Identity", "DepthToSpace", "Resize", "Sigmoid", "Slice"})
"""Operators a generator's subgraph may hold (convolutions, activations, skip concatenations, stored-weight
casts and scales, pixel shuffles): anything else means the cut missed the generator."""

PROBE_TOLERANCE = 1e-3
"""The largest difference, relative to the probe frame's peak radiance, between the lean and the graph path at load
(measured: 0 on the shipped models, the same float32 operations; the fp16 tolerance of export is 1e-2)."""

TINY, HUGE = 1e-30, 1e38  # as the exported graph's (diviewer.train.graph): a sign and a Where without Sign/Where


def _constant(model, name: str) -> float | None:
    """The scalar value of a graph tensor made by a Constant node or held as an initializer, or None."""
    from onnx import numpy_helper

    for t in model.graph.initializer:
        if t.name == name:
            return float(numpy_helper.to_array(t).reshape(-1)[0])
    for n in model.graph.node:
        if n.op_type == "Constant" and n.output[0] == name:
            return float(numpy_helper.to_array(n.attribute[0].t).reshape(-1)[0])
    return None


def albedo_floor(model) -> float:
    """The composition's albedo floor, in encoded albedo (2 floor - 1), as the graph holds it: the lower bound of
    the one Clip without an upper bound applied to a Slice (the encoded albedo's). Raises LeanUnsupported."""
    producer = {o: n for n in model.graph.node for o in n.output}
    found = [n for n in model.graph.node if n.op_type == "Clip" and len(n.input) >= 2
             and (len(n.input) == 2 or n.input[2] == "") and getattr(producer.get(n.input[0]), "op_type", "") == "Slice"]
    value = _constant(model, found[0].input[1]) if len(found) == 1 else None
    if value is None:
        raise LeanUnsupported(f"the graph's albedo floor is not found ({len(found)} candidate clips)")
    return value


class LeanUnsupported(Exception):
    """Why a model has no lean path (the caller runs its graph)."""


class NoGenerator(LeanUnsupported):
    """The graph has no generator to cut out (a linear baseline, a test's toy graph): nothing to say about it."""


def generator_subgraph(model):
    """The generator's subgraph of a self-contained model (an onnx ModelProto): float32 (N, planes, H, W) encoded
    input ``encoded`` -> float32 (N, 3, H, W) raw tanh output ``raw``. Raises LeanUnsupported."""
    from onnx import TensorProto

    g = model.graph
    convs = [n for n in g.node if n.op_type == "Conv"]
    tanhs = [n for n in g.node if n.op_type == "Tanh"]
    if not convs or len(tanhs) != 1:
        raise NoGenerator(f"the graph has {len(convs)} convolutions and {len(tanhs)} tanh: no generator found")
    encoded, raw = convs[0].input[0], tanhs[0].output[0]
    sub = _cut(model, encoded, raw)
    ops = {n.op_type for n in sub.graph.node} - GENERATOR_OPS
    if ops:
        raise LeanUnsupported(f"the cut between the encoding and netG's output holds {', '.join(sorted(ops))}")
    return sub


def _cut(model, encoded: str, raw: str):
    """The nodes that make ``raw`` from ``encoded`` and the initializers (as a model: input ``encoded``, output
    ``raw``, float32 NCHW of free size). Raises LeanUnsupported where ``raw`` needs another graph input."""
    from onnx import TensorProto, helper

    g = model.graph
    producer = {o: n for n in g.node for o in n.output}
    inits = {t.name: t for t in g.initializer}
    wanted, nodes, used, seen = [raw], [], set(), set()
    while wanted:
        name = wanted.pop()
        if name in seen or name == encoded or name == "":
            continue
        seen.add(name)
        if name in inits:
            used.add(name)
            continue
        if name not in producer:
            raise LeanUnsupported(f"netG's output depends on the graph input {name!r}, not only on the encoding")
        node = producer[name]
        if node not in nodes:
            nodes.append(node)
            wanted.extend(node.input)
    order = {id(n): i for i, n in enumerate(g.node)}
    nodes.sort(key=lambda n: order[id(n)])
    rename = {encoded: "encoded", raw: "raw"}
    out_nodes = []
    for n in nodes:
        c = type(n)()
        c.CopyFrom(n)
        c.input[:] = [rename.get(i, i) for i in c.input]
        c.output[:] = [rename.get(o, o) for o in c.output]
        out_nodes.append(c)
    first = next(n for n in nodes if encoded in n.input and n.op_type == "Conv")
    w = inits.get(first.input[1])
    channels = int(w.dims[1]) if w is not None else None
    if w is None and first.input[1] in producer:  # stored weights behind a Cast
        src = producer[first.input[1]].input[0]
        channels = int(inits[src].dims[1]) if src in inits else None
    graph = helper.make_graph(out_nodes, "netG",
                              [helper.make_tensor_value_info("encoded", TensorProto.FLOAT, ["N", channels, "H", "W"])],
                              [helper.make_tensor_value_info("raw", TensorProto.FLOAT, ["N", 3, "H", "W"])],
                              [inits[n] for n in sorted(used)])
    return helper.make_model(graph, opset_imports=model.opset_import, ir_version=model.ir_version)


def world_planes_np(depth, normal, cams, center, half) -> np.ndarray:
    """numpy twin of `diviewer.train.world.world_planes` (and of encode.glsl's): (N, 1, H, W) finite depth, (N, 3, H,
    W) view normal, (N, 20) cameras -> (N, 6, H, W) encoded world position and normal, 0 off the surfaces."""
    n, _, h, w = depth.shape
    f = np.float32
    c = np.asarray(cams, f).reshape(n, -1, 1, 1)
    cols = np.minimum(np.maximum(np.arange(w, dtype=f).reshape(1, 1, 1, w), c[:, 16:17]), c[:, 17:18]) + f(0.5)
    rows = np.minimum(np.maximum(np.arange(h, dtype=f).reshape(1, 1, h, 1), c[:, 18:19]), c[:, 19:20]) + f(0.5)
    view = (depth * (c[:, 12:13] * cols + c[:, 13:14]), depth * (c[:, 14:15] * rows + c[:, 15:16]), -depth)
    nrm = np.clip(normal, -1.0, 1.0)
    center = np.asarray(center, f).reshape(1, 3, 1, 1)
    inv_half = f(1.0) / np.asarray(half, f).reshape(1, 3, 1, 1)
    pos = np.concatenate([c[:, 3 * k:3 * k + 1] * view[0] + c[:, 3 * k + 1:3 * k + 2] * view[1]
                          + c[:, 3 * k + 2:3 * k + 3] * view[2] + c[:, 9 + k:10 + k] for k in range(3)], 1)
    wn = np.concatenate([c[:, 3 * k:3 * k + 1] * nrm[:, 0:1] + c[:, 3 * k + 1:3 * k + 2] * nrm[:, 1:2]
                         + c[:, 3 * k + 2:3 * k + 3] * nrm[:, 2:3] for k in range(3)], 1)
    with np.errstate(over="ignore", invalid="ignore"):  # the graph's geometry mask: depth x HUGE saturates to 1
        geo = np.clip(depth * f(HUGE), 0.0, 1.0)
    return np.concatenate([np.clip((pos - center) * inv_half, -1.0, 1.0) * geo, np.clip(wn, -1.0, 1.0) * geo], 1)


class LeanModel:
    """A loaded model's generator alone (``generator``), with the constants of the per-pixel work around it.

    Everything a caller reads of a ``NeuralGI`` (metadata, sizes, ``frame_inputs``, ``check_size``, ...) is the
    graph model's (``graph``); ``run`` gives what the graph gives, from raw buffers, with the encoding and the
    decoding in numpy; `diviewer.gl.neural.NeuralPass` does them in shaders and calls ``run_generator``.
    """

    lean = True

    def __init__(self, graph, providers: list[str] | None = None):
        import onnx
        import onnxruntime as ort

        self.graph = graph
        model = onnx.load(str(graph.path))
        sub = generator_subgraph(model)
        if graph.meta.get("precision") != "fp32":
            raise LeanUnsupported(f"a {graph.meta.get('precision')}-precision model (only fp32 graphs are cut)")
        self.enc = Encoding.from_dict(graph.meta["encoding"])
        if self.enc.version < 2:
            raise LeanUnsupported(f"encoding version {self.enc.version} (the cut is made for versions 2 to 4)")
        self.planes = self.enc.input_planes
        shape = sub.graph.input[0].type.tensor_type.shape.dim
        if len(shape) != 4 or shape[1].dim_value != self.planes:
            raise LeanUnsupported(f"the generator takes {shape[1].dim_value if len(shape) > 1 else '?'} planes, "
                                  f"encoding version {self.enc.version} makes {self.planes}")
        self.generator_ops = frozenset(n.op_type for n in sub.graph.node)
        """The operators of the generator's subgraph (a subset of GENERATOR_OPS)."""
        self.generator = ort.InferenceSession(sub.SerializeToString(), sess_options=graph.session_options,
                                              providers=providers or graph.session.get_providers())
        self.timer = StageTimer()
        self.target, self.divide_albedo = graph.meta["target"], bool(graph.meta["divide_albedo"])
        self.log_r = np.float32(math.log1p(self.enc.radiance_max))
        self.floor_lo = np.float32(albedo_floor(model)) if self.target != "full" and self.divide_albedo else None
        """The albedo floor of the composition in encoded albedo, read from the graph (None: no floor)."""
        self.out_scale = (0.5 if self.target != "full" and self.divide_albedo else 1.0) / self.enc.output().exposure
        self.nonfinite_inputs = self.nonfinite_outputs = 0

    def __getattr__(self, name):  # the graph model's metadata, sizes and frame inputs
        return getattr(self.__dict__["graph"], name) if "graph" in self.__dict__ else super().__getattribute__(name)

    # --- what the shaders and numpy share -------------------------------------------------------------------------
    def padding(self, width: int, height: int) -> tuple[tuple[int, int], tuple[int, int]]:
        """The padded size (W', H') of a ``width`` x ``height`` frame and where the frame starts in it (left, top),
        as the graph path pads it (`diviewer.contract.padding`)."""
        m, g = self.multiple, self.edge_guard
        return ((padded_size(width, m, g), padded_size(height, m)),
                (crop_slice(width, m, g).start, crop_slice(height, m).start))

    def constants(self, width: int, height: int, light_scale=None, camera=None, light=None) -> dict:
        """The per-frame constants of the encoding and the decoding (float32, as the graph computes them): the
        input and output scales, the padded camera (encoding 3) and the lights (encoding 4)."""
        f = np.float32
        out = {"in_k": f(self.enc.exposure), "out_k": f(self.out_scale)}
        if self.enc.light_scaled:
            if light_scale is None:
                raise ValueError(f"{self.path.name} uses encoding version {self.enc.version}: it needs each frame's "
                                 "light scale (its conditioning: NeuralGI.frame_inputs)")
            s = f(np.asarray(light_scale, f).reshape(-1)[0])
            inv = f(1.0) / s if s > 0 else f(0.0)
            out["in_k"], out["out_k"] = f(inv * f(self.enc.exposure)), f(s * f(self.out_scale))
        if self.enc.world_inputs:
            if camera is None:
                raise ValueError(f"{self.path.name} uses encoding version 3: it needs each frame's camera")
            c = np.asarray(camera, f).reshape(1, -1)
            out["camera"] = pad_camera_params(c, width, height, self.multiple, self.edge_guard)[0].astype(f)
        if self.enc.light_inputs:
            if light is None:
                raise ValueError(f"{self.path.name} uses encoding version 4: it needs each frame's lights")
            out["light"] = np.asarray(light, f).reshape(-1)
            if out["light"].size != 3 * self.light_count:
                raise ValueError(f"light: expected {3 * self.light_count} values, got {out['light'].size}")
        return out

    # --- the generator --------------------------------------------------------------------------------------------
    def run_generator(self, encoded: np.ndarray, timer: StageTimer | None = None) -> np.ndarray:
        """(1, planes, H', W') encoded inputs (padded) -> (1, 3, H', W') raw output, timed as ``inference``."""
        with (timer or self.timer).stage("inference"):
            (y,) = self.generator.run(["raw"], {"encoded": encoded})
        return y

    # --- the CPU path -----------------------------------------------------------------------------------------------
    def encode(self, x: np.ndarray, k: dict) -> np.ndarray:
        """(1, H', W', 10) padded raw buffers -> (1, planes, H', W') encoded, as the graph (and pack.glsl) encodes."""
        f = np.float32
        x = np.where(np.isnan(x), f(0.0), x).transpose(0, 3, 1, 2)
        depth = np.where(np.isinf(x[:, 0:1]), f(0.0), x[:, 0:1])
        geo, direct = x[:, 1:7], x[:, 7:10]
        with np.errstate(over="ignore", invalid="ignore"):
            d = depth * f(1.0 / self.enc.depth_scale)
            parts = [np.clip(d, 0, 1) - np.clip(f(1.0) - d * f(HUGE), 0, 1)]
            scale = np.array([1, 1, 1, 2, 2, 2], f).reshape(1, 6, 1, 1)
            offset = np.array([0, 0, 0, -1, -1, -1], f).reshape(1, 6, 1, 1)
            parts.append(np.clip(geo * scale + offset, -1, 1))
            c = np.clip(direct * k["in_k"], -self.enc.radiance_max, self.enc.radiance_max).astype(f)
            a = np.abs(c)
            parts.append(np.log(a + f(1.0)) * (c / np.maximum(a * self.log_r, f(TINY) * self.log_r)))
            if self.enc.world_inputs:
                parts.append(world_planes_np(depth, geo[:, :3], k["camera"][None], self.enc.world_center,
                                             self.enc.world_half))
            if self.enc.light_inputs:
                parts.append(k["light"].reshape(1, -1, 1, 1) * np.clip(depth * f(HUGE), 0, 1))
        return np.ascontiguousarray(np.concatenate(parts, 1), dtype=f)

    def decode(self, y: np.ndarray, x: np.ndarray, k: dict) -> np.ndarray:
        """(1, 3, H', W') raw output and (1, H', W', 10) padded raw buffers -> (1, H', W', 3) radiance, as the graph
        (and decode.glsl) decodes and composes it."""
        f = np.float32
        ay = np.abs(y)
        with np.errstate(over="ignore", invalid="ignore"):
            pred = (np.exp(ay * self.log_r) - f(1.0)) * (y / np.maximum(ay, f(TINY))) * k["out_k"]
            pred = pred.transpose(0, 2, 3, 1)
            if self.target == "full":
                return np.maximum(pred, f(0.0))
            if self.divide_albedo:
                albedo = np.where(np.isnan(x[..., 4:7]), f(0.0), x[..., 4:7])
                e = np.clip(albedo * f(2.0) - f(1.0), -1, 1)
                pred = pred * (np.maximum(e, self.floor_lo) + f(1.0))
            out = x[..., 7:10] + pred
        return np.where(out < 0, f(0.0), out)  # NaN stays NaN, as the graph's Relu and the runtime's clamp

    def run(self, buffers: np.ndarray, timer: StageTimer | None = None, light_scale=None, camera=None,
            light=None) -> np.ndarray:
        """`diviewer.contract.runtime.NeuralGI.run`'s contract, the per-pixel work in numpy and the generator in onnxruntime."""
        from diviewer.contract.runtime import count_nonfinite

        single = buffers.ndim == 3
        x = np.ascontiguousarray(buffers[None] if single else buffers, dtype=np.float32)
        if x.shape[0] != 1:
            return np.concatenate([self.run(b, timer, light_scale, camera, light)[None] for b in x])
        height, width = x.shape[1:3]
        self.check_size(width, height)
        self.nonfinite_inputs = count_nonfinite(x)
        k = self.constants(width, height, light_scale, camera, light)
        xp = pad_nhwc(x, self.multiple, self.edge_guard)
        y = self.decode(self.run_generator(self.encode(xp, k), timer), xp, k)
        y = np.ascontiguousarray(y[:, crop_slice(height, self.multiple),
                                   crop_slice(width, self.multiple, self.edge_guard)])
        self.nonfinite_outputs = count_nonfinite(y)
        return y[0] if single else y


def lean_model(graph, check: bool = True):
    """``graph`` (a NeuralGI)'s lean model and "" or, where it has none, None and the reason. With ``check`` the lean
    model must give the graph's radiance on the probe frame (`diviewer.contract.runtime.probe_frame`) to PROBE_TOLERANCE of
    its peak (a frame with background and albedo under the floor, so constants the graph holds are compared)."""
    if getattr(graph, "lean", False):
        return graph, ""
    if "_lean_model" not in graph.__dict__:  # cut once per loaded model (a pass is rebuilt on each resize)
        graph.__dict__["_lean_model"] = _lean_model(graph, check)
    return graph.__dict__["_lean_model"]


def _lean_model(graph, check: bool):
    from diviewer.contract.conditioning import stand_in
    from diviewer.contract.runtime import probe_frame

    from diviewer.errors import DiviewerError

    try:
        lean = LeanModel(graph)
    except NoGenerator:  # nothing to make lean: the graph runs, with nothing to explain
        return None, ""
    except (LeanUnsupported, DiviewerError, KeyError) as exc:  # a model without a generator or its record
        return None, f"{graph.path.name}: no lean path ({exc}); the graph runs"
    if check:
        w, h = (min(int(d), 64) for d in graph.resolution)
        cam = {"position": (0.3, 0.8, 3.0), "target": (0.0, 0.5, 0.0), "up": (0.0, 1.0, 0.0), "fov": 45.0}
        extra = stand_in(graph.encoding, (w, h), camera=cam, sun=(0.3, -1.0, 0.2)).inputs()
        frame = probe_frame(h, w)[0]
        frame[: h // 4, :, 4:7] = 0.01  # albedo under the composition's floor
        frame[h // 2:, : w // 4, 0] = 0.0  # background
        want, got = graph.run(frame, timer=StageTimer(), **extra), lean.run(frame, timer=StageTimer(), **extra)
        err = float(np.max(np.abs(want - got))) / max(float(np.max(want)), 1e-6)
        if not err <= PROBE_TOLERANCE:
            return None, (f"{graph.path.name}: no lean path (it differs from the graph by {err:.2g} of the probe "
                          f"frame's peak, above {PROBE_TOLERANCE:g}); the graph runs")
    return lean, ""
