"""The package's layout stays as the README's Layout section says: import arrows point down, torch stays in
train/, and no module outgrows what a reader holds in mind. Imports are read with ast (nothing is imported),
including those inside functions, since the heavy ones are deliberately lazy."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "diviewer"
MAX_LINES = 450

LAYERS = {
    # 0: leaves every floor may use
    "errors": 0, "paths": 0, "provenance": 0, "console": 0, "timing": 0, "imageio": 0, "metrics": 0, "outputs": 0,
    # 1: scene data and math, the channel encoding
    "scene/": 1, "encoding": 1, "padding": 1,
    # 2: what draws or runs a frame: GL passes, the path tracer, the onnxruntime model, frame records
    "gl/": 2, "reference/": 2, "runtime": 2, "frames": 2,
    # 3: datasets and single renders
    "data/": 3, "render": 3,
    # 4: training and evaluation
    "train/": 4, "evalset": 4, "evaluate": 4, "baseline": 4,
    # 5: the applications
    "viewer/": 5, "bench/": 5,
    # 6: the command line
    "cli": 6, "__main__": 6,
}
"""Each unit (a subpackage, or a top-level module) and its floor: a unit imports only its own floor or lower."""


def _unit(module: str) -> str:
    """``diviewer.gl.neural`` -> ``gl/``; ``diviewer.runtime`` -> ``runtime``."""
    parts = module.split(".")
    if len(parts) < 2:
        return parts[0]
    return f"{parts[1]}/" if (PACKAGE / parts[1]).is_dir() else parts[1]


def _modules() -> list[tuple[Path, str]]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out.append((path, ".".join(parts)))
    return out


def _imports(path: Path, module: str) -> set[str]:
    """Every module ``path`` imports, anywhere in it (lazy imports too), relative imports resolved; ``from
    diviewer import gl`` counts as importing ``diviewer.gl``."""
    names = set()
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[: len(package) - node.level + 1] + ([base] if base else []))
            names.add(base)
            if base == "diviewer":
                names.update(f"diviewer.{a.name}" for a in node.names)
    return names


GRAPH = {module: (_unit(module), path, _imports(path, module)) for path, module in _modules()}


def _offenders(source_units, forbidden) -> list[str]:
    """``module imports name`` for each module of ``source_units`` importing something ``forbidden`` accepts."""
    return sorted(f"{m} imports {name}" for m, (unit, _, names) in GRAPH.items()
                  if unit in source_units for name in names if forbidden(name))


def _is_unit(*units):
    return lambda name: name.startswith("diviewer.") and _unit(name) in units


def _is_root(*roots):
    return lambda name: name.split(".")[0] in roots


def test_the_graph_was_read(tmp_path):
    """The rules below judge something: every unit is placed, and imports (lazy, relative) are found."""
    units = {unit for unit, _, _ in GRAPH.values()} - {"diviewer"}
    assert units == set(LAYERS), f"place new units on a floor in LAYERS: {sorted(units ^ set(LAYERS))}"
    assert "diviewer.gl.display" in GRAPH["diviewer.viewer.app"][2]
    assert "torch" in GRAPH["diviewer.train.networks"][2]
    probe = tmp_path / "probe.py"
    probe.write_text("import os\nfrom . import sources\ndef f():\n    from ..gl.neural import NeuralPass\n"
                     "    import torch.nn\n")
    assert _imports(probe, "diviewer.viewer.probe") == {"os", "diviewer.viewer", "diviewer.gl.neural", "torch.nn"}


def test_no_import_points_upward():
    upward = sorted(f"{m} ({unit}, floor {LAYERS[unit]}) imports {name} ({_unit(name)}, floor {LAYERS[_unit(name)]})"
                    for m, (unit, _, names) in GRAPH.items() if unit in LAYERS
                    for name in names if name.startswith("diviewer.") and _unit(name) in LAYERS
                    and LAYERS[_unit(name)] > LAYERS[unit])
    assert not upward, "\n".join(upward)


def test_scene_imports_no_gl_no_torch_no_viewer():
    assert not _offenders({"scene/"}, _is_unit("gl/", "viewer/")), "scene/ is data and math"
    assert not _offenders({"scene/"}, _is_root("torch", "moderngl", "glfw", "imgui_bundle"))


def test_gl_imports_no_torch_and_no_viewer():
    assert not _offenders({"gl/"}, _is_unit("viewer/"))
    assert not _offenders({"gl/"}, _is_root("torch"))


def test_only_train_imports_torch():
    assert not _offenders(set(LAYERS) - {"train/"}, _is_root("torch", "torchvision"))


def test_viewer_bench_and_runtime_never_import_train():
    assert not _offenders({"viewer/", "bench/", "runtime"}, _is_unit("train/"))


@pytest.mark.parametrize("path", sorted(PACKAGE.rglob("*.py")), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_modules_stay_small(path):
    lines = len(path.read_text().splitlines())
    assert lines < MAX_LINES, f"{path.relative_to(PACKAGE)} has {lines} lines; split it into rooms (see README Layout)"
