"""Carry an evaluation set over to an edited scene file whose change none of its frames can see.

Usage: python tools/restamp_evalset.py --old-toml OLD.toml --new-toml NEW.toml EVALSET [EVALSET ...]

A scene file's identity (diviewer.scene.identity) changes with every mesh it declares, even one that only the
sampler's ranges name (cornell's ``train_meshes``). An evaluation set records that identity, and `diviewer eval`
refuses models of another one; rendering the set again costs hours at 1024 spp. When the new file only adds or
edits meshes that no frame of the set shows, and nothing else that the identity covers changed, every frame is
still a frame of the new scene, rendered exactly as the new file would render it: the set is restamped. Checked:
the set's recorded identity is OLD.toml's; the two files are equal once their ranges, camera, display exposure and
``[meshes]`` are left out; every mesh a frame's configuration names is declared the same in both (or in neither);
neither file loads other files (a glTF's bytes are part of the identity). The manifest then records the new
identity, the new file's text and where it came from (``restamped``); written atomically.
"""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from pathlib import Path

from diviewer import imageio
from diviewer.errors import DiviewerError
from diviewer.scene import load_scene
from diviewer.scene.identity import NOT_IDENTITY


def _looks(data: dict) -> dict:
    """What the identity covers, less the mesh declarations (compared mesh by mesh)."""
    out = {k: v for k, v in data.items() if k not in NOT_IDENTITY and k != "meshes"}
    if isinstance(out.get("scene"), dict):
        out["scene"] = {k: v for k, v in out["scene"].items() if k != "exposure"}
    return out


def frame_meshes(manifest: dict) -> set[str]:
    """Every mesh name a frame's configuration draws."""
    return {o["mesh"] for f in manifest["frame_list"] for o in f["config"]["objects"]}


def restamp(evalset: Path, old_toml: Path, new_toml: Path) -> str:
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
    old_data, new_data = (tomllib.loads(p.read_text()) for p in (old_toml, new_toml))
    for toml, data in ((old_toml, old_data), (new_toml, new_data)):
        loads = [n for n, m in data.get("meshes", {}).items() if "file" in m or "gltf" in m] + (
            ["gltf"] if "gltf" in data else [])
        if loads:
            raise DiviewerError(f"loads other files ({', '.join(loads)}): only self-contained scene files are carried "
                                f"over", path=toml, field="meshes")
    if _looks(old_data) != _looks(new_data):
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
    manifest["scene_toml"] = new_toml.read_text()
    manifest["scene_file"] = str(new_toml.resolve())
    imageio.write_text(mpath, json.dumps(manifest, indent=1))
    return f"restamped (meshes added: {', '.join(added) or 'none'}; edited: {', '.join(edited) or 'none'})"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old-toml", type=Path, required=True, help="the scene file the sets were made from")
    ap.add_argument("--new-toml", type=Path, required=True, help="the edited scene file")
    ap.add_argument("evalsets", nargs="+", type=Path)
    args = ap.parse_args(argv)
    try:
        for e in args.evalsets:
            print(f"{e}: {restamp(e, args.old_toml, args.new_toml)}")
    except DiviewerError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
