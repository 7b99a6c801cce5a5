"""The `diviewer` command: one subcommand per job (`diviewer.commands`); user errors print one line and exit 2."""

from __future__ import annotations

import argparse
import errno
import os
import sys

from diviewer.commands import build_parser
from diviewer.errors import DiviewerError
from diviewer.outputs import ENVIRONMENT_ERRNOS, check_command_outputs, is_scratch


def check_options(ap: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Before any work: every numeric option in range and finite (`diviewer.options`), outputs writable."""
    from diviewer.commands.parser import arguments, chosen_parser
    from diviewer.options import check_options as check_numbers

    check_numbers(ap, args)
    options = {a.dest: a.option_strings[0] if a.option_strings else a.dest for a in arguments(chosen_parser(ap, args))}
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
