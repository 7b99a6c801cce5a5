"""The one-pass ground truth (`diviewer.reference.split_path`) against the two passes it replaces: the same
expectation, and the time it saves.

Usage: python tools/experiments/split_path_check.py [--scene sponza] [--data runs/sponza/data --frames 0,36]
       [--res 114x64] [--spp 64] [--renders 8] [--time-res 228x128] [--out J.json]

Each frame (a capture's frames by index with ``--data``, else the scene's default frame) is rendered ``--renders``
times by each estimator under seeds 1..R: the two passes as a capture makes them (`MitsubaFrame.full` and
`.direct`, one seed) and the one pass. Per channel (full, direct, indirect = full - direct) it reports
- the relative difference of the two estimators' frame means, and its z score against the seeds' spread;
- the per-pixel z scores of the difference of the two mean images (mean and standard deviation over the pixels
  whose spread is above round-off: about 0 and 1 for estimators of one expectation, a t distribution's 1.29 at
  6 renders);
- the one pass's per-pixel variance over the seeds against the two passes', pooled over the frame (1: as noisy);
- the largest difference between the two estimators' renders under one seed, over the frame's mean: the direct
  light is drawn with the same random numbers by both, so it is the same image up to round-off where no cut-out
  lies in a shadow ray's way;
and, at ``--time-res``, the seconds of one render by each at ``--spp`` (median of 3, after a warm-up). Stop other
jobs first (SIGSTOP) when the times matter.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def frames_of(scene, data: str | None, indices: list[int]) -> list[tuple[str, object]]:
    """(name, configuration) of each frame: a capture's by index, else the scene's default frame."""
    from diviewer.scene.loader import config_from_dict

    if data is None:
        return [("default", scene.default)]
    listing = json.loads((Path(data) / "manifest.json").read_text())["frame_list"]
    return [(f"frame {i}", config_from_dict(scene, listing[i]["config"])) for i in indices]


def renders(frame, spp: int, seeds: range, one_pass: bool) -> np.ndarray:
    """(R, 2, H, W, 3): full and direct light per seed, by one estimator."""
    out = []
    for seed in seeds:
        out.append(np.stack(frame.full_and_direct(spp, seed)[:2] if one_pass else
                            (frame.full(spp, seed), frame.direct(spp, seed))))
    return np.stack(out)


def compare(a: np.ndarray, b: np.ndarray) -> dict:
    """Per channel: the estimators' frame means, their relative difference and its z, per-pixel z statistics."""
    out = {}
    for name, x, y in (("full", a[:, 0], b[:, 0]), ("direct", a[:, 1], b[:, 1]),
                       ("indirect", a[:, 0] - a[:, 1], b[:, 0] - b[:, 1])):
        r = len(x)
        mx, my = x.mean(axis=(1, 2, 3)), y.mean(axis=(1, 2, 3))  # per seed
        se = np.sqrt(mx.var(ddof=1) / r + my.var(ddof=1) / r)
        diff = mx.mean() - my.mean()
        px_se = np.sqrt(x.var(axis=0, ddof=1) / r + y.var(axis=0, ddof=1) / r)
        varying = px_se > 1e-4 * max(float(my.mean()), 1e-30)  # above float round-off of the frame's level
        z = (x.mean(axis=0) - y.mean(axis=0))[varying] / px_se[varying]
        out[name] = {"mean_one_pass": float(mx.mean()), "mean_two_passes": float(my.mean()),
                     "relative_difference": float(diff / my.mean()) if my.mean() > 0 else None,
                     "z": float(diff / se) if se > 0 else None,
                     "pixel_z_mean": float(z.mean()) if z.size else None,
                     "pixel_z_std": float(z.std()) if z.size else None, "pixels_varying": int(varying.sum()),
                     "same_seed_max_difference": float(np.abs(x - y).max() / max(float(my.mean()), 1e-30)),
                     "variance_ratio": float(x.var(axis=0, ddof=1).sum() / max(float(y.var(axis=0, ddof=1).sum()),
                                                                             1e-30))}
    return out


def timing(frame, spp: int) -> dict:
    """Seconds of one render by each estimator (median of 3 after a warm-up)."""
    frame.full_and_direct(4, 0)
    frame.full(4, 0)
    frame.direct(4, 0)
    one, two = [], []
    for k in range(3):
        t = time.perf_counter()
        frame.full_and_direct(spp, k + 1)
        one.append(time.perf_counter() - t)
        t = time.perf_counter()
        frame.full(spp, k + 1)
        frame.direct(spp, k + 1)
        two.append(time.perf_counter() - t)
    return {"one_pass_s": float(np.median(one)), "two_passes_s": float(np.median(two)),
            "saved": float(1.0 - np.median(one) / np.median(two))}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default="sponza")
    p.add_argument("--data", help="a capture whose frames to take (default: the scene's default frame)")
    p.add_argument("--frames", default="0", help="capture frame indices, comma separated")
    p.add_argument("--res", default="114x64")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--renders", type=int, default=8)
    p.add_argument("--time-res", default="228x128", help="WxH of the timed renders; 'none' skips them")
    p.add_argument("--out")
    a = p.parse_args(argv)

    from diviewer.reference.mitsuba import load_frame, select_variant
    from diviewer.scene.loader import load_scene

    scene = load_scene(a.scene)
    variant = select_variant()
    w, h = (int(x) for x in a.res.split("x"))
    rows = []
    for name, config in frames_of(scene, a.data, [int(i) for i in a.frames.split(",")]):
        frame = load_frame(scene, config, w, h)
        seeds = range(1, a.renders + 1)
        row = {"frame": name, **compare(renders(frame, a.spp, seeds, True), renders(frame, a.spp, seeds, False))}
        if a.time_res != "none":
            tw, th = (int(x) for x in a.time_res.split("x"))
            row["time"] = {"res": [tw, th], "spp": a.spp, **timing(load_frame(scene, config, tw, th), a.spp)}
        rows.append(row)
        print(json.dumps(row))
    result = {"scene": a.scene, "variant": variant, "res": [w, h], "spp": a.spp, "renders": a.renders,
              "frames": rows}
    if a.out:
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        Path(a.out).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
