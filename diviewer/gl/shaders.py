"""Shader programs loaded by name from shaders/, one file per program, through one cache."""

from __future__ import annotations

import re
from pathlib import Path

import moderngl

from diviewer.paths import shaders_dir

_STAGES = {
    "vertex_shader": "VERTEX_SHADER",
    "fragment_shader": "FRAGMENT_SHADER",
    "geometry_shader": "GEOMETRY_SHADER",
    "compute_shader": "COMPUTE_SHADER",
}
_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.MULTILINE)


def _source(name: str, seen: tuple[str, ...] = ()) -> str:
    if name in seen:
        raise RuntimeError(f"shader include cycle: {' -> '.join(seen + (name,))}")
    path = Path(shaders_dir()) / name
    return _resolve(path.read_text(), seen + (name,))


def _resolve(text: str, seen: tuple[str, ...] = ()) -> str:
    """``text`` with each ``#include "file"`` replaced by that file of shaders/ (recursively)."""
    return _INCLUDE.sub(lambda m: _source(m.group(1), seen), text)


class ShaderCache:
    """Programs keyed on (file name, defines); a program is compiled once per context."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self._programs: dict[tuple, moderngl.Program | moderngl.ComputeShader] = {}

    def program(self, name: str, defines: dict[str, object] | None = None) -> moderngl.Program:
        """A vertex/fragment program from ``shaders/<name>``; stages present are those it defines."""
        key = (name, tuple(sorted((defines or {}).items())))
        if key not in self._programs:
            src = _source(name)
            stages = {}
            for arg, macro in _STAGES.items():
                if macro == "COMPUTE_SHADER" or f"defined {macro}" not in src:
                    continue
                stages[arg] = self._with_defines(src, {macro: 1, **(defines or {})})
            self._programs[key] = self.ctx.program(**stages)
        return self._programs[key]

    def compute(self, name: str, defines: dict[str, object] | None = None) -> moderngl.ComputeShader:
        key = (name, "compute", tuple(sorted((defines or {}).items())))
        if key not in self._programs:
            src = _source(name)
            self._programs[key] = self.ctx.compute_shader(self._with_defines(src, {"COMPUTE_SHADER": 1, **(defines or {})}))
        return self._programs[key]

    def compute_source(self, text: str, defines: dict[str, object] | None = None) -> moderngl.ComputeShader:
        """A compute shader from source text that may ``#include`` files of shaders/ (e.g. a test's probe of
        a shader function); not cached."""
        return self.ctx.compute_shader(self._with_defines(_resolve(text), {"COMPUTE_SHADER": 1, **(defines or {})}))

    @staticmethod
    def _with_defines(src: str, defines: dict[str, object]) -> str:
        head = "#version 430 core\n" + "".join(f"#define {k} {v}\n" for k, v in defines.items())
        return head + "#line 1\n" + src

    def release(self) -> None:
        for p in self._programs.values():
            p.release()
        self._programs.clear()
