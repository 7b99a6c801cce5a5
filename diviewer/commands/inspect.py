"""`diviewer inspect`: what a scene holds and where a camera can go in it, and a scene file to start from.

Usage: diviewer inspect --scene model.glb [--json report.json] [--write-toml my_scene.toml]
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

from diviewer.commands.common import add_json, add_number, add_scene
from diviewer.errors import DiviewerError

GLTF_SUFFIXES = (".gltf", ".glb")


def add_parser(sub) -> None:
    """`diviewer inspect`."""
    p = sub.add_parser("inspect", help="a scene's bounds, triangles, materials, textures, lights and emitters, a "
                                       "suggested camera and camera region; optionally a scene file to start from")
    add_scene(p, default=None, required=True,
              help="a shipped scene's name, a scene file (.toml) or a glTF file (.gltf or .glb)")
    add_json(p, "also write the report as JSON to this file")
    p.add_argument("--write-toml", type=Path, default=None, metavar="FILE",
                   help="write a scene file importing the glTF with the suggested camera, camera region and a light "
                        "(never overwrites an existing file)")
    add_number(p, "--cells", default=32,
               help="grid cells along the scene's longest side in the open-space search (default 32)")
    p.set_defaults(func=run)


def load_any(scene: str):
    """A scene by shipped name, scene file or bare glTF file (imported as a scene file with only ``[gltf]``)."""
    from diviewer.scene import load_scene
    from diviewer.scene.loader import parse_scene

    p = Path(scene)
    if p.suffix.lower() not in GLTF_SUFFIXES:
        return load_scene(scene)
    if not p.is_file():
        raise DiviewerError(f"glTF file not found: {p}", field="--scene")
    return parse_scene({"scene": {"name": p.stem}, "gltf": {"file": p.name}}, path=p)


def _check_new_file(path: Path, option: str, suffix: str) -> None:
    from diviewer.outputs import check_output_file

    if path.exists():
        raise DiviewerError(f"{path} exists; inspect never overwrites a file: give a new name", field=option)
    check_output_file(path, option, suffix=suffix)


def write_new(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` only if no file is there, atomically (a complete file or none)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.link(tmp, path)  # fails if the file appeared meanwhile: never replaced
    except FileExistsError:
        raise DiviewerError(f"{path} exists; inspect never overwrites a file: give a new name",
                            field="--write-toml") from None
    finally:
        os.unlink(tmp)


def run(args: argparse.Namespace) -> int:
    """Survey the scene, print the report, and write the JSON and the scene file asked for."""
    from diviewer.scene.survey import OpenSpaceSettings, survey

    for path, option, suffix in ((args.json, "--json", ".json"), (args.write_toml, "--write-toml", ".toml")):
        if path is not None:
            _check_new_file(path, option, suffix)
    import warnings

    from diviewer.scene.reads import SceneWarning

    with warnings.catch_warnings():  # the report lists the load's warnings: not said twice
        warnings.simplefilter("ignore", SceneWarning)
        scene = load_any(args.scene)
    bare = Path(args.scene).suffix.lower() in GLTF_SUFFIXES  # no camera of the author's to start from
    report = survey(scene, OpenSpaceSettings(cells=args.cells), near=None if bare else scene.default.camera.position)
    skeleton = None
    if args.write_toml is not None:
        skeleton = _skeleton(scene, report, args.write_toml)
    print(format_report(report))
    if args.json is not None:
        from diviewer.outputs import write_json

        write_json(args.json, report)
        print(f"wrote {args.json}")
    if skeleton is not None:
        write_new(args.write_toml, skeleton)
        print(f"wrote {args.write_toml}: check its materials, light and camera region (docs/own-scene.md), then: "
              f"diviewer render --scene {args.write_toml} --out check; diviewer build --scene {args.write_toml} "
              f"--dry-run")
    return 0


def _skeleton(scene, report: dict, path: Path) -> str:
    """The scene file to write, loaded once before it is written (a file that would not load is never written)."""
    import tomllib
    import warnings

    from diviewer.scene.loader import parse_scene
    from diviewer.scene.reads import SceneWarning
    from diviewer.scene.skeleton import skeleton_toml

    try:
        text = skeleton_toml(scene, report, path)
    except ValueError:
        raise DiviewerError("--write-toml writes a scene file for a glTF scene (a .gltf or .glb, or a scene file with "
                            "[gltf]); this scene's meshes are its own: copy the suggested [camera] and [ranges.camera] "
                            "printed above into it", field="--write-toml") from None
    with warnings.catch_warnings():  # the load above said them already
        warnings.simplefilter("ignore", SceneWarning)
        parse_scene(tomllib.loads(text), path=path)
    return text


def _v(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


def format_report(r: dict) -> str:
    """The survey report as the lines `diviewer inspect` prints."""
    b = r["bounds"]
    lines = [f"scene {r['scene']}" + (f" ({r['file']})" if r["file"] else ""),
             f"bounds {_v(b['min'])} to {_v(b['max'])}, size {_v(b['size'])}",
             f"{r['triangles']} triangles placed, {r['meshes']} meshes, {r['objects']} objects",
             f"materials ({len(r['materials'])}):"]
    for m in r["materials"]:
        notes = [f"albedo {_v(m['albedo'])}"]
        if max(m["emission"]) > 0:
            notes.append(f"emission {_v(m['emission'])}" + (f" x texture {m['emission_texture']}"
                                                             if m.get("emission_texture") else ""))
        if m["texture"]:
            notes.append(f"texture {m['texture']}")
        notes += (["alpha cut-out"] if m["masked"] else []) + (["DEFAULT (the file gives none)"] if m["default"] else [])
        lines.append(f"  {m['name']}: {', '.join(notes)}; {m['objects']} object(s)")
    lines.append(f"textures: {len(r['textures'])}" + "".join(
        f"\n  {t['material']}: {t['size'][0]}x{t['size'][1]} {t['source']}" for t in r["textures"]))
    lines.append(f"lights ({len(r['lights'])}):" if r["lights"] else "lights: none (add one: docs/scene-files.md)")
    for light in r["lights"]:
        where = (f"direction {_v(light['direction'])}, irradiance {light['irradiance']:g}"
                 if light["type"] == "directional" else
                 f"position {_v(light['position'])}, intensity {light['intensity']:g}")
        lines.append(f"  {light['name']} ({light['type']}): {where}, color {_v(light['color'])}")
    e = r["emissive"]
    lines.append(f"emissive surfaces: {e['area_m2']:g} m^2" + "".join(
        f"\n  {k}: {a:g} m^2" for k, a in e["materials"].items()))
    s = r["suggested"]
    cam, reg = s["camera"], s["camera_region"]
    lines += [f"open space: {s['open_cells']} open cells of {s['cell_size']:g} m; the largest open box has "
              f"{s['region_cells']}",
              "suggested [camera]:",
              f"  position = {list(cam['position'])}", f"  target = {list(cam['target'])}",
              f"  fov = {cam['fov']:g}", f"  near = {cam['near']:g}", f"  far = {cam['far']:g}",
              "suggested [ranges.camera]:",
              f"  region = {[list(x) for x in reg['region']]}", f"  target = {list(reg['target'])}",
              f"  target_jitter = {list(reg['target_jitter'])}", f"  fov = {list(reg['fov'])}"]
    lines += [f"warning: {w}" for w in r["warnings"]]
    return "\n".join(lines)
