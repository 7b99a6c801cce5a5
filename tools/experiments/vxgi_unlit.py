"""Does VXGI see the light the network misses on the unseen shapes' unlit pixels? Per split and mesh of a full
evaluation set: VXGI's indirect light against the path tracer's, summed over the object's pixels without direct
light (the evaluation set's ``object_unlit``).

Usage: python tools/experiments/vxgi_unlit.py [--evalset DIR] [--grid 64] [--bounces 2] [--out OUT.json]

The ratio sum(VXGI's ``vxgi_indirect``) / sum(pt - pt_direct) over the region: a network misses a shape's light
where its own ratio there falls below its training shapes' (`tools/experiments/unlit_fit.py`); an input that kept
the same ratio on the unseen shapes as on the training ones would carry what they lack. ``indirect_share`` is
sum(pt - pt_direct) / sum(pt) over the region (the region is unlit by the GL light's test, the path tracer's
box-filtered pixel can still hold some direct light at its edges). Measures only.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from diviewer.evaluation.frames import EvalFrames, crop_frame
from diviewer.evaluation.scoring import regions
from diviewer.gl.context import headless_context
from diviewer.gl.renderer import Renderer
from diviewer.gl.vxgi import VXGIPass, VXGISettings
from diviewer.scene import config_from_dict
from diviewer.data.scales import dataset_scene
from unlit_edges import centre_mesh  # this folder


def measure(ev: EvalFrames, settings: VXGISettings) -> dict:
    scene = dataset_scene(ev.ds)
    out = {}
    with headless_context() as ctx:
        for split, shapes in ev.splits().items():
            w, h = shapes[0]
            renderer = Renderer(ctx, scene, w, h)
            vxgi = VXGIPass(ctx, renderer, settings)
            sums: dict[str, np.ndarray] = {}
            for i in ev.present(split, []):
                f = crop_frame(ev.load(i), w)
                m = regions(f, ev.exposure)["object_unlit"]
                if not m.any():
                    continue
                config = config_from_dict(scene, ev.entry(i)["config"])
                renderer.render(config)
                vxgi.run(config)
                s = sums.setdefault(centre_mesh(ev.entry(i)), np.zeros(4))
                s += [vxgi.read("vxgi_indirect")[m].sum(), (f["pt"] - f["pt_direct"])[m].sum(), f["pt"][m].sum(),
                      m.sum()]
            vxgi.release()
            renderer.release()
            out[split] = {mesh: {"vxgi_over_truth": float(s[0] / s[1]), "indirect_share": float(s[1] / s[2]),
                                 "pixels": int(s[3])} for mesh, s in sorted(sums.items())}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--evalset", type=Path, default=Path("runs/cornell/evalset_fly"))
    ap.add_argument("--grid", type=int, default=64, help="VXGI grid resolution")
    ap.add_argument("--bounces", type=int, default=2)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    ev = EvalFrames(a.evalset)
    if not ev.ladder_images():
        raise SystemExit(f"{a.evalset}: the compact evaluation set stores no pt_direct; give a full one")
    settings = VXGISettings(resolution=a.grid, bounces=a.bounces)
    result = {"evalset": str(a.evalset), "vxgi": {"resolution": a.grid, "bounces": a.bounces},
              "splits": measure(ev, settings)}
    for split, rows in result["splits"].items():
        print(f"{split}: " + ", ".join(f"{k} {v['vxgi_over_truth']:.3f} (share {v['indirect_share']:.2f}, "
                                       f"{v['pixels']} px)" for k, v in rows.items()))
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
