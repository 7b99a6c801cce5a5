"""An evaluation set's splits scored at other window shapes: a copy whose manifest lists only the chosen splits, each
at the chosen widths, its frames hard-linked (no bytes copied, nothing rendered).

Usage: python tools/experiments/evalset_shapes.py --evalset FULL --out COPY --split moved_camera --split
           unseen_objects --widths 170,228
       then: diviewer eval --evalset COPY --model M --out EVAL.json
       python tools/experiments/evalset_shapes.py geometry --evalset COPY --model M [--out G.json]

A full evaluation set renders every frame at its manifest's resolution and scores each split on centred crops of
its shapes' widths (`diviewer.evaluation.frames.crop`), so a split scored at 128 columns has its 4:3 and 16:9 frames stored
already: the same camera's narrower frames at the same vertical field of view, as a window of that shape shows it.
The set's own window-shapes split is at the scene camera only, where cornell's box fills the middle 170 of 228
columns (docs/generalisation.md); this scores the held-out cameras and the unseen objects in wide windows too.
A compact set is refused (its ladder is stored as scores per split and shape, not as images).

``geometry``: per split and shape, the share of pixels that show no geometry (the void: depth 0, where model and
truth are both ~0) and the model's and direct light's tone-mapped PSNR over the pixels that do (per frame, then the
mean), beside the whole frame's as `diviewer eval` computes it: what a wider frame's score owes to its void.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

from diviewer.data.scales import light_scales
from diviewer.errors import DiviewerError
from diviewer.evaluation.frames import EvalFrames, crop, crop_frame, split_key
from diviewer.evaluation.evaluate import area_direct_of, model_input, run_model, stored_inputs
from diviewer.metrics import psnr, tonemap
from diviewer.runtime import NeuralGI


def shaped_copy(src: Path, out: Path, splits: list[str], widths: list[int]) -> dict:
    """Write ``out``: ``src``'s manifest with only ``splits``, each at ``widths`` (full height), and ``src``'s frame
    files hard-linked. Returns the new manifest."""
    ev = EvalFrames(src)
    if ev.compact:
        raise DiviewerError("a compact set stores its ladder as scores per shape: give a full evaluation set",
                            path=src)
    manifest = json.loads((src / "manifest.json").read_text())
    w, h = manifest["resolution"]
    have = manifest["evalset"]["splits"]
    for name in splits:
        if name not in have:
            raise DiviewerError(f"no split '{name}' (the set has {', '.join(have)})", path=src / "manifest.json",
                                field="evalset.splits")
    for width in widths:  # the evaluation's own crop rule, checked before anything is written
        try:
            if width < 1:
                raise ValueError(f"cannot crop {w} columns centrally to {width}")
            crop(np.empty((0, w)), width)
        except ValueError as exc:
            raise DiviewerError(f"{exc} (the set's frames are {w} wide)", field="--widths") from None
    manifest["evalset"]["splits"] = {name: {**have[name], "shapes": [[width, h] for width in widths]}
                                     for name in splits}
    manifest["evalset"]["shapes_from"] = {"set": str(src), "tool": "tools/experiments/evalset_shapes.py"}
    out.mkdir(parents=True, exist_ok=False)
    for root, _dirs, files in os.walk(src / "frames"):
        dest = out / Path(root).relative_to(src)
        dest.mkdir(parents=True, exist_ok=True)
        for name in files:
            os.link(Path(root) / name, dest / name)
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1))
    return manifest


def _psnr_tm(image: np.ndarray, truth: np.ndarray, exposure: float, mask: np.ndarray | None = None) -> float:
    """`diviewer eval`'s tone-mapped PSNR, over ``mask``'s pixels only where one is given."""
    a, b = tonemap(image, exposure), tonemap(truth, exposure)
    return psnr(a, b) if mask is None else psnr(a[mask], b[mask])


def geometry_scores(evalset: Path, model: Path) -> dict:
    """Per split key: frames, void share (mean, max), and the model's and direct light's PSNR tm on the whole frame
    and on the geometry's pixels (means over frames)."""
    net = NeuralGI(model)
    ev = EvalFrames(evalset)
    every = [f["index"] for f in ev.frames]
    scales = dict(zip(every, light_scales(ev, every))) if net.light_scaled else {}
    area = area_direct_of(ev, {net.direct_samples} - {1})
    out = {}
    for split, shapes in ev.splits().items():
        rows = {tuple(shape): [] for shape in shapes}
        for i in ev.present(split, []):
            frame = ev.load(i)  # once per frame, cropped to each shape
            for shape in shapes:
                f = crop_frame(frame, shape[0])
                geo = f["depth"] > 0
                y = run_model(net, model_input(net, f, frame, area, i, shape[0]), scales.get(i),
                              **stored_inputs(net, ev.entry(i), f))
                rows[tuple(shape)].append((1.0 - float(geo.mean()), _psnr_tm(y, f["pt"], ev.exposure),
                                           _psnr_tm(y, f["pt"], ev.exposure, geo),
                                           _psnr_tm(f["direct"], f["pt"], ev.exposure),
                                           _psnr_tm(f["direct"], f["pt"], ev.exposure, geo)))
        for shape in shapes:
            a = np.array(rows[tuple(shape)])
            out[split_key(split, shape, shapes)] = {
                "frames": len(a), "void_mean": float(a[:, 0].mean()), "void_max": float(a[:, 0].max()),
                "model_psnr_tm": float(a[:, 1].mean()), "model_psnr_tm_geometry": float(a[:, 2].mean()),
                "direct_psnr_tm": float(a[:, 3].mean()), "direct_psnr_tm_geometry": float(a[:, 4].mean())}
    return {"evalset": str(evalset), "model": str(model), "exposure": ev.exposure, "splits": out}


def geometry_main(argv: list[str]) -> dict:
    ap = argparse.ArgumentParser(description="what a wider frame's score owes to its void")
    ap.add_argument("--evalset", type=Path, required=True)
    ap.add_argument("--model", type=Path, required=True)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    r = geometry_scores(a.evalset, a.model)
    for key, v in r["splits"].items():
        print(f"{key:<26} {v['frames']:>3} frames, void {100 * v['void_mean']:4.1f} % (max {100 * v['void_max']:.0f})"
              f" | model {v['model_psnr_tm']:.2f}, geometry only {v['model_psnr_tm_geometry']:.2f}"
              f" | direct {v['direct_psnr_tm']:.2f}, geometry only {v['direct_psnr_tm_geometry']:.2f} dB tm")
    if a.out:
        a.out.write_text(json.dumps(r, indent=1))
    return r


def main(argv: list[str] | None = None) -> dict:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["geometry"]:
        return geometry_main(argv[1:])
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--evalset", type=Path, required=True, help="a full evaluation set (diviewer evalset)")
    ap.add_argument("--out", type=Path, required=True, help="the copy (a new folder, on the same file system)")
    ap.add_argument("--split", action="append", required=True, help="a split to keep; repeat for several")
    ap.add_argument("--widths", required=True, help="comma-separated widths, e.g. 170,228 (4:3 and 16:9 at 128 rows)")
    a = ap.parse_args(argv)
    widths = [int(v) for v in a.widths.split(",")]
    m = shaped_copy(a.evalset, a.out, a.split, widths)
    print(f"{a.out}: {', '.join(m['evalset']['splits'])} at widths {widths}; score it with `diviewer eval "
          f"--evalset {a.out} --model M`")
    return m


if __name__ == "__main__":
    main()
