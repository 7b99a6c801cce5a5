"""How a model trained on square frames does in a non-square window, three ways of feeding it.

Usage: python tools/experiments/aspect_probe.py [--scene cornell] [--size 1024x768] [--spp 256] [--out runs/aspect.json]

The viewer runs the network at the GI resolution (e.g. 128x128) whatever the window's shape, so a
1024x768 window's buffers reach it squashed horizontally. This renders the window's view at the
training scale with square texels (here 171x128: the window's height maps to the model's 128 rows),
path traces it with Mitsuba (`llvm_ad_rgb`, --spp), and scores, tone-mapped as `diviewer eval` does:
  squash: the viewer's way (nearest-sampled to 128x128, the output stretched back);
  two square tiles: 128x128 at the left and at the right edge, blended linearly where they overlap;
  padded: 256x128 with the missing columns reflected or repeated from the edge, then cropped;
beside direct light alone, on the scene's default configuration and two test configurations.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="cornell")
    ap.add_argument("--model", default=None, help="default assets/models/SCENE.onnx")
    ap.add_argument("--size", default="1024x768", help="the window, WxH (wider than tall)")
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--out", default=None)
    a = ap.parse_args()

    from diviewer.evaluation.evaluate import score
    from diviewer.frames import parse_resolution
    from diviewer.gl.context import headless_context
    from diviewer.gl.renderer import Renderer
    from diviewer.reference.mitsuba import render_full
    from diviewer.runtime import NeuralGI, pack_buffers
    from diviewer.scene import load_scene, sample_config

    scene = load_scene(a.scene)
    model = NeuralGI(a.model or ROOT / "assets" / "models" / f"{a.scene}.onnx", scene=scene)
    mw, mh = model.resolution
    ww, wh = parse_resolution(a.size, "--size")
    gw = round(ww * mh / wh)  # square texels, the window's height at the model's rows
    pw = -(-gw // model.multiple) * model.multiple
    if gw <= mw or gw > 2 * mw:
        sys.exit(f"--size {a.size}: wants a window between 1 and 2 times as wide as tall at the model's rows")
    exposure = float(model.meta["encoding"]["exposure"])
    configs = [("default", scene.default)] + [(f"test seed {s}", sample_config(scene, seed=s, split="test"))
                                              for s in (3, 11)]
    rows: dict[str, list[float]] = {}
    with headless_context() as ctx:
        r = Renderer(ctx, scene, gw, mh)
        try:
            for _, cfg in configs:
                f = r.frame(cfg)
                truth = render_full(scene, cfg, gw, mh, spp=a.spp, seed=1)
                x = pack_buffers(f)
                out = {}
                cols = ((np.arange(mw) + 0.5) * gw / mw).astype(int)
                back = ((np.arange(gw) + 0.5) * mw / gw).astype(int)
                out["squash to the model's size (the viewer)"] = model.run(np.ascontiguousarray(x[:, cols]))[:, back]
                left, right = model.run(np.ascontiguousarray(x[:, :mw])), model.run(np.ascontiguousarray(x[:, gw - mw:]))
                w = np.clip((np.arange(gw) - (gw - mw)) / (2 * mw - gw), 0.0, 1.0)[None, :, None]
                tiles = np.zeros((mh, gw, 3), np.float32)
                tiles[:, :mw] += left * (1 - w[:, :mw])
                tiles[:, gw - mw:] += right * w[:, gw - mw:]
                out["two square tiles, blended"] = tiles
                for mode in ("reflect", "edge"):
                    lo = (pw - gw) // 2
                    xp = np.pad(x, ((0, 0), (lo, pw - gw - lo), (0, 0)), mode=mode)
                    out[f"padded to {pw}x{mh} ({mode}), cropped"] = model.run(np.ascontiguousarray(xp))[:, lo:lo + gw]
                out["direct light only"] = f["direct"]
                for k, v in out.items():
                    rows.setdefault(k, []).append(score(v, truth, exposure)["psnr_tm"])
        finally:
            r.release()
    result = {"scene": a.scene, "window": [ww, wh], "square_texel_gi": [gw, mh], "spp": a.spp,
              "configs": [c for c, _ in configs], "psnr_tm": rows,
              "mean_psnr_tm": {k: float(np.mean(v)) for k, v in rows.items()}}
    print(f"{a.scene}, {ww}x{wh} window, scored at {gw}x{mh} against Mitsuba {a.spp} spp (tone-mapped PSNR):")
    for k, v in rows.items():
        print(f"  {k:42s} " + " ".join(f"{x:6.2f}" for x in v) + f"   mean {np.mean(v):6.2f}")
    if a.out:
        Path(a.out).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
