"""Lay JSON files out by rows (diviewer.outputs.dumps_rows), their content unchanged.

Usage: python tools/relayout_json.py FILE_OR_FOLDER [...]     (a folder: every *.json under it)
       python tools/relayout_json.py --check FILE_OR_FOLDER [...]

The evaluation JSONs the docs cite (docs/data/) and the shipped sets' manifests (assets/evalsets/) were written one
member a line (``indent=1``); their bulk is per-frame records, one line per number. Laid out by rows, each record
is a line: about a fifth smaller, and as readable. A file is rewritten (atomically) only when what ``json.loads``
reads from the new text equals what it read from the old, number for number and key order included; a file
that is not strict JSON (NaN, Infinity) or not JSON at all is refused, naming it. ``--check`` rewrites nothing
and exits 1 if a file is not laid out by rows (the layout test runs it on the tree).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from diviewer import imageio
from diviewer.errors import DiviewerError
from diviewer.outputs import dumps_rows


def _reject_constant(name: str):
    raise ValueError(f"{name} is not strict JSON")


def relaid(path: Path) -> tuple[str, str]:
    """(old text, the text laid out by rows) of one file; refused if it is not strict JSON or would read otherwise."""
    try:
        text = path.read_text(encoding="utf-8")
        data = json.loads(text, parse_constant=_reject_constant)
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise DiviewerError(f"cannot be laid out: {e}", path=path) from None
    new = dumps_rows(data) + ("\n" if text.endswith("\n") else "")
    if json.loads(new, object_pairs_hook=list) != json.loads(text, object_pairs_hook=list):  # key order included
        raise DiviewerError("laid out by rows it would read otherwise; left as it is", path=path)
    return text, new


def json_files(targets: list[Path]) -> list[Path]:
    out = []
    for t in targets:
        if t.is_dir():
            out += sorted(t.rglob("*.json"))
        elif t.is_file():
            out.append(t)
        else:
            raise DiviewerError("no such file or folder", path=t)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("targets", nargs="+", type=Path)
    p.add_argument("--check", action="store_true", help="rewrite nothing; exit 1 if a file is not laid out by rows")
    a = p.parse_args(argv)
    try:
        files = json_files(a.targets)
        pending, before, after = [], 0, 0
        for f in files:
            old, new = relaid(f)
            before, after = before + len(old.encode()), after + len(new.encode())
            if new != old:
                pending.append((f, new))
    except DiviewerError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if a.check:
        for f, _ in pending:
            print(f"{f}: not laid out by rows (python tools/relayout_json.py {f})")
        return 1 if pending else 0
    for f, new in pending:
        imageio.write_text(f, new)
    print(f"{len(pending)} of {len(files)} JSON files laid out by rows: {before:,} -> {after:,} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
