"""Import a script of tools/ (not a package) as a module, for its tests."""

from __future__ import annotations

import importlib.util
from pathlib import Path

TOOLS = Path(__file__).resolve().parents[1] / "tools"


def load_tool(name: str):
    """tools/NAME.py as a module; the measurements of tools/experiments/ are not the product, and no test loads
    them (an oracle a test needs lives in tests/oracles.py)."""
    if name.startswith("experiments/"):
        raise ValueError(f"{name}: tests check the product, not tools/experiments/ (see tests/oracles.py)")
    spec = importlib.util.spec_from_file_location(name, TOOLS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
