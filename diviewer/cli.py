"""The `diviewer` command: one subcommand per job; user errors print one line and exit 2."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from diviewer import __version__
from diviewer.errors import DiviewerError


def _cmd_render(args: argparse.Namespace) -> int:
    from diviewer.render import render_to_dir

    record = render_to_dir(args.scene, args.out, res=args.res, seed=args.seed, split=args.split,
                           config_file=args.config, exposure=args.exposure, tonemap=args.tonemap)
    w, h = record["resolution"]
    print(f"rendered {record['scene']} at {w}x{h} into {args.out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="diviewer", description="Real-time OpenGL viewer with a neural GI pass.")
    ap.add_argument("--version", action="version", version=f"diviewer {__version__}")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("render", help="render one configuration of a scene to image files")
    p.add_argument("--scene", default="cornell", help="shipped scene name (cornell, atrium) or a .toml path")
    p.add_argument("--res", default="256", help="N (square) or WxH; default 256")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--seed", type=int, default=None, help="draw the configuration from the scene's ranges")
    p.add_argument("--split", default="train", choices=("train", "val", "test"), help="split to draw from (with --seed)")
    p.add_argument("--config", type=Path, default=None, help="render the configuration stored in a frame.json")
    p.add_argument("--exposure", type=float, default=None, help="display exposure in stops (PNG previews)")
    p.add_argument("--tonemap", default="aces", choices=("clamp", "reinhard", "aces"))
    p.set_defaults(func=_cmd_render)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except DiviewerError as exc:
        print(f"diviewer {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"diviewer {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
