"""Do the G-buffer and the path tracer cut the same holes with alpha masks? Measured on Sponza's real masks.

Usage: python tools/experiments/alpha_agreement.py [--scene sponza] [--positions 0.05 0.3 0.62 0.9] [--res 128]

At a few positions of the scene's camera path, the GL G-buffer's depth (one sample at each pixel centre) is
compared with the depth of Mitsuba rays through the same pixel centres (`centre_depth`: the path tracer's
scene, its ``mask`` BSDF with the thresholded nearest-texel opacity, traced through cut-out texels as the
path tracer does). Each renderer is run twice, with the masks and with the masked materials made opaque:
the pixels whose depth the masks change are that renderer's "holes". The figures (pixel counts per view,
pooled over the views at the end): the holes' IoU between the renderers, the per-pixel agreement inside
their union, and the agreement on all pixels with and without masks (the second is the geometric
baseline: rasterisation against ray casting at silhouettes).
One path-traced sample per pixel centre: no path-tracing noise enters (masks are binary).
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import numpy as np

AGREE = 0.01
"""Two depths agree within this fraction of the nearer (both misses agree)."""


def opaque(scene):
    """The scene with every alpha-masked material drawn opaque."""
    mats = {k: dataclasses.replace(m, alpha=None) if m.is_masked else m for k, m in scene.materials.items()}
    return dataclasses.replace(scene, materials=mats)


def centre_depth(scene, config, width: int, height: int) -> np.ndarray:
    """(H, W) view-space depth (-z) of the first surface Mitsuba's rays through the pixel centres stop at,
    passing cut-out texels as the path tracer does; 0 where they miss (as the G-buffer)."""
    import drjit as dr
    import mitsuba as mi

    from diviewer.reference import mitsuba as ref
    from diviewer.reference.aovs import _trace
    from diviewer.scene import camera as cam

    frame = ref.MitsubaFrame(scene, config, width, height)
    mi.set_variant(frame.variant)
    sensor = frame._mi_scene.sensors()[0]
    ys, xs = np.mgrid[0:height, 0:width]
    fx = ((xs + 0.5) / width).ravel().astype(np.float32)
    fy = ((ys + 0.5) / height).ravel().astype(np.float32)
    if mi.variant().startswith("scalar"):
        t = []
        for x, y in zip(fx, fy):
            ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(float(x), float(y)), mi.Point2f(0.5, 0.5))
            t.append(float(_trace(mi, dr, frame._mi_scene, mi.Ray3f(ray), lambda: 0.5)[0]))
        t = np.asarray(t, np.float64).reshape(height, width)
    else:
        ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5), mi.Point2f(mi.Float(fx), mi.Float(fy)),
                                   mi.Point2f(0.5, 0.5))
        # opacity is 0 or 1 (thresholded): any uniform number lets a ray through exactly the cut-out texels
        t = np.asarray(_trace(mi, dr, frame._mi_scene, mi.Ray3f(ray), lambda: mi.Float(0.5))[0],
                       np.float64).reshape(height, width)
    c = config.camera
    rays = cam.pixel_rays_view(width, height, c.fov)
    return np.where(t > 0.0, t / np.linalg.norm(rays, axis=-1) + c.near, 0.0)


def gl_depth(ctx, scene, config, width: int, height: int) -> np.ndarray:
    from diviewer.gl.renderer import Renderer, RenderSettings

    r = Renderer(ctx, scene, width, height, RenderSettings(shadows=False))
    try:
        return np.asarray(r.frame(config)["depth"], np.float64)
    finally:
        r.release()


def agree(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    both_miss = (a <= 0) & (b <= 0)
    return both_miss | (np.abs(a - b) <= AGREE * np.maximum(np.minimum(a, b), 1e-9))


def compare(ctx, scene, config, width: int, height: int) -> dict:
    """The figures of one view: holes (pixels the masks change) per renderer, their IoU, agreement."""
    flat = opaque(scene)
    g, g0 = gl_depth(ctx, scene, config, width, height), gl_depth(ctx, flat, config, width, height)
    m, m0 = centre_depth(scene, config, width, height), centre_depth(flat, config, width, height)
    holes_gl, holes_mi = ~agree(g, g0), ~agree(m, m0)
    union = holes_gl | holes_mi
    same = agree(g, m)
    return {"pixels": int(g.size), "holes_gl": int(holes_gl.sum()), "holes_mitsuba": int(holes_mi.sum()),
            "holes_both": int((holes_gl & holes_mi).sum()), "holes_union": int(union.sum()),
            "agree_in_holes": int(same[union].sum()),
            "agree_all_masked": int(same.sum()), "agree_all_opaque": int(agree(g0, m0).sum())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="sponza")
    ap.add_argument("--positions", type=float, nargs="+", default=[0.05, 0.3, 0.62, 0.9],
                    help="camera path parameters in [0, 1]")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args(argv)

    from diviewer.gl.context import headless_context
    from diviewer.reference import mitsuba as ref
    from diviewer.scene import load_scene
    from diviewer.scene.sampler import camera_on_path

    scene = load_scene(args.scene)
    ref.select_variant()
    rows = []
    with headless_context() as ctx:
        for s in args.positions:
            config = dataclasses.replace(scene.default, camera=camera_on_path(scene, s))
            row = {"s": s, **compare(ctx, scene, config, args.res, args.res)}
            rows.append(row)
            print(json.dumps(row))
    t = {k: sum(r[k] for r in rows) for k in rows[0] if k != "s"}
    union = max(t["holes_union"], 1)
    # pooled over the views (a view without masks in sight has no IoU of its own)
    print(json.dumps({"scene": args.scene, "res": args.res, "views": len(rows), **t,
                      "holes_iou": t["holes_both"] / union, "agree_in_holes_share": t["agree_in_holes"] / union,
                      "agree_all_masked_share": t["agree_all_masked"] / t["pixels"],
                      "agree_all_opaque_share": t["agree_all_opaque"] / t["pixels"]}))
    if args.json:
        from diviewer.imageio import write_text

        write_text(args.json, json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
