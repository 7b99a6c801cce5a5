"""Move models, cards and datasets from the version-1 scene hash to the scene identity (version 2).

Usage: python tools/restamp_scene_hash.py --scene cornell --old-toml OLD.toml FILE [FILE ...]

Version 1 was the sha256 of the scene file's bytes; version 2 (diviewer.scene.identity.scene_identity)
covers what the scene looks like, the files it loads included. A file is restamped only when its
recorded hash is the version-1 hash of OLD.toml (a dataset's own manifest text is used when it has
one) and OLD.toml describes the same scene as today's file (equal once comments, the camera and the
ranges are left out). ONNX models (the ``diviewer`` metadata), model cards (.json with ``scene_hash``)
and dataset manifests are rewritten atomically; anything else is refused.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tomllib
from pathlib import Path

from diviewer import imageio
from diviewer.errors import DiviewerError
from diviewer.scene import load_scene
from diviewer.scene.identity import NOT_IDENTITY
from diviewer.scene.loader import resolve_scene_path


def _content(text: str) -> dict:
    data = tomllib.loads(text)
    data = {k: v for k, v in data.items() if k not in NOT_IDENTITY}
    if isinstance(data.get("scene"), dict):
        data["scene"] = {k: v for k, v in data["scene"].items() if k != "exposure"}
    return data


def _check(recorded: str, old_text: str, new_text: str, what: Path) -> None:
    if recorded != hashlib.sha256(old_text.encode()).hexdigest():
        raise DiviewerError("the recorded scene hash is not the version-1 hash of the old scene file", path=what,
                            field="scene_hash")
    if _content(old_text) != _content(new_text):
        raise DiviewerError("the old scene file describes another scene than today's (beyond camera and ranges)",
                            path=what, field="scene_hash")


def restamp(file: Path, scene_name: str, old_toml: Path | None) -> str:
    """Rewrite one file's scene hash; returns what was done."""
    scene = load_scene(scene_name)
    new_text = resolve_scene_path(scene_name).read_text()
    old_text = old_toml.read_text() if old_toml else None
    if file.suffix == ".onnx":
        import onnx

        model = onnx.load(str(file))
        props = {p.key: p for p in model.metadata_props}
        meta = json.loads(props["diviewer"].value)
        if meta["scene_hash"] == scene.file_hash:
            return "already current"
        _check(meta["scene_hash"], old_text, new_text, file)
        meta["scene_hash"] = scene.file_hash
        props["diviewer"].value = json.dumps(meta, sort_keys=True)
        with imageio.atomic_path(file) as tmp:
            onnx.save(model, str(tmp))
        return "model restamped"
    raw = file.read_text()
    lines = raw.splitlines()
    indent = len(lines[1]) - len(lines[1].lstrip()) if len(lines) > 1 else 1  # keep the file's own layout
    data = json.loads(raw)
    if data.get("scene_hash") == scene.file_hash:
        return "already current"
    text = data.get("scene_toml") or old_text
    _check(data.get("scene_hash"), text, new_text, file)
    data["scene_hash"] = scene.file_hash
    imageio.write_text(file, json.dumps(data, indent=indent))
    return "restamped"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", required=True)
    ap.add_argument("--old-toml", type=Path, help="the scene file the recorded hash was taken of")
    ap.add_argument("files", nargs="+", type=Path)
    args = ap.parse_args(argv)
    try:
        for f in args.files:
            print(f"{f}: {restamp(f, args.scene, args.old_toml)}")
    except DiviewerError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
