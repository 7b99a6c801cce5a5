"""`diviewer render`: one configuration of a scene to image files (GL, reference, model, VXGI), or a camera
path's frames."""

from __future__ import annotations

import argparse
from pathlib import Path

from diviewer.commands.common import add_model, add_number, add_out, add_provider, add_scene, add_split, add_variant
from diviewer.errors import DiviewerError



def add_parser(sub) -> None:
    """`diviewer render`: one configuration to image files (GL, reference, model, VXGI)."""
    from diviewer.gl.display import DEFAULT_TONEMAP, TONEMAPS

    p = sub.add_parser("render", help="render one configuration of a scene to image files")
    add_scene(p)
    p.add_argument("--res", default=None, help="N (square) or WxH; default the model's resolution, else 256")
    add_out(p, "output folder")
    add_number(p, "--seed", default=None, help="draw the configuration from the scene's ranges")
    add_split(p, "train", "split to draw from (with --seed)")
    p.add_argument("--config", type=Path, default=None, help="render the configuration stored in a frame.json")
    add_number(p, "--exposure", type=float, default=None, help="display exposure in stops (PNG previews)")
    p.add_argument("--tonemap", default=DEFAULT_TONEMAP, choices=tuple(TONEMAPS),
                   help="display tone curve of the PNG previews")
    add_model(p, "an ONNX model (diviewer export): also write neural.exr", default=None)
    add_provider(p, "onnxruntime provider")
    _add_reference_args(p)
    g = p.add_argument_group("camera path (docs/paths.md)")
    g.add_argument("--path", type=Path, default=None, help="render every frame of a camera path file (resumable)")
    add_number(g, "--frames", default=None, help="frames evenly from the path's first key to its last")
    add_number(g, "--fps", type=float, default=None, help="frames per second of the path (default 30)")
    g.add_argument("--video", type=Path, default=None, help="also write the frames as an mp4 (H.264)")
    g.add_argument("--compare", default=None, help="methods side by side, labelled: direct,neural,reference "
                   "(neural needs --model; reference is Mitsuba at --spp, from the 'train' extra)")
    g.add_argument("--exr", action="store_true", help="also write each method's linear image as EXR")
    g = p.add_argument_group("voxel cone tracing")
    g.add_argument("--vxgi", action="store_true", help="also render VXGI: vxgi.exr and vxgi_indirect.exr")
    add_number(g, "--vxgi-res", default=64, help="voxels per side of the VXGI grid (32, 64, 128; default 64)")
    add_number(g, "--vxgi-trace-scale", default=1,
               help="trace one pixel per NxN block and upsample (default 1: full resolution)")
    g.add_argument("--vxgi-bounces", type=int, default=1, choices=(1, 2), help="bounces of indirect light (default 1)")
    p.set_defaults(func=run)


def _add_reference_args(p) -> None:
    g = p.add_argument_group("path-traced reference (needs the 'train' extra: mitsuba)")
    add_variant(g)
    g.add_argument("--reference", default=None, choices=("pt",),
                   help="also write the ground truth: pt = Mitsuba path tracer (pt.exr, pt_direct.exr, pt_indirect.exr)")
    add_number(g, "--spp", default=256, help="samples per pixel of the reference (default 256)")
    add_number(g, "--max-depth", default=None, help="path length limit of the reference (default 16; 2 = direct light only)")
    add_number(g, "--pt-seed", default=0, help="the path tracer's sampler seed (default 0)")
    g.add_argument("--noise-floor", action="store_true",
                   help="render a second time with the next seed and record PSNR/SSIM between the two in frame.json")


def run(args: argparse.Namespace) -> int:
    """Render one configuration (with its reference), or a camera path's frames (--path)."""
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

