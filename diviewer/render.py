"""`diviewer render`: one configuration of a scene to image files (each buffer as EXR + PNG, frame.json)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.errors import DiviewerError
from diviewer.frames import frame_record, load_frame_json, parse_resolution, read_frame_json, with_user_meshes
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
    from diviewer.gl.context import describe, headless_context
    from diviewer.gl.display import DEFAULT_TONEMAP, DisplayPass
    from diviewer.gl.renderer import BUFFERS, Renderer, RenderSettings

    tonemap = tonemap or DEFAULT_TONEMAP

    scene = load_scene(scene_name)
    net = None
    if model is not None:
        from diviewer.runtime import NeuralGI

        net = NeuralGI(model, scene=scene, provider=provider)
    if res is None:
        res = "x".join(str(x) for x in net.resolution) if net else "256"
    width, height = parse_resolution(res)
    if net is not None:
        net.check_size(width, height)
    scene, config, stored = choose_config(scene, seed, split, config_file)
    user_meshes = stored.get("user_meshes")
    settings = RenderSettings()
    neural_info = None
    with headless_context() as ctx:
        renderer = Renderer(ctx, scene, width, height, settings)
        compositor = DisplayPass(ctx, renderer.shaders)
        neural = vx = None
        vxgi_info = None
        try:
            frame = renderer.frame(config)
            if vxgi is not None:
                from diviewer.gl.context import stage_timer
                from diviewer.gl.vxgi import VXGIPass

                vx = VXGIPass(ctx, renderer, vxgi, timer=stage_timer(ctx, sync=True))
                vx.run(config)
                frame["vxgi"], frame["vxgi_indirect"] = vx.read("vxgi"), vx.read("vxgi_indirect")
                vxgi_info = {"settings": settings_dict(vxgi), "fragments": vx.fragment_counts,
                             "ms": {k: round(v, 3) for k, v in vx.timings.items()}}
            if net is not None:
                from diviewer.gl.neural import NeuralPass

                neural = NeuralPass(ctx, renderer, net)
                neural.run()
                frame["neural"] = neural.image()
                neural_info = {"model": str(model), "provider": net.provider, "target": net.meta["target"],
                               "K": net.meta["K"], "ms": {k: round(v, 3) for k, v in neural.timings.items()}}
            ev = scene.exposure if exposure is None else exposure
            out.mkdir(parents=True, exist_ok=True)
            for name in BUFFERS:
                imageio.write_exr(out / f"{name}.exr", frame[name])
            imageio.write_png(out / "depth.png", imageio.depth_preview(frame["depth"]))
            imageio.write_png(out / "normal.png", imageio.normal_preview(frame["normal"]))
            imageio.write_png(out / "albedo.png", srgb8(frame["albedo"]))
            imageio.write_png(out / "direct.png", compositor.to_ldr(frame["direct"], ev, tonemap))
            if "neural" in frame:
                imageio.write_exr(out / "neural.exr", frame["neural"])
                imageio.write_png(out / "neural.png", compositor.to_ldr(frame["neural"], ev, tonemap))
            if "vxgi" in frame:
                for name in ("vxgi", "vxgi_indirect"):
                    imageio.write_exr(out / f"{name}.exr", frame[name])
                    imageio.write_png(out / f"{name}.png", compositor.to_ldr(frame[name], ev, tonemap))
            record = frame_record(scene, config, (width, height), seed=seed, split=split if seed is not None else None,
                                  gl_renderer=describe(ctx), render_settings=settings_dict(settings),
                                  display={"exposure": ev, "tonemap": tonemap}, neural=neural_info,
                                  user_meshes=user_meshes, **({"vxgi": vxgi_info} if vxgi_info else {}))
        finally:
            if vx is not None:
                vx.release()
            if neural is not None:
                neural.release()
            compositor.release()
            renderer.release()
    imageio.write_text(out / "frame.json", json.dumps(record, indent=2))
    bad = [n for n in (*BUFFERS, "neural", "vxgi", "vxgi_indirect") if n in frame and not np.all(np.isfinite(frame[n]))]
    if bad:
        raise DiviewerError(f"the GL renderer produced non-finite values in {', '.join(bad)}")
    return record


REFERENCES = ("pt",)
"""Ground-truth renderers `diviewer render --reference` knows: pt = Mitsuba 3 path tracer."""


def check_reference(reference: str) -> None:
    """Fail early (before any GL work) when a reference renderer's extra is not installed."""
    if reference not in REFERENCES:
        raise DiviewerError(f"unknown reference '{reference}'; choose one of {', '.join(REFERENCES)}", field="--reference")
    from diviewer.reference.mitsuba import _import_mitsuba

    _import_mitsuba()


def render_reference_to_dir(scene_name: str, out: Path, reference: str = "pt", spp: int = 256,
                            max_depth: int | None = None, noise_floor: bool = False, pt_seed: int = 0) -> dict:
    """Path-trace the frame that ``render_to_dir`` wrote into ``out`` (its frame.json) beside its buffers.

    Writes pt.exr (full GI), pt_direct.exr (path length 2, same seed), pt_indirect.exr (full - direct)
    and their PNG previews, and adds a ``reference`` table to frame.json (variant, spp, seed, seconds,
    and with ``noise_floor`` the PSNR/SSIM against a second render with seed ``pt_seed + 1``).

    Returns:
        The ``reference`` table.
    """
    import time

    from diviewer.gl.context import headless_context
    from diviewer.gl.display import DEFAULT_TONEMAP, DisplayPass
    from diviewer.gl.shaders import ShaderCache
    from diviewer.reference import mitsuba as ref

    check_reference(reference)
    if spp < 1:
        raise DiviewerError(f"must be at least 1, got {spp}", field="--spp")
    depth = ref.DEFAULT_MAX_DEPTH if max_depth is None else max_depth
    if depth < 2:
        raise DiviewerError(f"must be at least 2 (2 = direct light only), got {depth}", field="--max-depth")
    scene = load_scene(scene_name)
    frame_json = out / "frame.json"
    config = load_frame_json(scene, frame_json)
    record = json.loads(frame_json.read_text())
    width, height = record["resolution"]

    ref.select_variant()
    t0 = time.perf_counter()
    frame = ref.load_frame(scene, config, width, height)
    t_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    full = frame.full(spp, pt_seed, depth)
    t_full = time.perf_counter() - t0
    t0 = time.perf_counter()
    direct = frame.direct(spp, pt_seed)  # the same seed: full - direct is the bounces beyond the first
    t_direct = time.perf_counter() - t0
    indirect = full - direct
    images = {"pt": full, "pt_direct": direct, "pt_indirect": indirect}
    bad = [n for n, im in images.items() if not np.all(np.isfinite(im))]
    if bad:
        raise DiviewerError(f"the path tracer produced non-finite values in {', '.join(bad)}")
    info = ref.variant_info()
    table = {
        "renderer": "mitsuba", "variant": info.variant, "libllvm": info.libllvm, "integrator": "path",
        "spp": ref.effective_spp(spp), "spp_requested": int(spp), "seed": int(pt_seed), "max_depth": depth,
        "rr_depth": ref.path_integrator(depth)["rr_depth"], "sampler": ref.SAMPLER,
        "seconds": {"load": round(t_load, 4), "full": round(t_full, 4), "direct": round(t_direct, 4)},
        "files": {n: f"{n}.exr" for n in images},
    }
    if noise_floor:
        t0 = time.perf_counter()
        second = frame.full(spp, pt_seed + 1, depth)
        table["seconds"]["noise_floor"] = round(time.perf_counter() - t0, 4)
        table["noise_floor"] = ref.compare_renders(full, second, spp=table["spp"], seeds=(pt_seed, pt_seed + 1))

    for name, im in images.items():
        imageio.write_exr(out / f"{name}.exr", im)
    display = record.get("display") or {}
    ev, tonemap = float(display.get("exposure", scene.exposure)), display.get("tonemap", DEFAULT_TONEMAP)
    with headless_context() as ctx:
        compositor = DisplayPass(ctx, ShaderCache(ctx))
        try:
            for name, im in images.items():
                # Noise can make single indirect pixels slightly negative; the preview clamps, the EXR does not.
                imageio.write_png(out / f"{name}.png", compositor.to_ldr(np.maximum(im, 0.0), ev, tonemap))
        finally:
            compositor.release()
    record["reference"] = table
    imageio.write_text(frame_json, json.dumps(record, indent=2))
    return table
