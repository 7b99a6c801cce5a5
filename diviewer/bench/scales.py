"""`diviewer bench --render-scales`: what each render scale of dynamic resolution costs and buys.

The viewer shades the G-buffer, the direct light, the GI upsample and the composite at round(s x window) per side
(`diviewer.viewer.scale.render_size`), runs the network at the size its ``--gi-res model`` policy gives
(`diviewer.viewer.models.gi_sizes`: the training row count in the window's shape, the same at every scale) and the
display pass magnifies the frame to the window bilinearly (averages it above 1). Each scale's row times that frame
per stage as every bench row is timed, and scores its 8-bit display image (the default tone curve at the scene's
exposure, metered on the scale-1 frame where the scene asks for auto exposure, as `diviewer render`'s PNGs) against
the scale-1 frame of the same view at each window size, and against the evaluation set's path-traced truth at the
set's own size.
"""

from __future__ import annotations

import numpy as np

from diviewer.bench.runner import GlBench, per_split, read_final

TRUTH = "vs_truth"


def check_render_scales(scales, resolutions) -> None:
    """Scales the viewer draws at (0 < s <= 2), each shading no more than the size cap at every ``resolutions``."""
    from diviewer.errors import DiviewerError
    from diviewer.fieldspec import MAX_SIZE
    from diviewer.viewer.scale import MAX_SCALE

    bad = [s for s in scales if not 0.0 < s <= MAX_SCALE]
    if bad:
        raise DiviewerError(f"render scales must be in (0, {MAX_SCALE:g}] (shaded pixels per window pixel per "
                            f"side), got {bad}", field="--render-scales")
    big = [(r, s) for r in resolutions for s in scales if round(r * s) > MAX_SIZE]
    if big:
        raise DiviewerError(f"{big[0][1]:g} x --res {big[0][0]} shades more than {MAX_SIZE} px a side; give a "
                            f"smaller scale or --res", field="--render-scales")


def shading_side(window: int, scale: float) -> int:
    """The viewer's shading side at ``scale`` of a square window (`diviewer.viewer.scale.render_size`)."""
    from diviewer.viewer.scale import render_size

    return render_size((window, window), scale)[0]


def model_gi_size(net, shading: int, window: int) -> tuple[int, int]:
    """The GI size the viewer runs ``net`` at under ``--gi-res model`` for a frame shaded at ``shading`` in a
    square ``window``."""
    from diviewer.viewer.models import gi_sizes

    return tuple(gi_sizes(net, "model", (shading, shading), (window, window))[0])


class ScaledFrames:
    """The viewer's frame at one render scale of one square window: shaded, GI, composited, shown at the window."""

    def __init__(self, ctx, scene, mode: str, net, window: int, scale: float):
        from diviewer.gl.shadow_fit import MOVING_SHADOW_SIZE
        from diviewer.viewer.scale import moving_map_size

        self.scene, self.net, self.window, self.scale = scene, net, window, scale
        self.side = shading_side(window, scale)
        self.gi_size = model_gi_size(net, self.side, window) if net is not None else None
        self.gb = GlBench(ctx, scene, self.side, self.side, mode, window=(window, window),
                          moving_shadow_size=moving_map_size(MOVING_SHADOW_SIZE, (self.side, self.side)))

    def time(self, configs, warmup: int) -> dict:
        """Per stage, as the viewer draws a moving frame at this scale (the sun's map at the viewer's moving size)."""
        if self.net is None:
            return self.gb.time_direct(configs, warmup)
        return self.gb.time_model(self.net, configs, warmup, gi_size=self.gi_size)

    def images(self, configs, exposures: list[float] | None) -> tuple[list[np.ndarray], list[float]]:
        """Each configuration's displayed frame (H, W, 3) uint8 at the window size, top row first, and the exposure
        it was shown at: ``exposures``, or where None the scene's, metered on the frame's HDR image at the shading
        size where the scene asks for auto exposure (`display_ev`)."""
        from diviewer.gl.display import read_rgb8

        neural = self.gb.neural_pass(self.net, gi_size=self.gi_size) if self.net is not None else None
        shown, evs = [], []
        try:
            for k, config in enumerate(configs):
                self.gb.renderer.render(config, direct=neural is None)
                if neural is not None:
                    neural.run(**neural.inputs_for(self.scene, config))
                    tex = neural.composite()
                else:
                    tex = self.gb.renderer.textures["direct"]
                if exposures is not None:
                    evs.append(exposures[k])
                else:
                    hdr = read_final(tex) if neural is not None else self.gb.renderer.read("direct")
                    evs.append(display_ev(self.scene, hdr))
                self.gb.present(tex, exposure=evs[-1])
                shown.append(read_rgb8(self.gb.target))
        finally:
            if neural is not None:
                neural.release()
            self.gb.timer.reset()
        return shown, evs

    def release(self) -> None:
        self.gb.release()


def display_ev(scene, hdr: np.ndarray) -> float:
    """The exposure (stops) a frame is shown at: the scene file's, or its meter's reading where it asks for auto
    exposure (`diviewer.exposure.still_ev`, as `diviewer render` meters its PNGs)."""
    from diviewer.exposure import SHOWN, WHITE_POINTS, still_ev
    from diviewer.gl.display import DEFAULT_TONEMAP

    return still_ev(scene.exposure, scene.auto_exposure, hdr, SHOWN, WHITE_POINTS[DEFAULT_TONEMAP])[0]


def _psnrs(images: list[np.ndarray], refs: list[np.ndarray]) -> dict:
    """Display PSNR (8-bit images over [0, 1]) of each image against its reference: per view, min and median (inf:
    identical)."""
    from diviewer.metrics import psnr

    values = [psnr(a / 255.0, b / 255.0) for a, b in zip(images, refs)]
    return {"min": float(min(values)), "median": float(np.median(values)), "per_view": values}


def _views(settings, scene, ds, configs) -> tuple[list, list[int], str]:
    """The views scored: the evaluation set's bench frames (``eval_frames`` per split), or without a set the
    scene's default view and the first three timed configurations."""
    from diviewer.scene.loader import config_from_dict

    if ds is None:
        return [scene.default] + list(configs[:3]), [], "the scene's default view and 3 timed configurations"
    idx = per_split(ds, ds.bench_frames()[0], settings.eval_frames)
    return [config_from_dict(scene, ds.entry(i)["config"]) for i in idx], idx, f"{len(idx)} frames of {ds.root}"


def _frames(ctx, scene, mode, net, window, scale, views, exposures):
    sf = ScaledFrames(ctx, scene, mode, net, window, scale)
    try:
        return sf.images(views, exposures)
    finally:
        sf.release()


def _truth(ctx, scene, mode, net, ds, idx, views, scales, log) -> dict:
    """Per scale, the display PSNR against the path-traced truth at the evaluation set's square size (the truth
    shown through the same display pass, at the exposure of the scale-1 frame of its view)."""
    from diviewer.evaluation.frames import crop_frame

    side = ds.bench_frames()[1][0]
    log(f"render scales against the path-traced truth at {side}x{side} ({len(idx)} frames)")
    sf = ScaledFrames(ctx, scene, mode, net, side, 1.0)
    try:
        ref, evs = sf.images(views, None)  # the truth through the same display pass, at these exposures
        truth = [sf.gb.display.to_ldr(crop_frame(ds.load(i), side)["pt"], ev) for i, ev in zip(idx, evs)]
    finally:
        sf.release()
    out = {}
    for s in scales:
        shown = ref if s == 1.0 else _frames(ctx, scene, mode, net, side, s, views, evs)[0]
        out[s] = {**_psnrs(shown, truth), "resolution": [side, side]}
    return out


def scale_rows(ctx, mode, settings, scene, ds, variants, net_of, configs, notes, log) -> dict:
    """The ``render_scales`` section of the bench's result: per window size (``resolutions``) and scale, the
    frame's timing per stage and its display PSNR against the scale-1 frame (and the truth where there is one)."""
    v = next((v for v in variants if v["kind"] == "neural" and "converted_from" not in v), None)
    net = net_of(v) if v is not None else None
    if net is None:
        notes.append("render scales: no trained model, so the rows show direct light only (the viewer without one)")
    views, idx, described = _views(settings, scene, ds, configs)
    scales = list(settings.render_scales)
    truth = _truth(ctx, scene, mode, net, ds, idx, views, scales, log) if ds is not None else {}
    rows = []
    for res in settings.resolutions:
        log(f"render scales at a {res}x{res} window: {' '.join(f'{s:g}' for s in scales)} "
            f"({len(views)} views scored against scale 1)")
        one = ScaledFrames(ctx, scene, mode, net, res, 1.0)  # the reference frames, and scale 1's row
        try:
            ref, evs = one.images(views, None)
            for s in scales:
                sf = one if s == 1.0 else ScaledFrames(ctx, scene, mode, net, res, s)
                try:
                    timing = sf.time(configs, settings.warmup)
                    shown = ref if sf is one else sf.images(views, evs)[0]
                finally:
                    if sf is not one:
                        sf.release()
                rows.append({"scale": s, "resolution": [res, res], "shading_resolution": [sf.side, sf.side],
                             "gi_resolution": list(sf.gi_size) if sf.gi_size else None, "timing": timing,
                             "vs_scale1": _psnrs(shown, ref), TRUTH: truth.get(s)})
        finally:
            one.release()
    return {"model": v["source"] if v is not None else None, "precision": v["precision"] if v is not None else None,
            "views": described, "frames": [int(i) for i in idx],
            "metric": "display PSNR (dB) of the 8-bit frame at the window size (the default tone curve at the "
                      "scene's exposure, metered on the scale-1 frame for an auto-exposure scene) against the "
                      "scale-1 frame of the same view (vs_scale1, at each window size; inf/null: identical) and "
                      "against the path-traced truth at the evaluation set's size (vs_truth)",
            "gi_res": "model", "rows": rows}


def table(section: dict) -> list[str]:
    """The render-scale rows for people: timing, shading and GI size, dB against scale 1 and the truth."""
    def db(d):
        if not d:
            return "-"
        f = lambda x: "inf" if x is None or not np.isfinite(x) else f"{x:.2f}"
        return f"{f(d['min'])} / {f(d['median'])}"

    model = section["model"] or "direct light only"
    lines = ["", f"render scales (dynamic resolution, GI at --gi-res model): {model}; {section['views']}",
             f"{'scale':>5} {'window':>6} {'shaded':>6} {'GI':>4} {'ms':>8} {'p95':>8} {'dB vs 1 min/med':>16} "
             f"{'dB vs truth min/med':>20}"]
    for r in section["rows"]:
        t = r["timing"]["frame"]
        gi = r["gi_resolution"][0] if r["gi_resolution"] else "-"
        lines.append(f"{r['scale']:5.2f} {r['resolution'][0]:>6} {r['shading_resolution'][0]:>6} {gi:>4} "
                     f"{t['median']:8.2f} {t['p95']:8.2f} {db(r['vs_scale1']):>16} {db(r[TRUTH]):>20}")
    lines.append("stages (median ms):")
    for r in section["rows"]:
        lines.append(f"  scale {r['scale']:.2f} {r['resolution'][0]:>4}: " +
                     "  ".join(f"{k} {v['median']:.2f}" for k, v in r["timing"]["stages"].items()))
    return lines
