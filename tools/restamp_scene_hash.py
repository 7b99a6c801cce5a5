"""Move files to another scene identity: from the version-1 hash, or across an edit none of their frames sees.

Usage: python tools/restamp_scene_hash.py --scene cornell --old-toml OLD.toml FILE [FILE ...]
       python tools/restamp_scene_hash.py --old-toml OLD.toml --new-toml NEW.toml EVALSET [EVALSET ...]

The first form moves models, cards and datasets from the version-1 scene hash to the scene identity (version 2).

Version 1 was the sha256 of the scene file's bytes; version 2 (diviewer.scene.identity.scene_identity)
covers what the scene looks like, the files it loads included. A file is restamped only when its
recorded hash is the version-1 hash of OLD.toml (a dataset's own manifest text is used when it has
one) and OLD.toml describes the same scene as today's file (equal once comments, the camera and the
ranges are left out). ONNX models (the ``diviewer`` metadata), model cards (.json with ``scene_hash``)
and dataset manifests are rewritten atomically; anything else is refused.

The second form carries evaluation sets over to an edited scene file. A scene file's identity changes with every
mesh it declares, even one that only the sampler's ranges name (cornell's ``train_meshes``); an evaluation set
records that identity, `diviewer eval` refuses models of another one, and rendering the set again costs hours at
1024 spp. When the new file only adds or edits meshes that no frame of the set shows, and nothing else that the
identity covers changed, every frame is still a frame of the new scene, rendered exactly as the new file would
render it. Checked: the set's recorded identity is OLD.toml's; the two files are equal once their ranges, camera,
display exposure and ``[meshes]`` are left out; every mesh a frame's configuration names is declared the same in
both (or in neither); neither file loads other files (a glTF's bytes are part of the identity). The manifest then
records the new identity, the new file's text and where it came from (``restamped``).
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


def _looks(text: str) -> dict:
    """What the identity covers, less the mesh declarations (compared mesh by mesh)."""
    return {k: v for k, v in _content(text).items() if k != "meshes"}


def frame_meshes(manifest: dict) -> set[str]:
    """Every mesh name a frame's configuration draws."""
    return {o["mesh"] for f in manifest["frame_list"] for o in f["config"]["objects"]}


def restamp_evalset(evalset: Path, old_toml: Path, new_toml: Path) -> str:
    """Rewrite one evaluation set's scene identity from OLD.toml's to NEW.toml's; returns what was done."""
    mpath = evalset / "manifest.json"
    try:
        manifest = json.loads(mpath.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise DiviewerError(f"no readable evaluation-set manifest: {exc}", path=mpath) from exc
    if manifest.get("kind") != "evalset" or "frame_list" not in manifest:
        raise DiviewerError("not an evaluation set (diviewer evalset)", path=mpath, field="kind")
    old, new = load_scene(old_toml), load_scene(new_toml)
    if manifest.get("scene_hash") == new.file_hash:
        return "already current"
    if manifest.get("scene_hash") != old.file_hash:
        raise DiviewerError(f"the set was not made from {old_toml}", path=mpath, field="scene_hash")
    old_text, new_text = old_toml.read_text(), new_toml.read_text()
    old_data, new_data = tomllib.loads(old_text), tomllib.loads(new_text)
    for toml, data in ((old_toml, old_data), (new_toml, new_data)):
        loads = [n for n, m in data.get("meshes", {}).items() if "file" in m or "gltf" in m] + (
            ["gltf"] if "gltf" in data else [])
        if loads:
            raise DiviewerError(f"loads other files ({', '.join(loads)}): only self-contained scene files are carried "
                                f"over", path=toml, field="meshes")
    if _looks(old_text) != _looks(new_text):
        raise DiviewerError(f"the scene itself changed (beyond its ranges, camera and meshes): render the set again "
                            f"with `diviewer evalset --scene {new_toml}`", path=new_toml)
    old_meshes, new_meshes = old_data.get("meshes", {}), new_data.get("meshes", {})
    changed = sorted(m for m in frame_meshes(manifest) if old_meshes.get(m) != new_meshes.get(m))
    if changed:
        raise DiviewerError(f"meshes the set's frames show changed: {', '.join(changed)}", path=new_toml,
                            field="meshes")
    added = sorted(set(new_meshes) - set(old_meshes))
    edited = sorted(m for m in set(new_meshes) & set(old_meshes) if new_meshes[m] != old_meshes[m])
    manifest["restamped"] = {"from_scene_hash": manifest["scene_hash"], "from_scene_toml": manifest.get("scene_toml"),
                             "meshes_added": added, "meshes_edited": edited, "meshes_removed":
                             sorted(set(old_meshes) - set(new_meshes))}
    manifest["scene_hash"] = new.file_hash
    manifest["scene_toml"] = new_text
    manifest["scene_file"] = str(new_toml.resolve())
    imageio.write_text(mpath, json.dumps(manifest, indent=1))
    return f"restamped (meshes added: {', '.join(added) or 'none'}; edited: {', '.join(edited) or 'none'})"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", help="the scene whose identity the files move to (the first form)")
    ap.add_argument("--old-toml", type=Path, help="the scene file the recorded hash was taken of")
    ap.add_argument("--new-toml", type=Path, help="the edited scene file (the second form: evaluation sets)")
    ap.add_argument("files", nargs="+", type=Path)
    args = ap.parse_args(argv)
    if (args.scene is None) == (args.new_toml is None):
        ap.error("give --scene (version-1 hashes) or --new-toml with --old-toml (evaluation sets), not both")
    if args.new_toml is not None and args.old_toml is None:
        ap.error("--new-toml needs --old-toml, the file the evaluation sets were made from")
    try:
        for f in args.files:
            done = (restamp(f, args.scene, args.old_toml) if args.scene
                    else restamp_evalset(f, args.old_toml, args.new_toml))
            print(f"{f}: {done}")
    except DiviewerError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
