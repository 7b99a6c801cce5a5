"""The `diviewer` command line: one module per command, each with ``add_parser(subparsers)`` and ``run(args)``.

`build_parser` makes the top parser from `COMMANDS`, in the order ``diviewer --help`` lists them;
`diviewer.cli.main` parses, checks every option before any work and runs the command. The option builders are in
`diviewer.commands.common`, the parser that records its options in `diviewer.commands.parser`.
"""

from __future__ import annotations

import argparse
import importlib

COMMANDS = ("render", "capture", "export", "train", "view", "build", "ship", "eval", "evalset", "baseline", "bench",
            "data", "inspect")
"""The command modules (`diviewer.commands.<name>`), one per subcommand of the same name."""


def build_parser() -> argparse.ArgumentParser:
    """The `diviewer` parser: ``--version`` and one subcommand per module of `COMMANDS`."""
    from diviewer import __version__
    from diviewer.commands.parser import CommandParser

    ap = CommandParser(prog="diviewer", description="Real-time OpenGL viewer with a neural GI pass.")
    ap.add_argument("--version", action="version", version=f"diviewer {__version__}")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"diviewer.commands.{name}").add_parser(sub)
    return ap
