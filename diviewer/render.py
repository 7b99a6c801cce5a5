"""`diviewer render`: one configuration of a scene to image files (each buffer as EXR + PNG, frame.json)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.errors import DiviewerError
from diviewer.frames import frame_record, parse_resolution, read_frame_json, with_user_meshes
from diviewer.outputs import check_output_dir, dumps, staged
from diviewer.provenance import settings_dict
from diviewer.scene import FrameConfig, Scene, config_from_dict, load_scene, sample_config
from diviewer.scene.colour import srgb8


def choose_config(scene: Scene, seed: int | None, split: str, config_file: Path | None) -> tuple[Scene, FrameConfig, dict]:
    """The frame to render: a stored frame.json (its scene gains the mesh files it records), the
    default pose, or one drawn with ``seed``. Also returns what the frame.json recorded ({} otherwise)."""
    if config_file is not None:
        data = read_frame_json(scene, config_file)  # read once: meshes, configuration, record
        scene = with_user_meshes(scene, data)
        return scene, config_from_dict(scene, data["config"], path=config_file), data
    if seed is None:
        return scene, scene.default, {}
    return scene, sample_config(scene, seed, split), {}


def render_to_dir(scene_name: str, out: Path, res: str | None = "256", seed: int | None = None, split: str = "train",
                  config_file: Path | None = None, exposure: float | None = None, tonemap: str | None = None,
                  model: Path | None = None, provider: str | None = None, vxgi=None) -> dict:
    """Render one frame's GL buffers (and, with a model, its neural GI image) and write them.

    Args:
        res: N or WxH; None means the model's training resolution (or 256 without a model).
        model: an ONNX model from `diviewer export`, checked against the scene; writes neural.exr.
        vxgi: a VXGISettings: also run voxel cone tracing; writes vxgi.exr (direct + albedo x indirect)
            and vxgi_indirect.exr (albedo x indirect, comparable with the path tracer's pt_indirect.exr).

    Returns:
        The frame record written to frame.json.
    """
    from diviewer.gl.context import check_render_size, describe, headless_context
    from diviewer.gl.display import DEFAULT_TONEMAP, DisplayPass
    from diviewer.gl.renderer import BUFFERS, Renderer, RenderSettings

    tonemap = tonemap or DEFAULT_TONEMAP

    out = check_output_dir(out, "--out")
    if exposure is not None and not np.isfinite(exposure):
        raise DiviewerError(f"must be a finite number of stops, got {exposure}", field="--exposure")
    scene = load_scene(scene_name)
    net = None
    if model is not None:
        from diviewer.contract.runtime import NeuralGI

        net = NeuralGI(model, scene=scene, provider=provider)
    if res is None:
        res = "x".join(str(x) for x in net.resolution) if net else "256"
    width, height = parse_resolution(res)
    if net is not None:
        net.check_size(width, height)
    scene, config, stored = choose_config(scene, seed, split, config_file)
    user_meshes = stored.get("user_meshes")
    settings = RenderSettings().for_scene(scene)
    neural_info = None
    with headless_context() as ctx:
        check_render_size(ctx, width, height, "--res")
        renderer = Renderer(ctx, scene, width, height, settings)
        compositor = DisplayPass(ctx, renderer.shaders)
        neural = vx = None
        vxgi_info = None
        try:
            frame = renderer.frame(config)
            if vxgi is not None:
                vx, vxgi_info = _vxgi_pass(ctx, renderer, vxgi, config, frame)
            if net is not None:
                neural = model_pass(ctx, scene, renderer, net, config)
                frame["neural"] = neural.image()
                neural_info = {"model": str(model), "provider": net.provider, "target": net.meta["target"],
                               "K": net.meta["K"], "ms": {k: round(v, 3) for k, v in neural.timings.items()}}
                note = net.shape_note(width, height)
                if note:
                    neural_info["shape_note"] = note
                    print(f"diviewer render: note: {note}", file=sys.stderr)
            # Known good before anything is written: an earlier render in --out stays as it was otherwise.
            check_finite(scene, config, frame, (*BUFFERS, "neural", "vxgi", "vxgi_indirect"))
            ev, metered = display_exposure(scene, frame, exposure, tonemap)
            record = frame_record(scene, config, (width, height), seed=seed, split=split if seed is not None else None,
                                  gl_renderer=describe(ctx), render_settings=settings_dict(settings),
                                  display={"exposure": ev, "tonemap": tonemap, **({"metered": metered} if metered else {}),
                                           "clipped": clipped_shares(frame, ev, tonemap)},
                                  neural=neural_info,
                                  user_meshes=user_meshes, **({"vxgi": vxgi_info} if vxgi_info else {}))
            _write_render(out, frame, record, compositor, ev, tonemap)
        finally:
            if vx is not None:
                vx.release()
            if neural is not None:
                neural.release()
            compositor.release()
            renderer.release()
    return record


def display_exposure(scene: Scene, frame: dict[str, np.ndarray], exposure: float | None,
                     tonemap: str = "aces") -> tuple[float, str | None]:
    """The PNGs' exposure (stops) and, where it was metered, the image it was metered on: ``exposure`` if given,
    else the scene file's, or for a scene that asks for auto exposure the viewer's meter
    (`diviewer.exposure.metered_ev` with `SHOWN`, highlights kept for ``tonemap``) on the frame shown (the neural
    composite, else the direct light)."""
    if exposure is not None:
        return exposure, None
    from diviewer.exposure import SHOWN, WHITE_POINTS, still_ev

    shown = "neural" if "neural" in frame else "direct"
    ev, metered = still_ev(scene.exposure, scene.auto_exposure, frame[shown], SHOWN, WHITE_POINTS[tonemap])
    return ev, (shown if metered else None)


def clipped_shares(frame: dict[str, np.ndarray], ev: float, tonemap: str) -> dict[str, float]:
    """Per radiance image of ``frame``, the share of its pixels its PNG shows as white (`clipped_share`)."""
    from diviewer.exposure import WHITE_POINTS, clipped_share

    return {name: round(clipped_share(frame[name], ev, WHITE_POINTS[tonemap]), 6)
            for name in ("direct", "neural", "vxgi") if name in frame}


def _vxgi_pass(ctx, renderer, vxgi, config, frame: dict):
    """Voxel cone tracing of ``config`` into ``frame`` (vxgi, vxgi_indirect); returns the pass and its record."""
    from diviewer.gl.context import stage_timer
    from diviewer.gl.vxgi import VXGIPass

    vx = VXGIPass(ctx, renderer, vxgi, timer=stage_timer(ctx, sync=True))
    vx.run(config)
    frame["vxgi"], frame["vxgi_indirect"] = vx.read("vxgi"), vx.read("vxgi_indirect")
    return vx, {"settings": settings_dict(vxgi), "fragments": vx.fragment_counts,
                "ms": {k: round(v, 3) for k, v in vx.timings.items()}}


def _write_render(out: Path, frame: dict, record: dict, compositor, ev: float, tonemap: str) -> None:
    """A render's buffers (EXR), previews (PNG) and frame.json, all under temporary names first and then renamed
    together: a failure part-way (a full disk) leaves the folder as it was."""
    from diviewer.gl.renderer import BUFFERS

    with staged() as stage:
        for name in BUFFERS:
            imageio.write_exr(stage(out / f"{name}.exr"), frame[name])
        imageio.write_png(stage(out / "depth.png"), imageio.depth_preview(frame["depth"]))
        imageio.write_png(stage(out / "normal.png"), imageio.normal_preview(frame["normal"]))
        imageio.write_png(stage(out / "albedo.png"), srgb8(frame["albedo"]))
        imageio.write_png(stage(out / "direct.png"), compositor.to_ldr(frame["direct"], ev, tonemap))
        for name in ("neural", "vxgi", "vxgi_indirect"):
            if name in frame:
                imageio.write_exr(stage(out / f"{name}.exr"), frame[name])
                imageio.write_png(stage(out / f"{name}.png"), compositor.to_ldr(frame[name], ev, tonemap))
        imageio.write_text(stage(out / "frame.json"), dumps(record, indent=2))

def model_pass(ctx, scene: Scene, renderer, net, config: FrameConfig):
    """The model run on ``config`` at ``renderer``'s size (the model pads it to its stride); returns the pass (the
    caller releases it). A model of the direct light over each pixel's area (``direct_samples`` s > 1,
    `diviewer.gl.area`) takes its inputs from the same renderer drawing ``config`` at s x s times its size, the
    direct light averaged over each pixel's block (`pack.glsl`'s AREA_DIRECT); the renderer then takes its own
    size back with its buffers blank (read them before)."""
    from diviewer.gl.context import check_render_size
    from diviewer.gl.neural import NeuralPass

    width, height, s = renderer.width, renderer.height, net.direct_samples
    if s > 1:
        check_render_size(ctx, width * s, height * s, "--res")
        renderer.resize(width * s, height * s)
    try:
        if s > 1:
            renderer.render(config)
        neural = NeuralPass(ctx, renderer, net, gi_size=(width, height))
        neural.run(**neural.inputs_for(scene, config), frame=renderer.buffers(samples=s))
    finally:
        renderer.resize(width, height)
    return neural


def check_finite(scene: Scene, config: FrameConfig, frame: dict, names) -> None:
    """Refuse a frame with NaN/Inf in any buffer, naming the light or material that overflowed float32."""
    bad = [n for n in names if n in frame and not np.all(np.isfinite(frame[n]))]
    if not bad:
        return
    # The loader keeps every field within float32, but products (intensity / distance^2) can still
    # overflow: point at the strongest emitter, which is what the user can change.
    strengths = [(max(l.color) * (l.irradiance if hasattr(l, "irradiance") else l.intensity),
                  f"lights[{i}].{'irradiance' if hasattr(l, 'irradiance') else 'intensity'}")
                 for i, l in enumerate(config.lights)]
    # A textured emitter's strength is its brightest texel's (its factor times the texture's peak).
    strengths += [(max(m.peak_emission), f"materials.{k}.emission") for k, m in scene.materials.items()]
    hint = ""
    if strengths:
        value, field = max(strengths)
        hint = f"; the strongest emitter is {field} = {value:.3g}: lower it"
    raise DiviewerError(f"the GL renderer produced non-finite values in {', '.join(bad)} (float32 overflow){hint}; "
                        f"nothing was written", path=scene.path)


REFERENCES = ("pt",)
"""Ground-truth renderers `diviewer render --reference` knows: pt = Mitsuba 3 path tracer."""


def check_reference(reference: str) -> None:
    """Fail early (before any GL work) when a reference renderer's extra is not installed."""
    if reference not in REFERENCES:
        raise DiviewerError(f"unknown reference '{reference}'; choose one of {', '.join(REFERENCES)}", field="--reference")
    from diviewer.reference.mitsuba import import_mitsuba

    import_mitsuba()


def render_reference_to_dir(scene_name: str, out: Path, reference: str = "pt", spp: int = 256,
                            max_depth: int | None = None, noise_floor: bool = False, pt_seed: int = 0) -> dict:
    """Path-trace the frame that ``render_to_dir`` wrote into ``out`` (its frame.json) beside its buffers.

    Writes pt.exr (full GI), pt_direct.exr (path length 2, the same paths), pt_indirect.exr (full - direct)
    and their PNG previews, and adds a ``reference`` table to frame.json (variant, spp, seed, seconds,
    and with ``noise_floor`` the PSNR/SSIM against a second render with seed ``pt_seed + 1``).

    Returns:
        The ``reference`` table.
    """
    import time

    from diviewer.exposure import WHITE_POINTS, clipped_share
    from diviewer.gl.context import headless_context
    from diviewer.gl.display import DisplayPass
    from diviewer.gl.shaders import ShaderCache
    from diviewer.reference import mitsuba as ref
    from diviewer.reference import split_path

    check_reference(reference)
    if spp < 1:
        raise DiviewerError(f"must be at least 1, got {spp}", field="--spp")
    depth = ref.DEFAULT_MAX_DEPTH if max_depth is None else max_depth
    if depth < 2:
        raise DiviewerError(f"must be at least 2 (2 = direct light only), got {depth}", field="--max-depth")
    scene = load_scene(scene_name)
    frame_json = out / "frame.json"
    record, config, (width, height), (ev, tonemap) = _stored_frame(scene, frame_json)

    ref.select_variant()
    t0 = time.perf_counter()
    frame = ref.load_frame(scene, config, width, height)
    t_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    # from the same paths (one pass, or two with one seed): full - direct is the bounces beyond the first
    full, direct, estimator = frame.full_and_direct(spp, pt_seed, depth)
    t_full = time.perf_counter() - t0
    indirect = full - direct
    images = {"pt": full, "pt_direct": direct, "pt_indirect": indirect}
    bad = [n for n, im in images.items() if not np.all(np.isfinite(im))]
    if bad:
        raise DiviewerError(f"the path tracer produced non-finite values in {', '.join(bad)}")
    info = ref.variant_info()
    table = {
        "renderer": "mitsuba", "variant": info.variant, "libllvm": info.libllvm, "pt_estimator": estimator,
        "integrator": split_path.NAME if estimator == split_path.ONE_PASS else "path",
        "spp": ref.effective_spp(spp), "spp_requested": int(spp), "seed": int(pt_seed), "max_depth": depth,
        "rr_depth": ref.path_integrator(depth)["rr_depth"], "sampler": ref.SAMPLER,
        "seconds": {"load": round(t_load, 4), "full": round(t_full, 4)},  # full: both images
        "files": {n: f"{n}.exr" for n in images},
        "clipped": round(clipped_share(full, float(ev), WHITE_POINTS[tonemap]), 6),  # at the PNGs' exposure
    }
    if noise_floor:
        t0 = time.perf_counter()
        second = frame.full_light(spp, pt_seed + 1, depth)  # the same estimator
        table["seconds"]["noise_floor"] = round(time.perf_counter() - t0, 4)
        table["noise_floor"] = ref.compare_renders(full, second, spp=table["spp"], seeds=(pt_seed, pt_seed + 1))

    record["reference"] = table
    with headless_context() as ctx, staged() as stage:
        compositor = DisplayPass(ctx, ShaderCache(ctx))
        try:
            for name, im in images.items():
                imageio.write_exr(stage(out / f"{name}.exr"), im)
                # Noise can make single indirect pixels slightly negative; the preview clamps, the EXR does not.
                imageio.write_png(stage(out / f"{name}.png"), compositor.to_ldr(np.maximum(im, 0.0), float(ev), tonemap))
        finally:
            compositor.release()
        imageio.write_text(stage(frame_json), dumps(record, indent=2))
    return table


def _stored_frame(scene: Scene, frame_json: Path) -> tuple[dict, FrameConfig, tuple[int, int], tuple[float, str]]:
    """What `render` stored in frame.json, checked before any path tracing: the record, its configuration, its
    [width, height] and its display (exposure, tone map)."""
    from diviewer.gl.display import DEFAULT_TONEMAP

    record = read_frame_json(scene, frame_json)
    config = config_from_dict(scene, record["config"], path=frame_json)
    res = record.get("resolution")
    if not (isinstance(res, list) and len(res) == 2 and all(isinstance(x, int) and x >= 1 for x in res)):
        raise DiviewerError(f"expected [width, height], got {res!r}", path=frame_json, field="resolution")
    display = record.get("display") if isinstance(record.get("display"), dict) else {}
    ev, tonemap = display.get("exposure", scene.exposure), display.get("tonemap", DEFAULT_TONEMAP)
    if isinstance(ev, bool) or not isinstance(ev, (int, float)) or not np.isfinite(ev):
        raise DiviewerError(f"expected a finite number, got {ev!r}", path=frame_json, field="display.exposure")
    if tonemap not in ("clamp", "reinhard", "aces"):
        raise DiviewerError(f"expected clamp, reinhard or aces, got {tonemap!r}", path=frame_json, field="display.tonemap")
    return record, config, (res[0], res[1]), (float(ev), tonemap)
