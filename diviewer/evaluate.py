"""`diviewer eval`: a model against a dataset split, beside the direct-light baseline (torch-free).

Every method is scored against the path-traced image (`pt`) with the same metrics as training's
validation: MSE, PSNR (peak 1) and SSIM on linear radiance, and the same on the tone-mapped image
(diviewer.metrics.tonemap at the model's exposure). The reference's own noise bounds what any score
can mean: `diviewer render --reference pt --noise-floor` measures it at the dataset's spp.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from diviewer.data.dataset import Dataset
from diviewer.errors import DiviewerError
from diviewer.metrics import mse, psnr, ssim, tonemap
from diviewer.outputs import check_output_file, write_json
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
    for i in idx:
        f = ds.load(i)
        if not np.any(f["pt"] > 0):
            black.append(i)
        t0 = time.perf_counter()
        y = model.run(pack_buffers(f))
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
    log(f"{'method':<22} {'PSNR':>7} {'SSIM':>7} {'PSNR tm':>8} {'SSIM tm':>8}")
    for m, label in (("neural", f"neural K={model.meta['K']} {model.meta['precision']}"), ("direct", "direct light only")):
        s = summary["methods"][m]
        log(f"{label:<22} {s['psnr']['mean']:7.2f} {s['ssim']['mean']:7.4f} {s['psnr_tm']['mean']:8.2f} "
            f"{s['ssim_tm']['mean']:8.4f}")
    log(f"inference {summary['inference_ms']['median']:.1f} ms median ({model.provider})")
    if black:
        # PSNR and SSIM against an all-black image measure only how dark the other image is.
        log(f"warning: {len(black)} frame(s) have an all-black reference ({', '.join(map(str, black[:8]))}"
            f"{', ...' if len(black) > 8 else ''}); their scores say little: check the dataset's lights")
    if out is not None:
        write_json(out, summary, indent=1)  # strict JSON: an infinite PSNR (identical images) is null
    return summary
