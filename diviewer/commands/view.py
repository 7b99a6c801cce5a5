"""`diviewer view` on the command line: its arguments, mapped onto ``ViewerSettings``."""

from __future__ import annotations

import argparse
from pathlib import Path

from diviewer.commands.common import add_model, add_number, add_provider, add_scene
from diviewer.errors import DiviewerError
from diviewer.fieldspec import MAX_SIZE
from diviewer.viewer.scale import DEFAULT_FLOOR, MAX_SCALE


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Define ``diviewer view`` on the CLI's subparsers."""
    p = subparsers.add_parser("view", help="fly through a scene with neural GI every frame (window + panel)",
                              description="Open a window on a scene with its neural GI model; "
                                          "the panel lists the keyboard shortcuts.")
    add_scene(p)
    add_model(p, "model file, 'auto' (assets/models/<scene>*.onnx, the first that fits) or 'none'", type=str,
              default="auto")
    p.add_argument("--size", default="768x768", help="window size WxH (or N); default 768x768")
    p.add_argument("--no-vsync", action="store_true", help="do not wait for the display's refresh")
    add_number(p, "--frames", default=None, help="render N frames, then exit (with --screenshot)")
    p.add_argument("--screenshot", type=Path, default=None, help="on exit, save the view as PNG (+ frame JSON)")
    p.add_argument("--window-screenshot", type=Path, default=None,
                   help="with --frames: save what the window shows in the last frame (its back buffer, panel "
                        "included) as PNG")
    add_provider(p, "onnxruntime execution provider (default: the fastest available)")
    p.add_argument("--camera", default="fly", choices=("fly", "orbit"), help="camera controller at start")
    p.add_argument("--gi-res", default="model",
                   help="neural GI resolution: 'model' (its training size, default), a fraction of the window "
                        "(1/2, 1/4, 1/6: snapped to the model's stride) or WxH (a multiple of the stride, else refused)")
    p.add_argument("--gi-downsample", default="nearest", choices=("nearest", "area"),
                   help="how the full-resolution buffers are reduced to the GI resolution (default nearest)")
    p.add_argument("--lean", action=argparse.BooleanOptionalAction, default=True,
                   help="run a model's lean path where it has one: the generator alone in onnxruntime, its encoding "
                        "and decoding in shaders (default); --no-lean runs the whole self-contained graph")
    p.add_argument("--pipelined", action="store_true",
                   help="run inference one frame behind on a worker thread (GL and onnxruntime overlap)")
    add_number(p, "--target-fps", type=float, default=30.0,
               help="hold this frame rate by scaling the shading resolution between --scale-floor and the "
                    "window's size, then upscaling (default 30; 0 turns it off)")
    add_number(p, "--render-scale", type=float, default=None,
               help=f"shade at this fixed multiple of the window's size per side (0 < S <= {MAX_SCALE:g}; above 1 "
                    "supersampled, 2: each pixel the mean of 2x2; turns --target-fps off)")
    add_number(p, "--scale-floor", type=float, default=DEFAULT_FLOOR,
               help=f"lowest render scale --target-fps goes to (default {DEFAULT_FLOOR})")
    add_number(p, "--scale-ceiling", type=float, default=1.0,
               help=f"highest render scale --target-fps goes to (1 to {MAX_SCALE:g}; default 1; above 1 it "
                    "supersamples where the frame rate allows)")
    p.add_argument("--refine-still", action=argparse.BooleanOptionalAction, default=True,
                   help="while nothing changes (camera, lights, objects, window, view mode, model), draw the view at "
                        "scale 1 (or --scale-ceiling above 1), then show it without drawing again (default); "
                        "--no-refine-still keeps every frame at the dynamic scale")
    p.add_argument("--temporal", default="off", choices=("on", "off"),
                   help="temporal upsampling of the final image (Halton-jittered frames reprojected, clamped and "
                        "accumulated at the window's size; default off: docs/viewer.md has its measurement)")
    p.add_argument("--auto-exposure", action=argparse.BooleanOptionalAction, default=None,
                   help="start with the exposure metered from the frame, or not (the panel toggles it; default: as "
                        "the scene file's [scene] auto_exposure says, on for sponza)")
    p.add_argument("--light-moving", action="store_true", help="start with the light animated")
    p.add_argument("--camera-moving", action="store_true",
                   help="start playing the scene's camera path (sponza's walk; as the P key), to time a moving "
                        "camera: culling, the shadow cache and the render scale then see what a walk shows")
    p.add_argument("--back-faces", action="store_true",
                   help="draw the back faces of single-sided materials too, as the path tracer sees them (slower; "
                        "by default the G-buffer culls them)")
    p.add_argument("--shadow-bands", action=argparse.BooleanOptionalAction, default=True,
                   help="once a moving sun rests, draw its full shadow map in bands over the next frames, the moving "
                        "map shown meanwhile (default; no stalled frame), or whole at the first frame it rests")
    p.add_argument("--path", type=Path, default=None,
                   help="play this camera path file from the first frame (P plays it again; docs/paths.md)")
    p.add_argument("--record-path", type=Path, default=None,
                   help="record the camera path from the first frame to the last into this JSON file (Ctrl+R "
                        "records by hand)")
    add_number(p, "--fixed-step", type=float, default=None,
               help="advance animations, paths and recordings by this many seconds a frame instead of the clock "
                    "(reproducible runs: a recording then replays frame for frame, with a fixed --render-scale)")
    p.add_argument("--stats", type=Path, default=None,
                   help="with --frames: write per-stage times, fps and the resolutions as JSON here")
    p.set_defaults(func=run)
    return p


def run(args: argparse.Namespace) -> int:
    """Open the viewer as the arguments say; with ``--frames``, print one line of what it did."""
    from diviewer.frames import parse_resolution
    from diviewer.gl.neural import GISettings
    from diviewer.viewer.run import run_viewer
    from diviewer.viewer.settings import ViewerSettings
    from diviewer.viewer.still import StillSettings

    # Each option's own range was checked before (diviewer.options); here the rules between them.
    if args.window_screenshot is not None and args.frames is None:
        raise DiviewerError("--window-screenshot needs --frames (it saves the last frame's window)",
                            field="--window-screenshot")
    size = parse_resolution(args.size, "--size")
    top = args.render_scale if args.render_scale is not None else args.scale_ceiling
    if max(size) * top > MAX_SIZE:
        option = "--render-scale" if args.render_scale is not None else "--scale-ceiling"
        raise DiviewerError(f"{args.size} shaded at {top:g}x per side is {round(size[0] * top)}x"
                            f"{round(size[1] * top)}, above {MAX_SIZE} a side; give a smaller --size or {option}",
                            field="--size")
    _check_paths(args)
    if args.frames is not None and str(args.model).lower() not in ("auto", "none"):
        # Scripted mode: a model the user named and the viewer refuses is a user error (exit 2),
        # found before a window opens; interactively the panel says why and offers the others.
        from diviewer.scene import load_scene
        from diviewer.viewer.models import open_model

        model, message = open_model(args.model, load_scene(args.scene), args.provider)
        if model is None:
            raise DiviewerError(message, field="--model")
    settings = ViewerSettings(size=size, vsync=not args.no_vsync, model=args.model, provider=args.provider,
                              controller=args.camera, gi_res=args.gi_res, target_fps=args.target_fps,
                              render_scale=args.render_scale, scale_floor=args.scale_floor,
                              scale_ceiling=args.scale_ceiling,
                              auto_exposure=args.auto_exposure, back_faces=args.back_faces,
                              rest_in_bands=args.shadow_bands, still=StillSettings(refine=args.refine_still),
                              temporal=args.temporal == "on",
                              gi=GISettings(downsample=args.gi_downsample, pipelined=args.pipelined, lean=args.lean),
                              path=str(args.path) if args.path else None, fixed_step=args.fixed_step,
                              record_path=str(args.record_path) if args.record_path else None)
    script = [(0, lambda v: setattr(v.state, "animate_light", True))] if args.light_moving else []
    if args.camera_moving:
        script.append((0, _play_camera_path))
    if args.window_screenshot is not None:
        script.append((args.frames - 1, "window_screenshot", {"path": args.window_screenshot}))
    summary = run_viewer(args.scene, frames=args.frames, screenshot=args.screenshot, settings=settings,
                         stats=args.stats, script=script)
    if args.frames is not None:
        gw, gh = summary["gi_size"]
        rw, rh = summary["render_size"]
        vw, vh = summary["view_size"]
        print(f"viewer: {summary['frames']} frames at {vw}x{vh} (shaded at {rw}x{rh}, scale "
              f"{summary['render_scale']:.2f}), GI {gw}x{gh}, "
              f"{summary['stages_ms']['frame']:.1f} ms/frame"
              + "".join(f", saved {p}" for p in (args.screenshot, args.window_screenshot, args.record_path) if p))
    return 0


def _check_paths(args: argparse.Namespace) -> None:
    """--path read and checked against the scene, --record-path writable: before a window opens (--fixed-step is
    the CLI's FLOAT_OPTIONS)."""
    from diviewer.outputs import check_output_file

    if args.record_path is not None:
        check_output_file(args.record_path, "--record-path", protect=(args.path,), suffix=".json")
    if args.path is not None:
        from diviewer.scene import load_scene
        from diviewer.scene.camera_path import read_path

        read_path(args.path, load_scene(args.scene))


def _play_camera_path(viewer) -> None:
    """--camera-moving: play the scene's camera path from the first frame; a scene without one is refused."""
    if not (viewer.state.play_path or viewer.state.toggle_path()):
        raise DiviewerError(f"scene {viewer.state.scene.name} has no camera path to play (a free-camera region is "
                            "not a path)", field="--camera-moving")
