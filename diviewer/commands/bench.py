"""`diviewer bench`: headless frame timing per stage and the speed/accuracy table."""

from __future__ import annotations

import argparse
from pathlib import Path

from diviewer.commands.common import add_json, add_number, add_provider, add_scene, scene_help


def add_parser(sub) -> None:
    """`diviewer bench`: the headless timing and speed/accuracy table."""
    p = sub.add_parser("bench", help="headless frame timing per stage and the speed/accuracy table: direct light, "
                                     "the baseline, models (fp32/fp16/int8, GI resolutions), untrained K, VXGI, path tracer")
    add_scene(p, default=None, help=scene_help("cornell"))
    p.add_argument("--models", type=Path, nargs="+", default=None,
                   help="ONNX models (diviewer export / baseline); default the scene's shipped models")
    add_number(p, "--res", nargs="+", default=None, help="square frame resolutions (default 128 256)")
    add_number(p, "--frames", default=None, help="timed frames per row (default 30)")
    add_number(p, "--warmup", default=None, help="untimed frames first (default 5)")
    add_number(p, "--untrained-k", nargs="*", default=None,
               help="base widths of untrained generators for the cost curve (default 8 16 32 64 128)")
    add_number(p, "--gi-steps", nargs="*", default=None,
               help="GI at 1/step of the frame resolution where the model allows (default 2)")
    add_number(p, "--render-scales", type=float, nargs="+", default=None,
               help="the viewer's render scales (dynamic resolution; 0 < S <= 2) to time and score against scale 1 "
                    "at each --res as the window (default none)")
    p.add_argument("--evalset", type=Path, default=None,
                   help="evaluation set (default the scene's compact set, assets/evalsets/<scene>)")
    add_number(p, "--eval-frames", default=None, help="frames per split scored (default all)")
    p.add_argument("--calib-data", type=Path, default=None,
                   help="a capture whose train split calibrates int8 (default GL renders of training configurations)")
    add_number(p, "--pt-frames", default=None, help="frames the path tracer is timed on (default 2)")
    add_number(p, "--vxgi-grids", nargs="*", default=None,
               help="VXGI grid resolutions, one row each (default 32 64 128; none: no VXGI rows)")
    add_number(p, "--vxgi-trace-scale", default=None,
               help="VXGI traces at 1/N of the frame resolution, then upsamples (default 2)")
    add_provider(p)
    p.add_argument("--timing", default=None, choices=("auto", "query", "sync"),
                   help="GL stages: timer queries (auto where supported) or wall clock around glFinish")
    p.add_argument("--path", type=Path, default=None, help="time a camera path file frame by frame (per stage, "
                   "median and p95) and its temporal stability against the path tracer (docs/paths.md)")
    add_json(p)
    p.add_argument("--plot", type=Path, default=None, help="write the speed/accuracy plot (PNG)")
    p.add_argument("--quick", action="store_true", help="a few frames at 32x32 (seconds): the test suite's run")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The benchmark's settings (--quick's or the defaults, then the options given), run as a table or along --path."""
    import dataclasses

    from diviewer.bench import BenchSettings, quick, run_bench

    settings = quick(BenchSettings()) if args.quick else BenchSettings()
    given = {"scene": args.scene, "models": tuple(str(m) for m in args.models) if args.models else None,
             "resolutions": tuple(args.res) if args.res else None, "frames": args.frames, "warmup": args.warmup,
             "untrained_k": tuple(args.untrained_k) if args.untrained_k is not None else None,
             "gi_steps": tuple(args.gi_steps) if args.gi_steps is not None else None,
             "render_scales": tuple(args.render_scales) if args.render_scales else None,
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
