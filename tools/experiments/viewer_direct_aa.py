"""The viewer's frame against Mitsuba at the window's size, as the viewer composes it and with its direct light
anti-aliased (the direct light over each window pixel's area, `diviewer.gl.area`, plus the same upsampled GI).

Usage: python tools/experiments/viewer_direct_aa.py --truth-cache runs/cornell/viewer_truth_384.npz
           [--model M ...] [--size 384] [--frames 4] [--samples 4] [--exposure 0.642] [--out OUT.json]

The frames and their Mitsuba truths are `scale_accuracy.py`'s (same seeds; its ``--truth-cache`` holds the
renders at 256 spp: run it first with ``--size 384x384 --frames 4 --spp 256 --truth-cache ...``). Per model: the
mean tone-mapped PSNR of the viewer's composite (window-resolution direct light at each pixel's centre + the
joint-bilateral-upsampled indirect light) and of the same indirect light over the direct light of
``--samples`` x ``--samples`` sub-pixel samples. What anti-aliasing the viewer's direct light would buy.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from scale_accuracy import STREAM  # noqa: E402


def measure(models: list[Path], cache: Path, size: int, frames: int, samples: int, exposure: float) -> dict:
    from diviewer.bench.runner import read_final
    from diviewer.evaluation.evaluate import score
    from diviewer.gl.area import AreaDirect
    from diviewer.gl.context import headless_context
    from diviewer.gl.neural import NeuralPass
    from diviewer.gl.renderer import Renderer
    from diviewer.runtime import NeuralGI
    from diviewer.scene import load_scene, sample_config
    from diviewer.viewer.models import gi_resolution, runtime_pads

    scene = load_scene("cornell")
    truths = dict(np.load(cache))
    out = {}

    for path in models:
        model = NeuralGI(path, scene=scene)
        rows = {"viewer": [], f"viewer_direct_aa{samples}": []}
        with headless_context() as ctx:
            r = Renderer(ctx, scene, size, size)
            gi = gi_resolution("model", (size, size), model.resolution, model.multiple, pads=runtime_pads(model),
                               shape=(size, size))
            npass, aa = NeuralPass(ctx, r, model, gi_size=gi), AreaDirect(ctx, scene, size, size, samples)
            try:
                for split in ("train", "test"):
                    for i in range(frames):
                        seed = int(np.random.SeedSequence([STREAM, 0 if split == "train" else 1, i]).generate_state(1)[0]
                                   & 0x7FFFFFFF)
                        config = sample_config(scene, seed, split)
                        truth = truths[f"cornell_{split}_{i}_{seed}_{size}x{size}_256"]
                        r.render(config)
                        npass.run(**npass.inputs_for(scene, config))
                        full, indirect = read_final(npass.composite()), read_final(npass.composite(indirect_only=True))
                        rows["viewer"].append(score(full, truth, exposure)["psnr_tm"])
                        rows[f"viewer_direct_aa{samples}"].append(score(indirect + aa(config), truth, exposure)["psnr_tm"])
            finally:
                aa.release()
                npass.release()
                r.release()
        out[str(path)] = {k: float(np.mean(v)) for k, v in rows.items()}
        print(path, {k: round(v, 2) for k, v in out[str(path)].items()})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", type=Path, action="append")
    ap.add_argument("--truth-cache", type=Path, required=True)
    ap.add_argument("--size", type=int, default=384)
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--samples", type=int, default=4)
    ap.add_argument("--exposure", type=float, default=0.642025732938584, help="the compact set's tone map")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    result = measure(a.model or [ROOT / "assets" / "models" / "cornell.onnx"], a.truth_cache, a.size, a.frames,
                     a.samples, a.exposure)
    if a.out:
        a.out.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
