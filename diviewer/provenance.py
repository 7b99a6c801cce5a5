"""What made an artifact: library versions and settings, recorded in manifests, checkpoints and models."""

from __future__ import annotations

import dataclasses
import platform
from importlib import metadata

import diviewer

_PACKAGES = ("numpy", "moderngl", "trimesh", "onnxruntime", "OpenEXR", "torch", "mitsuba", "onnx")


def versions() -> dict[str, str]:
    """Versions of diviewer, Python and the installed libraries that matter (missing ones omitted)."""
    out = {"diviewer": diviewer.__version__, "python": platform.python_version()}
    for name in _PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return out


def cpu_model() -> str:
    """The CPU's model name as /proc/cpuinfo gives it (e.g. "AMD EPYC"), else what ``platform`` knows."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            return next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), cpu)
    except OSError:
        return cpu


def settings_dict(settings) -> dict:
    """A frozen settings dataclass as a plain dict."""
    return dataclasses.asdict(settings)


def check_known_keys(cls, data, field: str, hint: str = "") -> None:
    """Refuse keys that are not fields of the settings dataclass ``cls`` (a newer or foreign file)."""
    from diviewer.errors import DiviewerError

    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise DiviewerError(f"unknown key(s) {unknown}; known keys are {sorted(known)}" + (f" ({hint})" if hint else ""),
                            field=field)
