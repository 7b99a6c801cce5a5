"""A scene file to start from, for a glTF scene: the import, the suggested camera and camera region, a light with
its range, and every material as a commented override. `diviewer inspect --write-toml` writes it. No GL."""

from __future__ import annotations

import json
import os
from pathlib import Path

from diviewer.scene.gltf import DEFAULT_MATERIAL
from diviewer.scene.gltf_material import toml_key
from diviewer.scene.model import DirectionalLight, Scene


def gltf_source(scene: Scene) -> Path | None:
    """The glTF file a scene's meshes came from (a glTF mesh's source is ``<file>#meshes[i]...``), or None."""
    for mesh in scene.meshes.values():
        head, sep, tail = mesh.source.rpartition("#")
        if sep and tail.startswith("meshes["):
            return Path(head)
    return None


def _v(v) -> str:
    return "[" + ", ".join(f"{float(x):.4g}" for x in v) + "]"


def _s(text: str) -> str:
    return json.dumps(text)  # a JSON string is a TOML basic string


def skeleton_toml(scene: Scene, report: dict, toml_path: Path) -> str:
    """The text of a scene file importing the scene's glTF file (by its path from ``toml_path``'s folder), with
    the survey ``report``'s suggestions (diviewer.scene.survey.survey).

    Raises:
        ValueError: the scene imports no glTF file (its meshes and objects cannot be written back).
    """
    source = gltf_source(scene)
    if source is None:
        raise ValueError("the scene imports no glTF file")
    rel = os.path.relpath(source.resolve(), toml_path.resolve().parent).replace(os.sep, "/")
    sug = report["suggested"]
    cam, reg = sug["camera"], sug["camera_region"]
    lo, hi = reg["region"]
    out = [f"# A scene file for {source.name}, written by `diviewer inspect`: check every value, then look at it",
           f"# (diviewer view --scene {toml_path.name}). Every field: docs/scene-files.md.",
           f"# Scene bounds {_v(report['bounds']['min'])} to {_v(report['bounds']['max'])}, "
           f"{report['triangles']} triangles."]
    out += [f"# warning: {w}" for w in report["warnings"]]
    out += ["", "[scene]", f"name = {_s(scene.name)}",
            "auto_exposure = true  # meter each frame: an unknown scene's brightness is a guess", "",
            "[gltf]", f"file = {_s(rel)}", "",
            "# The suggested camera: a corner of the largest open space, looking at the scene's centre.",
            "[camera]", f"position = {_v(cam['position'])}", f"target = {_v(cam['target'])}", "up = [0.0, 1.0, 0.0]",
            f"fov = {cam['fov']:g}", f"near = {cam['near']:.4g}", f"far = {cam['far']:.4g}", ""]
    out.append("# The file's materials: uncomment a table to override the values it gives (the rest stay).")
    for name, m in scene.materials.items():
        if name == DEFAULT_MATERIAL:
            out += [f"[materials.{DEFAULT_MATERIAL}]  # meshes without a material (glTF's default is albedo 1.0)",
                    "albedo = [0.8, 0.8, 0.8]"]
            continue
        out += [f"# [materials.{toml_key(name)}]", f"# albedo = {_v(m.albedo)}", f"# emission = {_v(m.emission)}"]
    out.append("")
    lights = list(scene.default.lights)
    for light in lights:
        out += ["[[lights]]", f"name = {_s(light.name)}"]
        if isinstance(light, DirectionalLight):
            out += ['type = "directional"', f"direction = {_v(light.direction)}", f"irradiance = {light.irradiance:g}"]
        else:
            out += ['type = "point"', f"position = {_v(light.position)}", f"intensity = {light.intensity:g}"]
        out += [f"color = {_v(light.color)}", ""]
    lamp_box = None
    if not lights:
        # A lamp at the top of the open space, bright enough to give ~2 W/m^2 on the floor below it.
        top = [(lo[0] + hi[0]) / 2, hi[1], (lo[2] + hi[2]) / 2]
        drop = max(hi[1] - report["bounds"]["min"][1], 1e-3)
        lamp_box = ([lo[0], (lo[1] + hi[1]) / 2, lo[2]], hi)
        out += ["# No lights in the file: a point light at the top of the open space (more types: docs/scene-files.md).",
                "[[lights]]", 'name = "lamp"', 'type = "point"', f"position = {_v(top)}",
                f"intensity = {2.0 * drop * drop:.4g}", "",
                "# Or a sun:", "# [[lights]]", '# name = "sun"', '# type = "directional"',
                "# direction = [-0.3, -1.0, -0.4]", "# irradiance = 3.0", ""]
    out += ["# Where the capture may put the camera: the largest open box found, looking at the centre.",
            "[ranges.camera]", f"region = [{_v(lo)}, {_v(hi)}]", f"target = {_v(reg['target'])}",
            f"target_jitter = {_v(reg['target_jitter'])}", f"fov = {_v(reg['fov'])}", "default_share = 0.1", ""]
    if lamp_box is not None:
        out += ["# The lamp anywhere in the upper half of the open box, half to twice as bright.",
                "[ranges.lights.lamp]", f"position = [{_v(lamp_box[0])}, {_v(lamp_box[1])}]",
                "intensity = [0.5, 2.0]", ""]
    return "\n".join(out)
