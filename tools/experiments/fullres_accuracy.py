"""How close the viewer's frame is to the path tracer at window resolution: full resolution vs stretched.

Usage: python tools/experiments/fullres_accuracy.py [--scene cornell] [--model assets/models/cornell.onnx] [--size 384]
       [--frames 6] [--spp 256] [--out runs/cornell/fullres_accuracy.json]

For each frame (drawn from the sampler's train and test splits with seeds no capture uses), three images
at the window's size:
- full: what the viewer shows now: G-buffer, shadows and direct light at the window's resolution, the
  network at the model's resolution on inputs downsampled from those buffers (nearest depth), its indirect
  light upsampled by the joint bilateral filter and composited over the full-resolution direct light
  (gl/neural.py, the viewer's own pass);
- stretched: what it showed before: the whole frame rendered and composited at the model's resolution
  and scaled to the window bilinearly (the display pass's texture filter);
- truth: Mitsuba at the window's resolution and --spp.
Both are scored against the truth with `diviewer eval`'s metrics (PSNR/SSIM linear and tone-mapped at the
model's exposure, LDR-FLIP), per split and in all.
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

STREAM = 0xF011E5  # seeds of their own: SeedSequence([STREAM, split, i])

from scale_accuracy import bilinear  # noqa: E402  (this folder is on sys.path: GL LINEAR magnification)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="cornell")
    ap.add_argument("--model", type=Path, default=ROOT / "assets" / "models" / "cornell.onnx")
    ap.add_argument("--size", type=int, default=384, help="window size (square), a multiple of the model's")
    ap.add_argument("--frames", type=int, default=6, help="frames per split (train, test)")
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--gi-downsample", default="nearest", choices=("nearest", "area"),
                    help="how the full-resolution buffers are reduced to the network's inputs")
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "cornell" / "fullres_accuracy.json")
    a = ap.parse_args()

    from diviewer import metrics
    from diviewer.evaluation.evaluate import score
    from diviewer.gl.context import describe, headless_context
    from diviewer.gl.neural import GISettings, NeuralPass
    from diviewer.gl.renderer import Renderer
    from diviewer.reference import mitsuba as ref
    from diviewer.runtime import NeuralGI, pack_buffers
    from diviewer.scene import load_scene, sample_config

    scene = load_scene(a.scene)
    model = NeuralGI(a.model)
    gw, gh = model.resolution
    exposure = float(model.meta["encoding"]["exposure"])
    variant = ref.select_variant()
    rows: dict[str, list] = {"train": [], "test": []}
    t0 = time.time()
    with headless_context() as ctx:
        full_r = Renderer(ctx, scene, a.size, a.size)
        low_r = Renderer(ctx, scene, gw, gh)
        npass = NeuralPass(ctx, full_r, model, gi_size=(gw, gh), settings=GISettings(downsample=a.gi_downsample))
        for split in rows:
            for i in range(a.frames):
                seed = int(np.random.SeedSequence([STREAM, 0 if split == "train" else 1, i]).generate_state(1)[0]
                           & 0x7FFFFFFF)
                config = sample_config(scene, seed, split)
                full_r.render(config)
                npass.run(**npass.inputs_for(scene, config))
                tex = npass.composite()
                full = np.flipud(np.frombuffer(tex.read(), dtype="f2").reshape(a.size, a.size, 4)[..., :3])
                full = np.ascontiguousarray(full, dtype=np.float32)
                low = model.run(pack_buffers(low_r.frame(config)))
                stretched = bilinear(low, a.size, a.size)
                truth = ref.load_frame(scene, config, a.size, a.size).full(spp=a.spp, seed=seed)
                row = {"seed": seed}
                for name, img in (("full", full), ("stretched", stretched)):
                    s = score(img, truth, exposure)
                    s["flip_ldr"] = metrics.flip(metrics.tonemap(truth, exposure), metrics.tonemap(img, exposure), "LDR")
                    row[name] = s
                rows[split].append(row)
                print(f"{split} {i}: full {row['full']['psnr_tm']:.2f} dB / {row['full']['ssim_tm']:.3f}, "
                      f"stretched {row['stretched']['psnr_tm']:.2f} dB / {row['stretched']['ssim_tm']:.3f} "
                      f"({time.time() - t0:.0f} s)", flush=True)
        gl = describe(ctx)
        npass.release()
        low_r.release()
        full_r.release()

    def mean(rs, name, q):
        return float(np.mean([r[name][q] for r in rs]))

    qs = ("psnr", "ssim", "psnr_tm", "ssim_tm", "flip_ldr")
    summary = {split: {name: {q: mean(rs, name, q) for q in qs} for name in ("full", "stretched")}
               for split, rs in [*rows.items(), ("all", rows["train"] + rows["test"])]}
    out = {"scene": a.scene, "model": str(a.model), "window": [a.size, a.size], "gi": [gw, gh], "spp": a.spp,
           "gi_downsample": a.gi_downsample,
           "variant": variant, "gl_renderer": gl, "tonemap_exposure": exposure, "summary": summary, "frames": rows,
           "seconds": round(time.time() - t0, 1)}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(out, indent=1))
    print(f"{'split':6} {'image':10} " + " ".join(f"{q:>9}" for q in qs))
    for split, d in summary.items():
        for name, v in d.items():
            print(f"{split:6} {name:10} " + " ".join(f"{v[q]:9.4f}" for q in qs))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
