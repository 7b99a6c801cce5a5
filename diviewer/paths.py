"""Where the shipped shaders and assets live: inside the wheel, or beside the package in a checkout."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

_PKG = Path(__file__).resolve().parent


@lru_cache(maxsize=None)
def _root(name: str) -> Path:
    for candidate in (_PKG / "_shipped" / name, _PKG.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"diviewer's '{name}' folder is missing from {_PKG} (broken install?)")


def shaders_dir() -> Path:
    """The folder of GLSL programs, one file per program."""
    return _root("shaders")


def assets_dir() -> Path:
    """The folder of shipped scenes and models."""
    return _root("assets")


def scenes_dir() -> Path:
    return assets_dir() / "scenes"


def shipped_scenes() -> list[str]:
    """The names `--scene` accepts besides a path: the shipped scene files' stems, read from the assets folder."""
    return sorted(p.stem for p in scenes_dir().glob("*.toml"))


def models_dir() -> Path:
    return assets_dir() / "models"


def default_work_dir(scene: str | Path) -> Path:
    """Where `diviewer build` works and ships by default for ``scene`` (a shipped name or a scene file):
    runs/<the file's stem>, under the current folder."""
    return Path("runs") / Path(str(scene)).stem


def scene_help(default: str | None = None) -> str:
    """--scene's help: the shipped scenes as the assets folder has them (not a list kept by hand)."""
    tail = f" (default {default})" if default else ""
    return f"shipped scene name ({', '.join(shipped_scenes())}) or a .toml path{tail}"
