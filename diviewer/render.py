"""`diviewer render`: one configuration of a scene to image files (each buffer as EXR + PNG, frame.json)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.errors import DiviewerError
from diviewer.provenance import settings_dict, versions
from diviewer.scene import FrameConfig, Scene, config_from_dict, load_scene, sample_config


def parse_resolution(text: str) -> tuple[int, int]:
    """``256`` (square) or ``320x240`` (width x height)."""
    try:
        parts = [int(p) for p in str(text).lower().split("x")]
    except ValueError:
        parts = []
    if len(parts) == 1:
        parts = parts * 2
    if len(parts) != 2 or min(parts) < 1 or max(parts) > 16384:
        raise DiviewerError(f"resolution must be N or WxH with 1 <= N <= 16384, got '{text}'", field="--res")
    return parts[0], parts[1]


def load_frame_json(scene: Scene, path: Path) -> FrameConfig:
    """The configuration stored in a frame.json (or a viewer screenshot's JSON)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise DiviewerError(f"cannot read frame configuration: {exc}", path=path) from exc
    if "config" not in data:
        raise DiviewerError("missing the 'config' table written by diviewer render", path=path, field="config")
    if data.get("scene_hash") and data["scene_hash"] != scene.file_hash:
        raise DiviewerError(f"this frame was made with another version of scene '{data.get('scene')}' "
                            f"(scene file hash differs)", path=path, field="scene_hash")
    return config_from_dict(scene, data["config"], path=path)


def choose_config(scene: Scene, seed: int | None, split: str, config_file: Path | None) -> FrameConfig:
    if config_file is not None:
        return load_frame_json(scene, config_file)
    if seed is None:
        return scene.default
    return sample_config(scene, seed, split)


def frame_record(scene: Scene, config: FrameConfig, size: tuple[int, int], **extra) -> dict:
    """The frame.json content: enough to render the same frame again."""
    return {
        "scene": scene.name,
        "scene_file": str(scene.path) if scene.path else None,
        "scene_hash": scene.file_hash,
        "resolution": list(size),
        **extra,
        "config": config.to_dict(),
        "versions": versions(),
    }


def render_to_dir(scene_name: str, out: Path, res: str = "256", seed: int | None = None, split: str = "train",
                  config_file: Path | None = None, exposure: float | None = None, tonemap: str = "aces") -> dict:
    """Render one frame's GL buffers and write them; returns the frame record."""
    from diviewer.gl.context import create_context, describe
    from diviewer.gl.renderer import BUFFERS, Compositor, Renderer, RenderSettings

    scene = load_scene(scene_name)
    width, height = parse_resolution(res)
    config = choose_config(scene, seed, split, config_file)
    settings = RenderSettings()
    ctx = create_context()
    renderer = Renderer(ctx, scene, width, height, settings)
    compositor = Compositor(ctx, renderer.shaders)
    try:
        frame = renderer.frame(config)
        ev = scene.exposure if exposure is None else exposure
        out.mkdir(parents=True, exist_ok=True)
        for name in BUFFERS:
            imageio.write_exr(out / f"{name}.exr", frame[name])
        imageio.write_png(out / "depth.png", imageio.depth_preview(frame["depth"]))
        imageio.write_png(out / "normal.png", imageio.normal_preview(frame["normal"]))
        imageio.write_png(out / "albedo.png", imageio.srgb8(frame["albedo"]))
        imageio.write_png(out / "direct.png", compositor.to_ldr(frame["direct"], ev, tonemap))
        record = frame_record(scene, config, (width, height), seed=seed, split=split if seed is not None else None,
                              gl_renderer=describe(ctx), render_settings=settings_dict(settings),
                              display={"exposure": ev, "tonemap": tonemap})
        imageio.write_text(out / "frame.json", json.dumps(record, indent=2))
        bad = [n for n in BUFFERS if not np.all(np.isfinite(frame[n]))]
        if bad:
            raise DiviewerError(f"the GL renderer produced non-finite values in {', '.join(bad)}")
        return record
    finally:
        compositor.release()
        renderer.release()
        ctx.release()
