"""`diviewer baseline`: the per-pixel linear-regression baseline a network must beat, as an ONNX model.

Published screen-space GI work reports such a baseline beside its networks: a least-squares fit, per
pixel, from the same input buffers to the target. Here the target is what the GL direct pass misses,
``pt - direct`` (indirect light, plus the path tracer's exact shadows where the shadow map differs),
and each colour channel c is predicted from the features

    f = (1, depth / depth_scale, normal xyz, direct rgb)                       (8 numbers)
    y_c = direct_c + f . a_c + albedo_c * (f . b_c)                            (16 weights per channel)

so 48 parameters in all: the albedo products let bounce light be coloured by the surface it lands on,
as a diffuse surface does. The fit solves the normal equations accumulated over every pixel of the
training split (float64; a ridge of 1e-9 of the diagonal only guards a degenerate feature).

The model follows the runtime's contract (diviewer/contract/runtime.py): input ``buffers`` (N, H, W, 10) raw
linear, output ``radiance`` (N, H, W, 3), metadata under ``diviewer`` with ``"kind": "linear_baseline"``,
so ``diviewer eval``, the benchmark and the viewer run it like any model. Building it needs numpy and
the ``onnx`` package (no torch); running it needs only onnxruntime.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.data.area import direct_samples
from diviewer.data.dataset import Dataset
from diviewer.contract.encoding import INPUT_CHANNELS, Encoding, fit_exposure
from diviewer.errors import DiviewerError, missing_extra
from diviewer.provenance import versions
from diviewer.contract.runtime import INPUT_NAME, META_KEY, MODEL_FORMAT, OUTPUT_NAME

KIND = "linear_baseline"
FEATURES = ("1", "depth/depth_scale", "normal_x", "normal_y", "normal_z", "direct_r", "direct_g", "direct_b")
OPSET = 17
RIDGE = 1e-9


def features(depth: np.ndarray, normal: np.ndarray, direct: np.ndarray, depth_scale: float) -> np.ndarray:
    """(..., 8) float64 features of each pixel, in FEATURES order."""
    d = np.asarray(depth, dtype=np.float64)
    d = d[..., None] if d.ndim == normal.ndim - 1 else d
    ones = np.ones_like(d)
    return np.concatenate([ones, d / depth_scale, np.asarray(normal, np.float64), np.asarray(direct, np.float64)], -1)


def predict(weights_a: np.ndarray, weights_b: np.ndarray, depth, normal, albedo, direct,
            depth_scale: float) -> np.ndarray:
    """The baseline in numpy (what the ONNX graph computes): direct + f @ A + albedo * (f @ B)."""
    f = features(depth, normal, direct, depth_scale)
    return np.asarray(direct, np.float64) + f @ weights_a + np.asarray(albedo, np.float64) * (f @ weights_b)


def _depth_scale(ds: Dataset, idx: list[int]) -> float:
    """The camera's far plane (as the network's encoding uses), else 1."""
    wanted = set(idx)
    fars = [float(f["config"]["camera"]["far"]) for f in ds.frames
            if f["index"] in wanted and isinstance((f.get("config") or {}).get("camera", {}).get("far"), (int, float))]
    return max(fars) if fars else 1.0


def fit(ds: Dataset, split: str = "train", max_frames: int | None = None, log=print) -> dict:
    """Least squares over every pixel of the split's present frames; returns weights and fit statistics."""
    idx = ds.indices(split)
    if max_frames:
        idx = idx[:max_frames]
    if not idx:
        raise DiviewerError(f"the dataset has no '{split}' frames yet", path=ds.root)
    if "pt" not in ds.slices:
        raise DiviewerError("the dataset has no path-traced ground truth (channel 'pt')", path=ds.root)
    depth_scale = _depth_scale(ds, idx)
    n = len(FEATURES)
    xtx = np.zeros((3, 2 * n, 2 * n))
    xty = np.zeros((3, 2 * n))
    yty = np.zeros(3)
    directs = []
    t0 = time.perf_counter()
    for k, i in enumerate(idx):
        fr = ds.load(i)
        f = features(fr["depth"], fr["normal"], fr["direct"], depth_scale).reshape(-1, n)
        albedo = fr["albedo"].reshape(-1, 3).astype(np.float64)
        target = (fr["pt"] - fr["direct"]).reshape(-1, 3).astype(np.float64)
        for c in range(3):
            x = np.concatenate([f, albedo[:, c:c + 1] * f], axis=1)
            xtx[c] += x.T @ x
            xty[c] += x.T @ target[:, c]
            yty[c] += target[:, c] @ target[:, c]
        if k % 64 == 0:
            directs.append(fr["direct"][::4, ::4])  # a thinned sample for the tone map's exposure
        if log and (k + 1) % 500 == 0:
            log(f"  {k + 1}/{len(idx)} frames accumulated ({time.perf_counter() - t0:.0f} s)")
    w = np.zeros((3, 2 * n))
    for c in range(3):
        ridge = RIDGE * max(float(np.trace(xtx[c])) / (2 * n), 1e-30)
        w[c] = np.linalg.solve(xtx[c] + ridge * np.eye(2 * n), xty[c])
    pixels = len(idx) * ds.width * ds.height
    # Residual sum of squares from the accumulated moments: y'y - 2 w'X'y + w'X'X w.
    rss = [float(yty[c] - 2 * w[c] @ xty[c] + w[c] @ xtx[c] @ w[c]) for c in range(3)]
    return {"A": w[:, :n].T.copy(), "B": w[:, n:].T.copy(), "depth_scale": depth_scale, "frames": len(idx),
            "pixels": pixels, "train_rmse": float(np.sqrt(max(sum(rss), 0.0) / (3 * pixels))),
            "exposure": float(fit_exposure(directs)), "seconds": round(time.perf_counter() - t0, 1)}


def build_onnx(A: np.ndarray, B: np.ndarray, depth_scale: float, meta: dict):
    """The ONNX graph: slices of ``buffers``, two MatMuls, an albedo product, plus direct."""
    try:
        import onnx
        from onnx import TensorProto, helper, numpy_helper
    except ImportError as exc:
        raise missing_extra("onnx") from exc

    def const(name, arr, dtype=np.float32):
        return numpy_helper.from_array(np.asarray(arr, dtype=dtype), name)

    inits = [const("axis_last", [3], np.int64), const("s0", [0], np.int64), const("s1", [1], np.int64),
             const("s4", [4], np.int64), const("s7", [7], np.int64), const("s10", [10], np.int64),
             const("inv_depth_scale", 1.0 / depth_scale), const("zero", 0.0), const("one", 1.0),
             const("A", A), const("B", B)]
    nodes = [
        helper.make_node("Slice", [INPUT_NAME, "s0", "s1", "axis_last"], ["depth"]),
        helper.make_node("Slice", [INPUT_NAME, "s1", "s4", "axis_last"], ["normal"]),
        helper.make_node("Slice", [INPUT_NAME, "s4", "s7", "axis_last"], ["albedo"]),
        helper.make_node("Slice", [INPUT_NAME, "s7", "s10", "axis_last"], ["direct"]),
        helper.make_node("Mul", ["depth", "zero"], ["zeros"]),
        helper.make_node("Add", ["zeros", "one"], ["ones"]),
        helper.make_node("Mul", ["depth", "inv_depth_scale"], ["depth_n"]),
        helper.make_node("Concat", ["ones", "depth_n", "normal", "direct"], ["features"], axis=3),
        helper.make_node("MatMul", ["features", "A"], ["plain"]),
        helper.make_node("MatMul", ["features", "B"], ["modulated"]),
        helper.make_node("Mul", ["albedo", "modulated"], ["bounce"]),
        helper.make_node("Add", ["plain", "bounce"], ["residual"]),
        helper.make_node("Add", ["direct", "residual"], [OUTPUT_NAME]),
    ]
    x = helper.make_tensor_value_info(INPUT_NAME, TensorProto.FLOAT, ["N", "H", "W", sum(c for _, c in INPUT_CHANNELS)])
    y = helper.make_tensor_value_info(OUTPUT_NAME, TensorProto.FLOAT, ["N", "H", "W", 3])
    model = helper.make_model(helper.make_graph(nodes, "linear_baseline", [x], [y], inits),
                              opset_imports=[helper.make_opsetid("", OPSET)])
    model.ir_version = 8  # readable by every onnxruntime this project supports
    helper.set_model_props(model, {META_KEY: json.dumps(meta, sort_keys=True)})
    model.producer_name = "diviewer"
    onnx.checker.check_model(model)
    return model


def build_baseline(data_dir: Path, out: Path, split: str = "train", max_frames: int | None = None, log=print) -> dict:
    """Fit on a dataset's split, write ``out`` (ONNX) and its model card (``out`` with .json); returns the card."""
    import onnx

    from diviewer.outputs import check_output_file

    if max_frames is not None and (isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 1):
        raise DiviewerError(f"must be at least 1 (or left out: every present frame), got {max_frames!r}",
                            field="--max-frames")
    out = Path(out)
    for path in (out, out.with_suffix(".json")):  # before the fit: the model's and the card's names are free
        check_output_file(path, "--out", suffix=".onnx" if path == out else None, replaces="model")
    ds = Dataset(data_dir)
    log(f"fitting the linear baseline on {data_dir} ({split} split, {len(ds.indices(split))} frames present)")
    r = fit(ds, split, max_frames, log)
    w, h = ds.width, ds.height
    card = {
        "format": MODEL_FORMAT, "kind": KIND, "input": INPUT_NAME, "output": OUTPUT_NAME, "layout": "NHWC",
        "channels": [list(c) for c in INPUT_CHANNELS], "resolution": [w, h], "multiple": 1, "K": 0, "levels": 0,
        "target": "indirect", "precision": "fp32",
        # the direct light it was fitted on (a capture's direct_area): the runtime feeds it the same light
        "direct_samples": direct_samples(ds.manifest),
        "encoding": Encoding(exposure=r["exposure"], depth_scale=r["depth_scale"]).to_dict(),
        "scene": ds.manifest["scene"], "scene_hash": ds.manifest["scene_hash"], "dataset_hash": ds.hash,
        "description": "per-pixel linear regression (a baseline, not a network): radiance = direct + f.A + "
                       "albedo * (f.B), f = " + ", ".join(FEATURES),
        "features": list(FEATURES), "parameters": int(r["A"].size + r["B"].size),
        "weights": {"A": r["A"].tolist(), "B": r["B"].tolist()},
        "fit": {"split": split, "frames": r["frames"], "pixels": r["pixels"], "train_rmse": r["train_rmse"],
                "seconds": r["seconds"], "data": str(data_dir), "ridge": RIDGE},
        "exported_with": versions(), "opset": OPSET,
    }
    model = build_onnx(r["A"], r["B"], r["depth_scale"], card)
    with imageio.atomic_path(out) as tmp:
        onnx.save(model, str(tmp))
    imageio.write_text(Path(out).with_suffix(".json"), json.dumps(card, indent=2, sort_keys=True))
    log(f"wrote {out}: {card['parameters']} parameters fitted on {r['frames']} frames ({r['pixels']} pixels), "
        f"train RMSE of the residual {r['train_rmse']:.4g}, {r['seconds']:.0f} s")
    return card
