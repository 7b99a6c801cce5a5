"""The shell commands of the docs run as written, so a page cannot drift from the CLI.

Every line of a ```bash / ```sh / ```console / ```shell block of DOCS that starts with ``diviewer `` (after an
optional ``$ ``) runs as ``python -m diviewer`` in a folder holding a small procedural glTF room, ``room.glb``
(the scene docs/own-scene.md is written for; other scenes a page names become it, a scene file `inspect` writes
becomes room.toml). Sizes shrink (``--res``,
``--size``, ``--frames``, ``--spp``); ``view`` runs a few frames in a window (the display fixture: Xvfb in CI;
without a display it is only parsed); ``build`` runs with ``--dry-run`` (a real build takes hours). The commands
that take minutes to hours and have no dry run (PARSE_ONLY), and a path-traced reference where Mitsuba is not
installed, are only parsed. The model the build would write is stood in for by a hand-built one of the room
(tests/onnx_models.py), so ``view`` and ``render --model`` run on it. Each command must exit 0.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from gltf_doc import _box, glb_bytes
from viewer.test_app import display  # noqa: F401 (the fixture: an Xvfb display for the view commands)

ROOT = Path(__file__).resolve().parents[1]
DOCS = ("docs/own-scene.md", "README.md", "docs/viewer.md", "docs/paths.md", "docs/scene-files.md", "docs/build.md",
        "docs/scaling.md", "docs/evaluation.md", "docs/speed.md", "docs/training.md")
FENCE = re.compile(r"^```(?:bash|sh|console|shell)[ \t]*\n(.*?)^```", re.M | re.S)
TOML_FENCE = re.compile(r"^```toml[ \t]*\n(.*?)^```", re.M | re.S)
PARSE_ONLY = {"capture", "train", "evalset", "export", "baseline", "bench", "eval", "data"}
"""Minutes to hours each, and no --dry-run: checked by the CLI's parser only."""
SHRINK = {"--res": "32", "--size": "64x48", "--frames": "3", "--spp": "4"}
MODEL = "runs/room/room.onnx"
"""Where `diviewer build --scene room.toml` ships the room's model (the work folder)."""
HAS_MITSUBA = importlib.util.find_spec("mitsuba") is not None

WALLS = [("floor", (4.4, 0.2, 4.4), (0, -0.1, 0)), ("ceiling", (4.4, 0.2, 4.4), (0, 3.1, 0)),
         ("left", (0.2, 3, 4), (-2.1, 1.5, 0)), ("right", (0.2, 3, 4), (2.1, 1.5, 0)),
         ("back", (4, 3, 0.2), (0, 1.5, -2.1)), ("front", (4, 3, 0.2), (0, 1.5, 2.1))]
"""tests/room_doc.py's room as glTF nodes: (name, scale of the unit box, translation)."""


def room_glb() -> bytes:
    """The room of tests/room_doc.py as a .glb: six walls of the material 'plaster' and a pedestal without one (it
    gets gltf_default), no light (inspect suggests a point light)."""
    v, f = _box()
    vb, fb = v.tobytes(), f.ravel().tobytes()
    blob = vb + fb + b"\0" * (-len(fb) % 4)
    prim = {"attributes": {"POSITION": 0}, "indices": 1}
    nodes = [{"name": n, "mesh": 0, "scale": list(s), "translation": list(t)} for n, s, t in WALLS]
    nodes.append({"name": "pedestal", "mesh": 1, "scale": [0.8, 1, 0.8], "translation": [0, 0.5, 0]})
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(blob)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(vb)},
                        {"buffer": 0, "byteOffset": len(vb), "byteLength": len(fb)}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3",
                       "min": [-0.5] * 3, "max": [0.5] * 3},
                      {"bufferView": 1, "componentType": 5123, "count": 36, "type": "SCALAR"}],
        "materials": [{"name": "plaster", "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.9, 0.85, 1]}}],
        "meshes": [{"name": "wall", "primitives": [dict(prim, material=0)]},
                   {"name": "block", "primitives": [dict(prim)]}],
        "nodes": nodes,
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
    }
    return glb_bytes(doc, blob)


def doc_commands(markdown: str) -> list[list[str]]:
    """The argv (after ``diviewer``) of every command line in the page's shell blocks, continuations joined."""
    out = []
    for block in FENCE.findall(markdown):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.strip().removeprefix("$ ")
            if line.startswith("diviewer "):
                out.append(shlex.split(line, comments=True)[1:])
    return out


def shrink(argv: list[str]) -> list[str]:
    """The command on the tiny room: small sizes, the room for any other scene, the stand-in for any model."""
    out = list(argv)
    for i, word in enumerate(out[:-1]):
        value = out[i + 1]
        if word in SHRINK:
            out[i + 1] = SHRINK[word]
        elif word == "--scene" and value not in ("room.glb", "room.toml"):
            out[i + 1] = "room.glb" if value.endswith((".glb", ".gltf")) else "room.toml"
        elif word == "--write-toml":
            out[i + 1] = "room.toml"
        elif word == "--model" and value.endswith(".onnx"):
            out[i + 1] = MODEL
    if out[0] == "view":
        for flag in ("--frames", "--size"):
            if flag not in out:
                out += [flag, SHRINK[flag]]
    if out[0] == "build" and "--dry-run" not in out:
        out.append("--dry-run")
    return out


def _stand_in_model(folder: Path) -> None:
    """The model a build of room.toml ships, stood in for by radiance = 2 x direct, tied to the room as it is."""
    from onnx_models import base_meta, direct_times

    from diviewer.scene import load_scene

    scene = load_scene(folder / "room.toml")
    (folder / MODEL).parent.mkdir(parents=True, exist_ok=True)
    direct_times(folder / MODEL, meta=base_meta(scene_hash=scene.file_hash, scene=scene.name))


def _recorded_without_a_window(argv: list[str], folder: Path) -> None:
    """What ``view --record-path F`` of a still camera writes, for the commands after it when no window can open:
    two keys, a second apart, at the scene file's camera."""
    from diviewer.scene import load_scene
    from diviewer.scene.camera_path import CameraPath, PathKey, write_path

    scene = load_scene(folder / argv[argv.index("--scene") + 1])
    keys = tuple(PathKey(time=t, camera=scene.default.camera) for t in (0.0, 1.0))
    write_path(folder / argv[argv.index("--record-path") + 1],
               CameraPath(keys=keys, scene=scene.name, scene_hash=scene.file_hash))


def _parses(argv: list[str]) -> None:
    from diviewer.cli import build_parser

    try:
        build_parser().parse_args(argv)
    except SystemExit as exc:
        pytest.fail(f"`diviewer {shlex.join(argv)}` no longer parses (exit {exc.code})")


def _run(argv: list[str], folder: Path) -> None:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    r = subprocess.run([sys.executable, "-m", "diviewer", *argv], cwd=folder, env=env, capture_output=True,
                       text=True, timeout=300)
    said = r.stdout[-2000:] + r.stderr[-2000:]
    assert r.returncode == 0, f"`diviewer {shlex.join(argv)}` exit {r.returncode}:\n{said}"


def test_the_extraction_reads_fences_prompts_continuations_and_comments():
    page = ("```console\n$ diviewer view --scene a.toml   # fly\n```\n```\ndiviewer not-a-shell-block\n```\n"
            "```bash\necho hi\ndiviewer render --scene a.toml \\\n  --res 512 --out x\n```\n")
    assert doc_commands(page) == [["view", "--scene", "a.toml"], ["render", "--scene", "a.toml", "--res", "512",
                                                                    "--out", "x"]]
    assert shrink(["view", "--scene", "sponza", "--model", "m.onnx"]) == [
        "view", "--scene", "room.toml", "--model", MODEL, "--frames", "3", "--size", "64x48"]
    assert shrink(["build", "--scene", "x.glb", "--res", "256"]) == [
        "build", "--scene", "room.glb", "--res", "32", "--dry-run"]


def test_the_walkthrough_covers_every_step():
    commands = doc_commands((ROOT / "docs/own-scene.md").read_text(encoding="utf-8"))
    used = {argv[0] for argv in commands}
    assert {"inspect", "render", "build", "view"} <= used, used
    assert any("--write-toml" in a for a in commands) and any("--record-path" in a for a in commands)
    assert any("--video" in a for a in commands)


def test_the_scene_snippets_of_the_walkthrough_load_on_the_room(tmp_path):
    """Each TOML block of docs/own-scene.md, under a [scene] that imports room.glb, loads (its fields and ranges as
    the loader checks them), and each material it sets overrides one the room's objects wear."""
    from diviewer.scene import load_scene

    (tmp_path / "room.glb").write_bytes(room_glb())
    blocks = TOML_FENCE.findall((ROOT / "docs/own-scene.md").read_text(encoding="utf-8"))
    assert blocks
    for i, block in enumerate(blocks):
        path = tmp_path / f"snippet{i}.toml"
        path.write_text('[scene]\nname = "room"\n[gltf]\nfile = "room.glb"\n' + block)
        scene = load_scene(path)
        worn = {o.material for o in scene.default.objects}
        assert set(tomllib.loads(block).get("materials", {})) <= worn, (block, worn)


def _run_page(page: str, tmp_path: Path, windows: bool, room: Path) -> int:
    """Every command of ``page`` in its order, in a folder of its own with the room and ``room`` (the scene file
    `inspect --write-toml` writes for it); how many ran (not only parsed)."""
    commands = [shrink(argv) for argv in doc_commands((ROOT / page).read_text(encoding="utf-8"))]
    if not commands:
        return 0
    folder = tmp_path / Path(page).stem
    folder.mkdir()
    (folder / "room.glb").write_bytes(room_glb())
    # room.toml first: commands before the page's own inspect (a README's flight) fly it; the page's
    # inspect --write-toml then writes it anew, as in the fresh folder the page is written for.
    shutil.copyfile(room, folder / "room.toml")
    ran = 0
    for argv in commands:
        if argv[0] == "inspect" and "--write-toml" in argv:
            (folder / argv[argv.index("--write-toml") + 1]).unlink(missing_ok=True)
        if (argv[0] in PARSE_ONLY or ("--reference" in argv and not HAS_MITSUBA)
                or (argv[0] == "view" and not windows)):
            _parses(argv)
            if argv[0] == "view" and "--record-path" in argv:
                _recorded_without_a_window(argv, folder)
            continue
        if MODEL in argv and not (folder / MODEL).exists():
            _stand_in_model(folder)
        _run(argv, folder)
        ran += 1
    return ran


@pytest.mark.slow
def test_the_commands_of_the_docs_run(tmp_path, request):
    """Every command of each page, in the page's order, on the room in a folder of its own, room.toml written
    first. Without a display (and without DIVIEWER_REQUIRE_GL, where
    that fails) the window commands are only parsed."""
    try:
        request.getfixturevalue("display")
        windows = True
    except pytest.skip.Exception:
        windows = False
    from concurrent.futures import ThreadPoolExecutor

    # The pages run side by side (each in its own folder, its commands in order): the commands are processes,
    # so two pages at a time keep both cores busy.
    first = tmp_path / "inspected"
    first.mkdir()
    (first / "room.glb").write_bytes(room_glb())
    _run(["inspect", "--scene", "room.glb", "--write-toml", "room.toml"], first)  # once: every page starts from it
    with ThreadPoolExecutor(max_workers=2) as pool:
        ran = sum(pool.map(lambda page: _run_page(page, tmp_path, windows, first / "room.toml"), DOCS))
    assert ran >= (8 if windows else 5), ran
