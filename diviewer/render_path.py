"""`diviewer render --path`: every frame of a camera path as PNG (and EXR), a JSON record each, and an mp4.

The frames go to ``OUT/frames/NNNNNN.png`` with ``NNNNNN.json`` (the frame.json record: time, camera, the whole
configuration) written after it; a frame whose PNG and complete record are there is not drawn again, so a killed
run resumes where it stopped. ``OUT/path_render.json`` holds the settings (and the exposure metered on the first
frame, so every frame and a resumed run share it); a folder holding another render's frames is refused. The video is
made from the PNGs at the end (imageio + imageio-ffmpeg), written under a temporary name and then renamed.
The GL buffers, the neural pass and the path tracer are `diviewer.render`'s own.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from diviewer.errors import DiviewerError

METHODS = ("direct", "neural", "reference")
"""What `--compare` may tile: the GL direct light, the model's image, Mitsuba's path-traced reference."""
LABEL_HEIGHT = 14
"""Pixels of the caption strip above each tile of a comparison."""


def parse_compare(text: str | None, model) -> tuple[str, ...]:
    """``--compare direct,neural,reference`` as a tuple (default: the neural image with a model, else the direct
    light), checked before any work: known names, a model for ``neural``, Mitsuba for ``reference``."""
    if not text:
        return ("neural",) if model is not None else ("direct",)
    methods = tuple(m.strip() for m in str(text).split(",") if m.strip())
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods or len(set(methods)) != len(methods):
        raise DiviewerError(f"takes distinct names among {', '.join(METHODS)} separated by commas, got '{text}'",
                            field="--compare")
    if "neural" in methods and model is None:
        raise DiviewerError("'neural' needs a model: give --model MODEL.onnx", field="--compare")
    if "reference" in methods:
        from diviewer.render import check_reference

        check_reference("pt")  # names the 'train' extra when Mitsuba is missing
    return methods


def check_video(video: Path | None, inputs: tuple = ()) -> Path | None:
    """An mp4 file name that can be written (the one rule of every writer), or None."""
    if video is None:
        return None
    from diviewer.outputs import check_output_file

    video = check_output_file(video, "--video", protect=inputs, suffix=".mp4")
    if video.parent.is_dir():  # permissions alone do not tell (a read-only mount, /proc): try a file there
        import tempfile

        try:
            fd, probe = tempfile.mkstemp(prefix=f".{video.stem}.", suffix=".probe", dir=video.parent)
            os.close(fd)
            os.unlink(probe)
        except OSError as exc:
            raise DiviewerError(f"cannot write in {video.parent}: {exc.strerror or exc}", path=video,
                                field="--video") from None
    return video


def render_path(scene_name: str, path_file: Path, out: Path, *, frames: int | None = None, fps: float | None = None,
                res: str | None = None, video: Path | None = None, compare: str | None = None, spp: int = 256,
                exr: bool = False, model: Path | None = None, provider: str | None = None,
                exposure: float | None = None, tonemap: str | None = None, max_depth: int | None = None,
                pt_seed: int = 0) -> dict:
    """Render every frame of a camera path file into ``out`` (resuming), then the video. Returns the settings record."""
    from diviewer.console import progress_bar
    from diviewer.frames import parse_resolution
    from diviewer.gl.display import DEFAULT_TONEMAP
    from diviewer.outputs import check_output_dir
    from diviewer.scene import load_scene
    from diviewer.scene.camera_path import frame_times, frames_per_second, read_path

    if fps is not None and not (math.isfinite(fps) and fps > 0):
        raise DiviewerError(f"must be a positive number of frames per second, got {fps}", field="--fps")
    if frames is not None and fps is not None:
        raise DiviewerError("give --frames or --fps, not both", field="--fps")
    out = check_output_dir(out, "--out")
    video = check_video(video, (path_file,))
    scene = load_scene(scene_name)
    path, scene = read_path(path_file, scene)
    methods = parse_compare(compare, model)
    net = None
    if model is not None:
        from diviewer.contract.runtime import NeuralGI

        net = NeuralGI(model, scene=scene, provider=provider)
    width, height = parse_resolution(res or ("x".join(map(str, net.resolution)) if net else "256"))
    if net is not None:
        net.check_size(width, height)
    times = frame_times(path, frames, fps)
    rate = frames_per_second(path, frames, fps)
    settings = {"path": str(path_file), "scene": scene.name, "scene_hash": scene.file_hash, "resolution": [width, height],
                "times": times, "fps": rate, "methods": list(methods), "model": str(model) if model else None,
                "spp": spp if "reference" in methods else None, "max_depth": max_depth, "pt_seed": pt_seed,
                "tonemap": tonemap or DEFAULT_TONEMAP, "exr": bool(exr), "exposure": exposure}
    settings = _resume_settings(out / "path_render.json", settings)
    todo = [i for i in range(len(times)) if not _frame_done(out, i, times[i], (width, height), len(methods))]
    bar = progress_bar(len(times), "render", "frame", initial=len(times) - len(todo))  # a resumed run starts there
    try:
        if todo:
            _render_frames(scene, path, out, todo, settings, methods, net, bar)
    finally:
        bar.close()
    if video is not None:
        write_video(video, [_png(out, i) for i in range(len(times))], rate)
    return settings


def _png(out: Path, i: int) -> Path:
    return out / "frames" / f"{i:06d}.png"


def _resume_settings(file: Path, settings: dict) -> dict:
    """The settings of the render in ``out``: these, or the ones found there when they agree (a resumed run keeps
    their exposure); a folder holding frames of another render is refused."""
    from diviewer.imageio import write_text
    from diviewer.outputs import dumps

    if file.is_file():
        try:
            found = json.loads(file.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise DiviewerError(f"cannot read the render's settings: {exc}; remove it or give another --out",
                                path=file) from exc
        differ = [k for k in settings if k != "exposure" and found.get(k) != settings[k]]
        if settings["exposure"] is not None and found.get("exposure") not in (None, settings["exposure"]):
            differ.append("exposure")
        if differ:
            raise DiviewerError(f"the folder holds frames of another render ({', '.join(differ)} differ); give another "
                                "--out, or the same options to resume it", path=file, field=differ[0])
        return found
    write_text(file, dumps(settings, indent=1))
    return settings


def _frame_done(out: Path, i: int, t: float, size: tuple[int, int], tiles: int) -> bool:
    """Whether frame i's PNG and its complete record are there (a frame cut short is drawn again)."""
    png, record = _png(out, i), _png(out, i).with_suffix(".json")
    if not (png.is_file() and record.is_file()):
        return False
    try:
        data = json.loads(record.read_text())
        from diviewer.imageio import read_png

        shape = read_png(png).shape
    except (OSError, ValueError):
        return False
    w, h = size
    want = (h + (LABEL_HEIGHT if tiles > 1 else 0), w * tiles, 3)
    return data.get("complete") is True and data.get("index") == i and data.get("time") == t and shape == want


def _render_frames(scene, path, out: Path, todo: list[int], settings: dict, methods, net, bar) -> None:
    from diviewer.gl.context import check_render_size, describe, headless_context
    from diviewer.gl.display import DisplayPass
    from diviewer.gl.renderer import RenderSettings, Renderer
    from diviewer.imageio import write_text
    from diviewer.outputs import dumps
    from diviewer.provenance import settings_dict

    width, height = settings["resolution"]
    render_settings = RenderSettings().for_scene(scene)
    if "reference" in methods:
        from diviewer.reference import mitsuba as ref

        ref.select_variant()
    with headless_context() as ctx:
        check_render_size(ctx, width, height, "--res")
        renderer = Renderer(ctx, scene, width, height, render_settings)
        compositor = DisplayPass(ctx, renderer.shaders)
        made = {"gl_renderer": describe(ctx), "render_settings": settings_dict(render_settings)}  # every frame's
        try:
            for i in todo:
                t = settings["times"][i]
                config = path.config_at(t, scene.default)
                images, info = _method_images(ctx, scene, renderer, net, config, methods, settings)
                if settings["exposure"] is None:  # metered once, on the first frame drawn, then kept
                    from diviewer.render import display_exposure

                    # the neural image's, else direct, with the highlights kept for the chosen tone curve
                    settings["exposure"] = display_exposure(scene, images, None, settings["tonemap"])[0]
                    write_text(out / "path_render.json", dumps(settings, indent=1))
                _write_frame(out, i, t, scene, config, images, methods, compositor, settings, {**made, **info})
                bar.update(1)
        finally:
            compositor.release()
            renderer.release()


def _method_images(ctx, scene, renderer, net, config, methods, settings) -> tuple[dict, dict]:
    """Each method's linear radiance image of ``config`` (the direct light always), and what the record says of them."""
    from diviewer.render import check_finite, model_pass

    frame = renderer.frame(config)
    images, info = {"direct": frame["direct"]}, {}
    if "neural" in methods:
        neural = model_pass(ctx, scene, renderer, net, config)  # the renderer's buffers blank after: read above
        try:
            images["neural"] = neural.image()
            info["neural"] = {"model": settings["model"], "provider": net.provider, "K": net.meta["K"]}
        finally:
            neural.release()
    check_finite(scene, config, images, tuple(images))
    if "reference" in methods:
        from diviewer.reference import mitsuba as ref

        depth = ref.DEFAULT_MAX_DEPTH if settings["max_depth"] is None else settings["max_depth"]
        mf = ref.load_frame(scene, config, renderer.width, renderer.height)
        images["reference"] = mf.full_light(settings["spp"], settings["pt_seed"], depth)
        info["reference"] = {"renderer": "mitsuba", "variant": ref.variant_info().variant,
                             "spp": ref.effective_spp(settings["spp"]), "seed": settings["pt_seed"], "max_depth": depth}
    return images, info


def _write_frame(out: Path, i: int, t: float, scene, config, images: dict, methods, compositor, settings: dict,
                 info: dict) -> None:
    """Frame i's PNG (the methods side by side, captioned when there are several), EXRs on request, and its record
    last: all under temporary names, renamed together."""
    from diviewer import imageio
    from diviewer.frames import frame_record
    from diviewer.outputs import dumps, staged

    ev, tonemap = settings["exposure"], settings["tonemap"]
    tiles = [compositor.to_ldr(np.maximum(images[m], 0.0), ev, tonemap) for m in methods]
    picture = label_tiles(tiles, methods) if len(methods) > 1 else tiles[0]
    png = _png(out, i)
    record = frame_record(scene, config, tuple(settings["resolution"]), index=i, time=t, path=settings["path"],
                          methods=list(methods), display={"exposure": ev, "tonemap": tonemap}, **info)
    record["complete"] = True
    with staged() as stage:
        imageio.write_png(stage(png), picture)
        if settings["exr"]:
            for m in methods:
                imageio.write_exr(stage(png.with_name(f"{i:06d}_{m}.exr")), np.ascontiguousarray(images[m]))
        imageio.write_text(stage(png.with_suffix(".json")), dumps(record, indent=1))


def label_tiles(tiles: list[np.ndarray], labels) -> np.ndarray:
    """uint8 images side by side, each under a caption strip with its name."""
    from PIL import Image, ImageDraw

    h, w = tiles[0].shape[:2]
    canvas = Image.new("RGB", (w * len(tiles), h + LABEL_HEIGHT), (0, 0, 0))
    draw = ImageDraw.Draw(canvas)
    for k, (tile, label) in enumerate(zip(tiles, labels)):
        canvas.paste(Image.fromarray(np.ascontiguousarray(tile)), (k * w, LABEL_HEIGHT))
        draw.text((k * w + 3, 1), str(label), fill=(255, 255, 255))
    return np.asarray(canvas)


def write_video(video: Path, pngs: list[Path], fps: float) -> None:
    """An H.264 mp4 of the PNGs at ``fps`` (sides padded to even numbers, as yuv420p needs), written under a temporary
    name beside ``video`` and renamed into place (`diviewer.imageio.atomic_path`)."""
    import imageio.v2 as iio

    from diviewer.imageio import atomic_path, read_png

    with atomic_path(video) as tmp:
        with iio.get_writer(str(tmp), format="FFMPEG", fps=fps, codec="libx264", pixelformat="yuv420p", quality=8,
                            macro_block_size=1, ffmpeg_log_level="error") as writer:
            for png in pngs:
                image = read_png(png)
                pad = ((0, image.shape[0] % 2), (0, image.shape[1] % 2), (0, 0))
                writer.append_data(np.pad(image, pad, mode="edge"))
