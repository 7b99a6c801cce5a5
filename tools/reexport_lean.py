"""Re-export a shipped model's generator as the lean graph, from the weights inside its ONNX file.

Usage: python tools/reexport_lean.py assets/models/cornell.onnx [--out NEW.onnx] [--frames 4]

The training checkpoints of the shipped models are not kept, but their ONNX files hold every weight. This
rebuilds the torch ``UnetGenerator`` from them (layer by layer in graph order; batch norm that the exporter
folded into a convolution becomes the convolution's weights and an identity batch norm whose shift is the
folded bias), then checks, before anything is written:

1. the rebuilt generator inside training's own encode/decode (``ReferenceGI``) reproduces the old graph run
   in float32 (the old file with its fp16 weights widened, ``bench.onnx_tools.to_fp32``) on random buffers
   to 1e-5 of the peak;
2. the lean export (``diviewer.train.export.verified_onnx``, same precision and encoding as the old file)
   passes the export's own checks against PyTorch, extremes included;
3. the new file against the old one in onnxruntime, both as shipped, on random buffers and on GL renders
   of the scene's test configurations: the largest difference is reported in the card.

The card keeps the old one's fields (encoding, scene_hash, recipe, trained_on, validation, ...), with the
new graph's verification, layout and opset, and a ``reexport`` record (the old file's sha256, the checks).
Without --out the model and its card are replaced in place.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.errors import DiviewerError
from diviewer.outputs import dumps, staged
from diviewer.contract.weights import weights_to_float32

REBUILD_TOLERANCE = 1e-5
"""The rebuilt generator must reproduce the old float32 graph to this fraction of the peak radiance."""


def _initializers(model) -> dict[str, np.ndarray]:
    from onnx import numpy_helper

    return {i.name: numpy_helper.to_array(i).astype(np.float32) for i in model.graph.initializer}


def rebuild_generator(model, meta: dict):
    """The old graph's generator as a float32 torch ``UnetGenerator`` (eval mode), weights from the file."""
    import torch

    from diviewer.train.networks import UnetGenerator

    if meta.get("norm", "batch") != "batch" or meta.get("upsample", "transpose") not in ("transpose", "resize"):
        raise DiviewerError("only batch-norm generators with transpose or resize decoders are rebuilt",
                            field="norm/upsample")
    from diviewer.contract.encoding import INPUT_CHANNEL_COUNT, Encoding

    # the encoding's own planes (encoding 3's world planes, 4's light planes), and its Fourier features if any
    planes = Encoding.from_dict(meta["encoding"]).input_planes if meta.get("encoding") else INPUT_CHANNEL_COUNT
    netG = UnetGenerator(in_channels=planes, K=int(meta["K"]), levels=int(meta["levels"]),
                         upsample=meta.get("upsample", "transpose"), norm="batch",
                         frequencies=int(meta.get("world_frequencies") or 0)).eval()
    model = weights_to_float32(model)  # weights stored as float16 (export --half-weights): as initializers again
    inits = _initializers(model)
    nodes = list(model.graph.node)
    consumers = {}
    for n in nodes:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    convs = [n for n in nodes if n.op_type in ("Conv", "ConvTranspose") and n.input[1] in inits]
    layers = []  # (conv module, batch norm module or None), in forward order
    for block in (*netG.down, *netG.up):
        mods = list(block)
        for k, m in enumerate(mods):
            if isinstance(m, (torch.nn.Conv2d, torch.nn.ConvTranspose2d)):
                bn = mods[k + 1] if k + 1 < len(mods) and isinstance(mods[k + 1], torch.nn.BatchNorm2d) else None
                layers.append((m, bn))
    if len(convs) != len(layers):
        raise DiviewerError(f"the graph has {len(convs)} convolutions, a K={meta['K']} generator {len(layers)}")
    with torch.no_grad():
        for node, (conv, bn) in zip(convs, layers):
            w = inits[node.input[1]]
            b = inits[node.input[2]] if len(node.input) > 2 and node.input[2] else None
            if tuple(w.shape) != tuple(conv.weight.shape) or (node.op_type == "ConvTranspose") != isinstance(
                    conv, torch.nn.ConvTranspose2d):
                raise DiviewerError(f"{node.name}: {node.op_type} {w.shape} does not fit {conv}")
            conv.weight.copy_(torch.from_numpy(w))
            after = [c for c in consumers.get(node.output[0], []) if c.op_type == "BatchNormalization"]
            if bn is None:
                if b is None or conv.bias is None:
                    raise DiviewerError(f"{node.name}: bias expected on both sides")
                conv.bias.copy_(torch.from_numpy(b))
            elif after:  # an explicit batch norm node: its parameters as they are
                g, beta, mean, var = (inits[i] for i in after[0].input[1:5])
                eps = next((a.f for a in after[0].attribute if a.name == "epsilon"), 1e-5)
                bn.weight.copy_(torch.from_numpy(g)), bn.bias.copy_(torch.from_numpy(beta))
                bn.running_mean.copy_(torch.from_numpy(mean)), bn.running_var.copy_(torch.from_numpy(var))
                bn.eps = float(eps)
                if b is not None:
                    raise DiviewerError(f"{node.name}: a convolution before a batch norm has no bias here")
            else:  # folded by the exporter: the conv holds the scaled weights, the bias is the shift
                bn.weight.fill_(1.0), bn.running_mean.zero_()
                bn.running_var.fill_(1.0 - bn.eps)  # 1 / sqrt(var + eps) = 1
                bn.bias.copy_(torch.from_numpy(b if b is not None else np.zeros(bn.num_features, np.float32)))
    return netG


def random_frames(n: int, h: int, w: int, seed: int = 0) -> np.ndarray:
    """Buffers in the ranges the renderer gives: depth 0 (background) or 0.5..far, unit normals, albedo, direct."""
    rng = np.random.default_rng(seed)
    depth = np.where(rng.random((n, h, w, 1)) < 0.1, 0.0, rng.uniform(0.5, 9.0, (n, h, w, 1)))
    normal = rng.normal(size=(n, h, w, 3))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    return np.concatenate([depth, normal, rng.uniform(0, 1, (n, h, w, 3)), rng.exponential(0.5, (n, h, w, 3))],
                          -1).astype(np.float32)


def gl_frames(scene_name: str, n: int, res: tuple[int, int]) -> np.ndarray:
    """GL inputs of the scene's first ``n`` test configurations (as the viewer packs them)."""
    from diviewer.gl.context import headless_context
    from diviewer.gl.renderer import Renderer
    from diviewer.contract.runtime import pack_buffers
    from diviewer.scene import load_scene, sample_config

    scene = load_scene(scene_name)
    with headless_context() as ctx:
        r = Renderer(ctx, scene, *res)
        try:
            return np.stack([pack_buffers(r.frame(sample_config(scene, 7000 + i, "test"))) for i in range(n)])
        finally:
            r.release()


def _run(session, x: np.ndarray) -> np.ndarray:
    return np.concatenate([session.run(None, {"buffers": f[None]})[0] for f in x])


def reexport(path: Path, out: Path, n_frames: int = 4, log=print) -> dict:
    """Rebuild, check, re-export lean; returns the new card."""
    import onnx
    import onnxruntime as ort
    import torch

    from diviewer.bench.onnx_tools import get_meta, to_fp32
    from diviewer.contract.encoding import Encoding
    from diviewer.provenance import versions
    from diviewer.train.export import OPSET, ExportSettings, gi_module, verified_onnx
    from diviewer.contract.runtime import META_KEY

    old = onnx.load(str(path))
    meta = get_meta(old)
    enc = Encoding.from_dict(meta["encoding"])
    if enc.light_scaled:
        raise DiviewerError("an encoding-2 model is lean already (exported by this diviewer)", path=path)
    res = tuple(int(v) for v in meta["resolution"])
    netG = rebuild_generator(old, meta)
    compose = {"target": meta["target"], "divide_albedo": bool(meta.get("divide_albedo"))}
    # 1. the rebuilt generator in training's functions against the old graph, both in float32
    ref = gi_module(netG, enc, compose, lean=False)
    old32 = ort.InferenceSession(to_fp32(old).SerializeToString(), providers=["CPUExecutionProvider"])
    x = random_frames(n_frames, *res[::-1])
    with torch.no_grad():
        want = ref(torch.from_numpy(x)).numpy()
    got = _run(old32, x)
    rebuild_err = float(np.abs(got - want).max() / (np.abs(want).max() or 1.0))
    log(f"{path.name}: rebuilt generator vs the old graph in float32: max |diff| {rebuild_err:.2g} of peak")
    if rebuild_err > REBUILD_TOLERANCE:
        raise DiviewerError(f"the rebuilt generator differs from the old graph by {rebuild_err:.2g} of peak "
                            f"(tolerance {REBUILD_TOLERANCE}); nothing written", path=path)
    # 2. the lean export, checked as every export is
    frames = np.concatenate([gl_frames(meta["scene"], n_frames, res), x[:1]])
    settings = ExportSettings(fp16=meta["precision"] == "fp16", verify_frames=len(frames), layout=meta["layout"])
    model, check = verified_onnx(lambda: rebuild_generator(old, meta), enc, compose, settings, frames, None,
                                 f"{n_frames} GL frames of {meta['scene']}'s test configurations and 1 random frame",
                                 out, log)
    # 3. new against old, both as shipped
    old_s = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    new_s = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    a, b = _run(old_s, frames), _run(new_s, frames)
    peak = float(np.abs(a).max()) or 1.0
    vs_old = {"frames": check["frames"], "max_abs_diff": float(np.abs(a - b).max()),
              "max_rel_to_peak": float(np.abs(a - b).max() / peak), "mean_abs_diff": float(np.abs(a - b).mean())}
    log(f"new vs old file ({meta['precision']}, onnxruntime): max |diff| {vs_old['max_abs_diff']:.3g} "
        f"({vs_old['max_rel_to_peak']:.2g} of peak {peak:.3g}), mean {vs_old['mean_abs_diff']:.3g}")
    sha = hashlib.sha256(path.read_bytes()).hexdigest()
    card = {**meta, "layout": settings.layout, "opset": OPSET, "verification": check, "exported_with": versions(),
            "note": "re-exported as the lean graph from the weights in the ONNX file (the training checkpoint is not "
                    "kept) by tools/reexport_lean.py",
            "reexport": {"from_sha256": sha, "rebuild_max_rel_to_peak": rebuild_err, "new_vs_old": vs_old,
                         "previous_verification": meta.get("verification"), "previous_opset": meta.get("opset")}}
    onnx.helper.set_model_props(model, {META_KEY: dumps(card, sort_keys=True)})
    model.producer_name, model.producer_version = "diviewer", card["exported_with"]["diviewer"]
    with staged() as stage:
        onnx.save(model, str(stage(out)))
        imageio.write_text(stage(out.with_suffix(".json")),
                           dumps(card_with_extras(path.with_suffix(".json"), card), indent=2, sort_keys=True))
    log(f"wrote {out} and {out.with_suffix('.json').name}")
    return card


def card_with_extras(old_card: Path, card: dict) -> dict:
    """The new card plus what the old card file held beyond the model's metadata (e.g. the K ladder's record)."""
    import json

    extra = json.loads(old_card.read_text()) if old_card.is_file() else {}
    return {**{k: v for k, v in extra.items() if k not in card}, **card}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", type=Path)
    ap.add_argument("--out", type=Path, default=None, help="default: replace the model and its card")
    ap.add_argument("--frames", type=int, default=4, help="GL and random frames for the checks")
    args = ap.parse_args(argv)
    try:
        reexport(args.model, args.out or args.model, args.frames)
    except DiviewerError as exc:
        print(f"reexport_lean: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
