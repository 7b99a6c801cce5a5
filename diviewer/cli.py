"""The `diviewer` command: one subcommand per job; user errors print one line and exit 2."""

from __future__ import annotations

import argparse
import errno
import math
import os
import sys
from pathlib import Path

from diviewer import __version__
from diviewer.errors import DiviewerError
from diviewer.outputs import ENVIRONMENT_ERRNOS, check_command_outputs, is_scratch

def _cmd_render(args: argparse.Namespace) -> int:
    from diviewer.render import render_to_dir

    if args.path is not None:
        return _render_path(args)
    for flag, given in (("--frames", args.frames), ("--fps", args.fps), ("--video", args.video),
                        ("--compare", args.compare), ("--exr", args.exr)):
        if given:
            raise DiviewerError("renders the frames of a camera path: give --path FILE", field=flag)
    if args.reference:
        from diviewer.render import check_reference

        check_reference(args.reference)  # a missing extra fails before any GL work
    record = render_to_dir(args.scene, args.out, res=args.res, seed=args.seed, split=args.split,
                           config_file=args.config, exposure=args.exposure, tonemap=args.tonemap, model=args.model,
                           provider=args.provider, vxgi=_vxgi_settings(args))
    w, h = record["resolution"]
    print(f"rendered {record['scene']} at {w}x{h} into {args.out}")
    if args.reference:
        _render_reference(args)
    return 0


def _render_path(args: argparse.Namespace) -> int:
    from diviewer.render_path import render_path

    for flag, given in (("--seed", args.seed is not None), ("--config", args.config), ("--reference", args.reference),
                        ("--vxgi", args.vxgi), ("--noise-floor", args.noise_floor)):
        if given:
            raise DiviewerError("does not apply to --path (the path gives each frame; --compare adds the reference)",
                                field=flag)
    done = render_path(args.scene, args.path, args.out, frames=args.frames, fps=args.fps, res=args.res,
                       video=args.video, compare=args.compare, spp=args.spp, exr=args.exr, model=args.model,
                       provider=args.provider, exposure=args.exposure, tonemap=args.tonemap,
                       max_depth=args.max_depth, pt_seed=args.pt_seed)
    w, h = done["resolution"]
    print(f"rendered {len(done['times'])} frames of {args.path} at {w}x{h} into {args.out}"
          + (f", video {args.video}" if args.video else ""))
    return 0


def _vxgi_settings(args: argparse.Namespace):
    """The VXGISettings that `render --vxgi` asked for, or None."""
    if not args.vxgi:
        return None
    from diviewer.gl.vxgi import VXGISettings

    settings = VXGISettings(resolution=args.vxgi_res, trace_scale=args.vxgi_trace_scale, bounces=args.vxgi_bounces)
    settings.validate()
    return settings


def _render_reference(args: argparse.Namespace) -> None:
    from diviewer.render import render_reference_to_dir

    ref = render_reference_to_dir(args.scene, args.out, args.reference, spp=args.spp, max_depth=args.max_depth,
                                  noise_floor=args.noise_floor, pt_seed=args.pt_seed)
    line = (f"path-traced reference ({ref['variant']}, {ref['spp']} spp, max depth {ref['max_depth']}) "
            f"in {ref['seconds']['full']:.1f} s ({ref['pt_estimator'].replace('_', ' ')})")
    if "noise_floor" in ref:
        line += f"; noise floor PSNR {ref['noise_floor']['psnr']:.2f} dB, SSIM {ref['noise_floor']['ssim']:.4f}"
    print(line)


def _cmd_capture(args: argparse.Namespace) -> int:
    from diviewer.data.capture import CaptureSettings, capture, parse_shard
    from diviewer.frames import parse_resolution

    width, height = parse_resolution(args.res)
    fractions = parse_splits(args.splits)
    settings = CaptureSettings(frames=args.frames, width=width, height=height, gt=args.gt, spp=args.spp,
                               max_depth=args.max_depth, seed=args.seed, split_fractions=fractions, dtype=args.dtype,
                               thumbs=args.thumbs, vxgi_resolution=args.vxgi_res, direct_samples=args.direct_samples)
    capture(args.scene, args.out, settings, parse_shard(args.shard))
    return 0


def parse_splits(text: str) -> tuple[float, float, float]:
    """``0.8,0.1,0.1``: three finite non-negative fractions train,val,test with a positive sum."""
    try:
        fractions = tuple(float(x) for x in str(text).split(","))
    except ValueError:
        fractions = ()
    if len(fractions) != 3 or not all(math.isfinite(f) and f >= 0 for f in fractions) or sum(fractions) <= 0:
        raise DiviewerError(f"takes three non-negative fractions train,val,test (e.g. 0.8,0.1,0.1), got '{text}'",
                            field="--splits")
    return fractions


def _cmd_baseline(args: argparse.Namespace) -> int:
    from diviewer.evaluation.baseline import build_baseline

    build_baseline(args.data, args.out, split=args.split, max_frames=args.max_frames)
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    import dataclasses

    from diviewer.bench import BenchSettings, quick, run_bench

    settings = quick(BenchSettings()) if args.quick else BenchSettings()
    given = {"scene": args.scene, "models": tuple(str(m) for m in args.models) if args.models else None,
             "resolutions": tuple(args.res) if args.res else None, "frames": args.frames, "warmup": args.warmup,
             "untrained_k": tuple(args.untrained_k) if args.untrained_k is not None else None,
             "gi_steps": tuple(args.gi_steps) if args.gi_steps is not None else None,
             "evalset": str(args.evalset) if args.evalset else None, "eval_frames": args.eval_frames,
             "calib_data": str(args.calib_data) if args.calib_data else None, "provider": args.provider,
             "timing": args.timing, "pt_frames": args.pt_frames,
             "vxgi_grids": tuple(args.vxgi_grids) if args.vxgi_grids is not None else None,
             "vxgi_trace_scale": args.vxgi_trace_scale}
    settings = dataclasses.replace(settings, **{k: v for k, v in given.items() if v is not None})
    if args.path is not None:
        from diviewer.bench.path import check_path_options, run_path_bench

        check_path_options(args)
        run_path_bench(settings, args.path, json_out=args.json)
        return 0
    run_bench(settings, json_out=args.json, plot_out=args.plot)
    return 0


MITSUBA_VARIANTS = ("cuda_ad_rgb", "llvm_ad_rgb", "scalar_rgb")
"""--variant choices (diviewer.reference.variant.VARIANTS; not imported here to keep the parser light)."""


def _add_variant_arg(p) -> None:
    p.add_argument("--variant", default=None, choices=MITSUBA_VARIANTS,
                   help="Mitsuba variant (default: cuda_ad_rgb on a CUDA GPU, else llvm_ad_rgb where a libLLVM >= 16 "
                        "works, else scalar_rgb; a variant that cannot run here falls back the same way)")


def _add_reference_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("path-traced reference (needs the 'train' extra: mitsuba)")
    _add_variant_arg(g)
    g.add_argument("--reference", default=None, choices=("pt",),
                   help="also write the ground truth: pt = Mitsuba path tracer (pt.exr, pt_direct.exr, pt_indirect.exr)")
    g.add_argument("--spp", type=int, default=256, help="samples per pixel of the reference (default 256)")
    g.add_argument("--max-depth", type=int, default=None,
                   help="path length limit of the reference (default 16; 2 = direct light only)")
    g.add_argument("--pt-seed", type=int, default=0, help="the path tracer's sampler seed (default 0)")
    g.add_argument("--noise-floor", action="store_true",
                   help="render a second time with the next seed and record PSNR/SSIM between the two in frame.json")


def _cmd_export(args: argparse.Namespace) -> int:
    from diviewer.train.export import ExportSettings, export, info

    if args.info:
        print(info(args.info))
        return 0
    if args.checkpoint is None or args.out is None:
        raise DiviewerError("give a checkpoint and --out (or --info MODEL)", field="export")
    export(args.checkpoint, args.out, ExportSettings(fp16=args.fp16, half_weights=args.half_weights,
                                                     int8_weights=args.int8_weights,
                                                     verify_frames=args.verify_frames, layout=args.layout))
    return 0


def _scene_help(default: str | None = None) -> str:
    from diviewer.paths import scene_help

    return scene_help(default)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="diviewer", description="Real-time OpenGL viewer with a neural GI pass.")
    ap.add_argument("--version", action="version", version=f"diviewer {__version__}")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    from diviewer.build.command import add_build_parser
    from diviewer.datacommand import add_data_parsers
    from diviewer.evalcommand import add_eval_parsers
    from diviewer.inspectcommand import add_inspect_parser
    from diviewer.ship.command import add_ship_parser
    from diviewer.train.cli import add_train_parser
    from diviewer.viewer.command import add_view_parser

    _add_render_parser(sub)
    _add_capture_parser(sub)
    _add_export_parser(sub)
    add_train_parser(sub)
    add_view_parser(sub)
    add_build_parser(sub)
    add_ship_parser(sub)
    add_eval_parsers(sub, _add_variant_arg)
    _add_baseline_parser(sub)
    _add_bench_parser(sub)
    add_data_parsers(sub)
    add_inspect_parser(sub)
    return ap


def _add_render_parser(sub) -> None:
    """`diviewer render`: one configuration to image files (GL, reference, model, VXGI)."""
    from diviewer.gl.display import DEFAULT_TONEMAP, TONEMAPS

    p = sub.add_parser("render", help="render one configuration of a scene to image files")
    p.add_argument("--scene", default="cornell", help=_scene_help())
    p.add_argument("--res", default=None, help="N (square) or WxH; default the model's resolution, else 256")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--seed", type=int, default=None, help="draw the configuration from the scene's ranges")
    p.add_argument("--split", default="train", choices=("train", "val", "test"), help="split to draw from (with --seed)")
    p.add_argument("--config", type=Path, default=None, help="render the configuration stored in a frame.json")
    p.add_argument("--exposure", type=float, default=None, help="display exposure in stops (PNG previews)")
    p.add_argument("--tonemap", default=DEFAULT_TONEMAP, choices=tuple(TONEMAPS),
                   help="display tone curve of the PNG previews")
    p.add_argument("--model", type=Path, default=None, help="an ONNX model (diviewer export): also write neural.exr")
    p.add_argument("--provider", default=None, choices=("cpu", "cuda", "tensorrt"), help="onnxruntime provider")
    _add_reference_args(p)
    g = p.add_argument_group("camera path (docs/paths.md)")
    g.add_argument("--path", type=Path, default=None, help="render every frame of a camera path file (resumable)")
    g.add_argument("--frames", type=int, default=None, help="frames evenly from the path's first key to its last")
    g.add_argument("--fps", type=float, default=None, help="frames per second of the path (default 30)")
    g.add_argument("--video", type=Path, default=None, help="also write the frames as an mp4 (H.264)")
    g.add_argument("--compare", default=None, help="methods side by side, labelled: direct,neural,reference "
                   "(neural needs --model; reference is Mitsuba at --spp, from the 'train' extra)")
    g.add_argument("--exr", action="store_true", help="also write each method's linear image as EXR")
    g = p.add_argument_group("voxel cone tracing")
    g.add_argument("--vxgi", action="store_true", help="also render VXGI: vxgi.exr and vxgi_indirect.exr")
    g.add_argument("--vxgi-res", type=int, default=64, help="voxels per side of the VXGI grid (32, 64, 128; default 64)")
    g.add_argument("--vxgi-trace-scale", type=int, default=1,
                   help="trace one pixel per NxN block and upsample (default 1: full resolution)")
    g.add_argument("--vxgi-bounces", type=int, default=1, choices=(1, 2), help="bounces of indirect light (default 1)")
    p.set_defaults(func=_cmd_render)


def _add_capture_parser(sub) -> None:
    """`diviewer capture`: a dataset of GL inputs and ground truth."""
    p = sub.add_parser("capture", help="render a dataset: GL inputs and path-traced ground truth (resumable)")
    p.add_argument("--scene", default="cornell", help=_scene_help())
    p.add_argument("--frames", type=int, default=100, help="frames over all splits")
    p.add_argument("--res", default="128", help="N or WxH; default 128")
    p.add_argument("--gt", default="pt", choices=("pt", "vxgi"),
                   help="ground truth: pt (Mitsuba path tracer) or vxgi (voxel cone tracing, stored in the same channels)")
    p.add_argument("--vxgi-res", type=int, default=64, help="VXGI grid resolution with --gt vxgi (default 64)")
    p.add_argument("--spp", type=int, default=256, help="path-tracing samples per pixel (default 256)")
    p.add_argument("--max-depth", type=int, default=16, help="path length limit of the full render")
    p.add_argument("--seed", type=int, default=0, help="base seed of configurations and path-tracer seeds")
    p.add_argument("--splits", default="0.8,0.1,0.1", help="fractions train,val,test")
    p.add_argument("--dtype", default="float16", choices=("float16", "float32"), help="frame storage type")
    p.add_argument("--thumbs", type=int, default=2, help="PNG thumbnails per split")
    p.add_argument("--direct-samples", type=int, default=1, help="samples per axis of the stored direct light: 1 "
                   "each pixel's centre (default), 4 the mean over its area (diviewer.gl.area)")
    p.add_argument("--shard", default=None, help="k/n: render every n-th frame starting at the k-th")
    _add_variant_arg(p)
    p.add_argument("--out", type=Path, required=True, help="dataset folder (created, or resumed)")
    p.set_defaults(func=_cmd_capture)


def _add_export_parser(sub) -> None:
    """`diviewer export`: a checkpoint to a verified ONNX model and its card."""
    p = sub.add_parser("export", help="checkpoint to ONNX (encoding inside the graph), verified against PyTorch")
    p.add_argument("checkpoint", type=Path, nargs="?", help="RUN/best.ckpt")
    p.add_argument("--out", type=Path, help="model.onnx (a model card model.json is written beside it)")
    p.add_argument("--fp16", action="store_true", help="float16 weights and generator (encoding stays float32)")
    p.add_argument("--half-weights", action="store_true",
                   help="float32 generator with its weights stored as float16: half the file, cast back on load")
    p.add_argument("--int8-weights", action="store_true",
                   help="float32 generator with its inner convolutions' weights stored as int8 (a scale per output "
                        "channel), the rest as float16: a quarter of float32's file, cast back on load")
    p.add_argument("--layout", choices=("NHWC", "NCHW"), default="NHWC",
                   help="the graph's input layout: NHWC as the GL pack writes it (default), or NCHW")
    p.add_argument("--verify-frames", type=int, default=4, help="frames compared with PyTorch before writing")
    p.add_argument("--info", type=Path, metavar="MODEL", help="print a model's metadata and exit")
    p.set_defaults(func=_cmd_export)


def _add_baseline_parser(sub) -> None:
    """`diviewer baseline`: the linear-regression baseline as an ONNX model."""
    p = sub.add_parser("baseline", help="fit the per-pixel linear-regression baseline on a dataset; write it as "
                                        "an ONNX model that eval, bench and view run like any model")
    p.add_argument("--data", type=Path, required=True, help="a dataset (diviewer capture)")
    p.add_argument("--out", type=Path, required=True, help="model.onnx (a model card model.json beside it)")
    p.add_argument("--split", default="train", choices=("train", "val", "test"), help="split to fit on (train)")
    p.add_argument("--max-frames", type=int, default=None, help="fit on the first N present frames only")
    p.set_defaults(func=_cmd_baseline)


def _add_bench_parser(sub) -> None:
    """`diviewer bench`: the headless timing and speed/accuracy table."""
    p = sub.add_parser("bench", help="headless frame timing per stage and the speed/accuracy table: direct light, "
                                     "the baseline, models (fp32/fp16/int8, GI resolutions), untrained K, VXGI, path tracer")
    p.add_argument("--scene", default=None, help=_scene_help("cornell"))
    p.add_argument("--models", type=Path, nargs="+", default=None,
                   help="ONNX models (diviewer export / baseline); default the scene's shipped models")
    p.add_argument("--res", type=int, nargs="+", default=None, help="square frame resolutions (default 128 256)")
    p.add_argument("--frames", type=int, default=None, help="timed frames per row (default 30)")
    p.add_argument("--warmup", type=int, default=None, help="untimed frames first (default 5)")
    p.add_argument("--untrained-k", type=int, nargs="*", default=None,
                   help="base widths of untrained generators for the cost curve (default 8 16 32 64 128)")
    p.add_argument("--gi-steps", type=int, nargs="*", default=None,
                   help="GI at 1/step of the frame resolution where the model allows (default 2)")
    p.add_argument("--evalset", type=Path, default=None,
                   help="evaluation set (default the scene's compact set, assets/evalsets/<scene>)")
    p.add_argument("--eval-frames", type=int, default=None, help="frames per split scored (default all)")
    p.add_argument("--calib-data", type=Path, default=None,
                   help="a capture whose train split calibrates int8 (default GL renders of training configurations)")
    p.add_argument("--pt-frames", type=int, default=None, help="frames the path tracer is timed on (default 2)")
    p.add_argument("--vxgi-grids", type=int, nargs="*", default=None,
                   help="VXGI grid resolutions, one row each (default 32 64 128; none: no VXGI rows)")
    p.add_argument("--vxgi-trace-scale", type=int, default=None,
                   help="VXGI traces at 1/N of the frame resolution, then upsamples (default 2)")
    p.add_argument("--provider", default=None, choices=("cpu", "cuda", "tensorrt"))
    p.add_argument("--timing", default=None, choices=("auto", "query", "sync"),
                   help="GL stages: timer queries (auto where supported) or wall clock around glFinish")
    p.add_argument("--path", type=Path, default=None, help="time a camera path file frame by frame (per stage, "
                   "median and p95) and its temporal stability against the path tracer (docs/paths.md)")
    p.add_argument("--json", type=Path, default=None, help="write the results as strict JSON")
    p.add_argument("--plot", type=Path, default=None, help="write the speed/accuracy plot (PNG)")
    p.add_argument("--quick", action="store_true", help="a few frames at 32x32 (seconds): the test suite's run")
    p.set_defaults(func=_cmd_bench)


def check_options(ap: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Before any work: every numeric option in range and finite (`diviewer.options`), outputs writable."""
    from diviewer.options import check_options as check_numbers, chosen_parser

    check_numbers(ap, args)
    options = {a.dest: a.option_strings[0] if a.option_strings else a.dest for a in chosen_parser(ap, args)._actions}
    check_command_outputs(args.command, args, options)


def _say_scene_warnings(command: str) -> None:
    """Print a scene load's warnings (an unhonoured glTF extension, a default material) as one line each."""
    import warnings

    from diviewer.scene.reads import SceneWarning

    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, SceneWarning):
            print(f"diviewer {command}: warning: {message}", file=sys.stderr)
        else:
            shown(message, category, filename, lineno, file, line)
    warnings.showwarning = show
    warnings.simplefilter("always", SceneWarning)  # each load says them (a second scene may share a glTF)


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    _say_scene_warnings(args.command)
    try:
        check_options(ap, args)
        if getattr(args, "variant", None):
            os.environ["DIVIEWER_MITSUBA_VARIANT"] = args.variant  # read by reference.variant.select_variant
        return int(args.func(args) or 0)
    except DiviewerError as exc:
        print(f"diviewer {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        # A full disk, a read-only folder, a file where a folder should be: the machine's state,
        # not a bug. Whatever was written before is intact (every write goes to a temporary name).
        if exc.errno not in ENVIRONMENT_ERRNOS:
            raise
        where = exc.filename or ""
        hint = ("; free some space and run the same command again (nothing half-written was kept)"
                if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG) else "")
        if where and is_scratch(where):
            hint += " (a scratch file of this command: point TMPDIR at a folder with space)"
        print(f"diviewer {args.command}: error: {where}{': ' if where else ''}{exc.strerror or exc}{hint}",
              file=sys.stderr)
        return 2
    except MemoryError:
        print(f"diviewer {args.command}: error: out of memory; use a smaller size or fewer frames", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"diviewer {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
