"""`diviewer eval`: models against an evaluation set (or a dataset split), beside direct light (torch-free).

Every method is scored against the path-traced image (`pt`) with the same metrics as training's
validation: MSE, PSNR (peak 1) and SSIM on linear radiance, and the same on the tone-mapped image
(diviewer.metrics.tonemap). On an evaluation set (diviewer.evalset) also: HDR-FLIP on linear radiance,
LDR-FLIP on the tone-mapped images, the checkerboard ratio over flat regions, and the equivalent sample
count; beside the models, direct light alone, the noise floor (a second seed at the reference's spp)
and the path tracer at each ladder count, per split. One tone map (the evaluation set's exposure)
for every row. On a dataset split (``--data``) the tone map is the model's exposure, as in training.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.data.dataset import Dataset
from diviewer.errors import DiviewerError
from diviewer.metrics import (equivalent_spp, flat_mask, flip, highpass_power, mse, power_ratio, psnr, psnr_error,
                              ssim, tonemap)
from diviewer.outputs import check_output_file, strict, write_json
from diviewer.data.scales import light_scales
from diviewer.runtime import NeuralGI, pack_buffers

SSIM_MIN = 11
"""SSIM's window (diviewer.metrics): smaller frames cannot be scored."""
KEYS = ("mse", "psnr", "ssim", "mse_tm", "psnr_tm", "ssim_tm")


def score(image: np.ndarray, truth: np.ndarray, exposure: float) -> dict[str, float]:
    a, b = tonemap(image, exposure), tonemap(truth, exposure)
    return {"mse": mse(image, truth), "psnr": psnr(image, truth), "ssim": ssim(image, truth),
            "mse_tm": mse(a, b), "psnr_tm": psnr(a, b), "ssim_tm": ssim(a, b)}


def evaluate(model_path: Path, data_dir: Path, split: str = "test", provider: str | None = None,
             out: Path | None = None, log=print) -> dict:
    if out is not None:
        check_output_file(out, "--out", protect=(model_path, Path(model_path).with_suffix(".json")))
    ds = Dataset(data_dir)
    if min(ds.width, ds.height) < SSIM_MIN:
        raise DiviewerError(f"SSIM needs frames of at least {SSIM_MIN}x{SSIM_MIN} pixels, the dataset's are "
                            f"{ds.width}x{ds.height}", path=Path(data_dir) / "manifest.json", field="resolution")
    model = NeuralGI(model_path, provider=provider)
    if model.meta["scene_hash"] != ds.manifest["scene_hash"]:
        raise DiviewerError(f"the model was trained for scene '{model.meta['scene']}' (another scene file than "
                            f"the dataset's '{ds.manifest['scene']}')", path=model_path, field="scene_hash")
    idx = ds.indices(split)
    if not idx:
        raise DiviewerError(f"the dataset has no '{split}' frames", path=data_dir)
    exposure = float(model.meta["encoding"]["exposure"])
    rows, times, black = {"neural": [], "direct": []}, [], []
    scales = light_scales(ds, idx) if model.light_scaled else [None] * len(idx)  # encoding 2: each frame's light
    for i, s in zip(idx, scales):
        f = ds.load(i)
        if not np.any(f["pt"] > 0):
            black.append(i)
        t0 = time.perf_counter()
        y = model.run(pack_buffers(f), light_scale=s)
        times.append((time.perf_counter() - t0) * 1e3)
        rows["neural"].append(score(y, f["pt"], exposure))
        rows["direct"].append(score(f["direct"], f["pt"], exposure))
    summary = {
        "model": str(model_path), "data": str(data_dir), "split": split, "frames": len(idx),
        "scene": ds.manifest["scene"], "reference_spp": ds.manifest["spp"], "provider": model.provider,
        "K": model.meta["K"], "target": model.meta["target"], "precision": model.meta["precision"],
        "inference_ms": {"median": float(np.median(times)), "p95": float(np.percentile(times, 95))},
        "black_reference_frames": black,
        "methods": {m: {k: {"mean": float(np.mean([r[k] for r in rs])), "std": float(np.std([r[k] for r in rs]))}
                        for k in KEYS} for m, rs in rows.items()},
    }
    log(f"{summary['scene']} {split} split, {len(idx)} frames, against path tracing at {summary['reference_spp']} spp")
    log(f"{'method':<34} {'PSNR':>7} {'SSIM':>7} {'PSNR tm':>8} {'SSIM tm':>8}")
    for m, label in (("neural", _model_label(model.meta, Path(model_path))), ("direct", "direct light only")):
        s = summary["methods"][m]
        log(f"{label:<34} {s['psnr']['mean']:7.2f} {s['ssim']['mean']:7.4f} {s['psnr_tm']['mean']:8.2f} "
            f"{s['ssim_tm']['mean']:8.4f}")
    log(f"inference {summary['inference_ms']['median']:.1f} ms median ({model.provider})")
    if black:
        # PSNR and SSIM against an all-black image measure only how dark the other image is.
        log(f"warning: {len(black)} frame(s) have an all-black reference ({', '.join(map(str, black[:8]))}"
            f"{', ...' if len(black) > 8 else ''}); their scores say little: check the dataset's lights")
    if out is not None:
        write_json(out, summary, indent=1)  # strict JSON: an infinite PSNR (identical images) is null
    return summary


# --- evaluation sets ---------------------------------------------------------------------------------------------

EVAL_KEYS = KEYS + ("flip_hdr", "flip_ldr")
EQUIVALENT_BY = ("psnr_tm", "psnr", "flip_ldr")
"""Metrics the equivalent sample count is read from; the first is the headline (tables, targets)."""


def score_frame(image: np.ndarray, truth: np.ndarray, exposure: float, mask: np.ndarray,
                direct: np.ndarray | None = None) -> dict[str, float]:
    """Every evaluation-set metric of one frame, plus the sums behind the pooled checkerboard ratio and
    the pooled bias (given the frame's GL ``direct`` light, also the bias of the indirect light alone)."""
    a, b = tonemap(image, exposure), tonemap(truth, exposure)
    s = score(image, truth, exposure)
    s["flip_hdr"] = flip(truth, image, "HDR")
    s["flip_ldr"] = flip(b, a, "LDR")
    s["hf_power"], s["hf_power_ref"] = highpass_power(a, mask), highpass_power(b, mask)
    s["sum"], s["sum_ref"] = float(np.sum(image, dtype=np.float64)), float(np.sum(truth, dtype=np.float64))
    if direct is not None:
        d = float(np.sum(direct, dtype=np.float64))
        s["sum_indirect"], s["sum_indirect_ref"] = s["sum"] - d, s["sum_ref"] - d
    return s


def pooled_bias(rows: list[dict], key: str = "sum") -> float | None:
    """Signed relative error of the summed radiance over all frames, (sum image / sum truth) - 1: negative
    where a method is darker than the truth on the whole. An unbiased estimator (the path tracer at any
    sample count) scores ~0; L1 training on noisy targets converges to the per-pixel median, which is
    darker than the mean where fireflies are. None without the sums or with a black truth."""
    if not rows or any(key not in r for r in rows):
        return None
    ref = sum(r[f"{key}_ref"] for r in rows)
    return sum(r[key] for r in rows) / ref - 1.0 if ref > 0 else None


def aggregate(rows: list[dict]) -> dict:
    """Per-frame scores (``score_frame``) of one method as mean and std per key, plus the pooled checkerboard
    ratio; what evaluate and the bench report per method."""
    out = {k: {"mean": float(np.mean([r[k] for r in rows])), "std": float(np.std([r[k] for r in rows]))}
           for k in EVAL_KEYS}
    # Pooled over frames (each frame's flat pixels weigh alike), not a mean of per-frame ratios.
    out["checkerboard"] = power_ratio(sum(r["hf_power"] for r in rows), sum(r["hf_power_ref"] for r in rows))
    out["bias"] = pooled_bias(rows)
    out["bias_indirect"] = pooled_bias(rows, "sum_indirect")
    return out


def _error(summary: dict, key: str) -> float:
    v = summary[key]["mean"]
    return psnr_error(v) if key.startswith("psnr") else v


def equivalent(summary: dict, ladder_spp: list[int], ladder: list[dict]) -> dict:
    """The path-traced sample count whose error matches ``summary``'s (an ``aggregate``), per key of
    ``EQUIVALENT_BY``, read off the ladder (``ladder[i]`` aggregated at ``ladder_spp[i]``); None where none can be."""
    out = {}
    for key in EQUIVALENT_BY:
        try:
            out[key] = equivalent_spp(ladder_spp, [_error(r, key) for r in ladder], _error(summary, key))
        except ValueError:  # a perfect score (error 0) or a ladder with one: no sample count to read
            out[key] = None
    return out


def _model_label(meta: dict, path: Path) -> str:
    if meta.get("kind") == "linear_baseline":
        return f"linear baseline ({meta.get('parameters', '?')} params)"
    return f"neural K={meta['K']} {meta['precision']} ({path.stem})"


def evaluate_evalset(model_paths: list[Path], evalset_dir: Path, provider: str | None = None,
                     out: Path | None = None, log=print) -> dict:
    """Score models, direct light, the noise floor and the path-tracer ladder on an evaluation set, per split."""
    from diviewer.evalset import EVAL_SPLITS, load_evalset
    from diviewer.console import progress_bar

    ds = load_evalset(evalset_dir)
    info = ds.manifest["evalset"]
    exposure = float(info["tonemap"]["exposure"])
    ladder_spp, ladder_ch = [int(n) for n in info["ladder_spp"]], list(info["ladder_channels"])
    models = {}
    for path in model_paths:
        net = NeuralGI(path, provider=provider)
        if net.meta["scene_hash"] != ds.manifest["scene_hash"]:
            raise DiviewerError(f"the model was made for scene '{net.meta['scene']}' (another scene file than the "
                                f"evaluation set's '{ds.manifest['scene']}')", path=path, field="scene_hash")
        key = path.stem if path.stem not in models else f"{path.stem}_{len(models)}"
        models[key] = net
    rows_of = {"direct": "direct", "noise_floor": info["second_seed_channel"],
               **{f"pt_spp{n}": ch for n, ch in zip(ladder_spp, ladder_ch)}}
    result = {"evalset": str(evalset_dir), "scene": ds.manifest["scene"], "reference_spp": ds.manifest["spp"],
              "resolution": ds.manifest["resolution"], "tonemap_exposure": exposure, "ladder_spp": ladder_spp,
              "flip": {"flip_hdr": "HDR-FLIP on linear radiance (negative values clamped to 0)",
                       "flip_ldr": "LDR-FLIP on the tone-mapped images"},
              "equivalent_spp_by": EQUIVALENT_BY[0], "splits": {}}
    progress = progress_bar(len(ds.indices()), "eval", "frame")
    for split in EVAL_SPLITS:
        idx = ds.indices(split)
        if not idx:
            continue
        rows = {k: [] for k in (*models, *rows_of)}
        times = {k: [] for k in models}
        flat = 0
        scales = light_scales(ds, idx) if any(n.light_scaled for n in models.values()) else [None] * len(idx)
        for i, s in zip(idx, scales):
            f = ds.load(i)
            mask = flat_mask(f["depth"], f["normal"], f["albedo"], f["direct"])  # flat and no shadow edge
            flat += int(mask.sum())
            for key, net in models.items():
                t0 = time.perf_counter()
                y = net.run(pack_buffers(f), light_scale=s)
                times[key].append((time.perf_counter() - t0) * 1e3)
                rows[key].append(score_frame(y, f["pt"], exposure, mask, f["direct"]))
            for key, ch in rows_of.items():
                rows[key].append(score_frame(f[ch], f["pt"], exposure, mask, f["direct"]))
            progress.update()
        methods = {k: aggregate(r) for k, r in rows.items()}
        ladder = [methods[f"pt_spp{n}"] for n in ladder_spp]
        for key, m in methods.items():
            m["equivalent_spp"] = equivalent(m, ladder_spp, ladder)
            if key in models:
                net = models[key]
                m.update(kind=net.meta.get("kind", "neural"), label=_model_label(net.meta, net.path),
                         model=str(net.path), provider=net.provider,
                         inference_ms={"median": float(np.median(times[key]))})
            elif key == "direct":
                m.update(kind="direct", label="direct light only (GL)")
            elif key == "noise_floor":
                m.update(kind="noise_floor", label=f"noise floor ({ds.manifest['spp']} spp, 2nd seed)")
            else:
                m.update(kind="path_tracer", label=f"path traced {key[6:]} spp")
        result["splits"][split] = {"frames": len(idx), "flat_pixels_per_frame": flat / len(idx), "methods": methods}
    progress.close()
    for line in format_tables(result):
        log(line)
    if out is not None:
        imageio.write_text(out, strict_json(result))
    return result


def format_tables(result: dict) -> list[str]:
    """The per-split tables for people."""
    lines = [f"{result['scene']}: against path tracing at {result['reference_spp']} spp; tm = tone-mapped at "
             f"exposure {result['tonemap_exposure']:.3g}; FLIP-HDR on linear radiance, FLIP-LDR on tone-mapped; "
             f"eq. spp from PSNR tm; checker = high-frequency power over flat, shadow-edge-free regions / "
             f"the reference's; bias = summed radiance / the reference's - 1 (indirect: minus GL direct light)"]
    for split, r in result["splits"].items():
        lines.append("")
        lines.append(f"{split} ({r['frames']} frames)")
        lines.append(f"{'method':<34} {'PSNR':>6} {'SSIM':>6} {'PSNR tm':>7} {'SSIM tm':>7} {'FLIP-HDR':>8} "
                     f"{'FLIP-LDR':>8} {'eq. spp':>8} {'checker':>7} {'bias':>7} {'indirect':>8}")
        for m in r["methods"].values():
            eq = m["equivalent_spp"][EQUIVALENT_BY[0]]
            lines.append(f"{m['label']:<34} {m['psnr']['mean']:6.2f} {m['ssim']['mean']:6.4f} "
                         f"{m['psnr_tm']['mean']:7.2f} {m['ssim_tm']['mean']:7.4f} {m['flip_hdr']['mean']:8.4f} "
                         f"{m['flip_ldr']['mean']:8.4f} {eq['text'] if eq else '-':>8} {_num(m['checkerboard']):>7} "
                         f"{_pct(m.get('bias')):>7} {_pct(m.get('bias_indirect')):>8}")
    return lines


def _pct(v: float | None) -> str:
    return f"{100 * v:+.1f}%" if v is not None and math.isfinite(v) else "-"


def _num(v: float) -> str:
    return f"{v:.3g}" if math.isfinite(v) else "inf"


def strict_json(obj) -> str:
    """JSON without NaN or Infinity (a perfect PSNR, a ratio over a perfectly smooth reference): they become null."""
    return json.dumps(strict(obj), indent=1, allow_nan=False)
