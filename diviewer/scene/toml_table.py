"""One TOML table of a scene file being read: typed getters whose errors name the file and the field."""

from __future__ import annotations

import math

import numpy as np

from diviewer.errors import DiviewerError

FLOAT32_MAX = float(np.finfo(np.float32).max)
"""Every number ends up in float32 (GL uniforms, Mitsuba's rgb variants): larger ones are refused."""

def f32(v: float) -> bool:
    return abs(v) <= FLOAT32_MAX


class TomlTable:
    """One TOML table being read: typed getters that name the file and field in every error."""

    def __init__(self, data, path, where: str):
        if not isinstance(data, dict):
            raise DiviewerError(f"expected a table, got {type(data).__name__}", path=path, field=where)
        self.data, self.path, self.where, self.used = data, path, where, set()

    def _field(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def err(self, key: str, msg: str) -> DiviewerError:
        return DiviewerError(msg, path=self.path, field=self._field(key))

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default=None):
        self.used.add(key)
        return self.data.get(key, default)

    def str(self, key: str, default=None, choices=None) -> str:
        v = self.raw(key, default)
        if v is None:
            raise self.err(key, "missing required field")
        if not isinstance(v, str):
            raise self.err(key, f"expected a string, got {v!r}")
        if choices is not None and v not in choices:
            raise self.err(key, f"'{v}' is not one of {', '.join(choices)}")
        return v

    def bool(self, key: str, default=None) -> bool:
        v = self.raw(key, default)
        if v is None:
            raise self.err(key, "missing required field")
        if not isinstance(v, bool):
            raise self.err(key, f"expected true or false, got {v!r}")
        return v

    def num(self, key: str, default=None, lo=None, hi=None, lo_open=False, hi_open=False) -> float:
        v = self.raw(key, default)
        if v is None:
            raise self.err(key, "missing required field")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.err(key, f"expected a finite number, got {v!r}")
        v = float(v)
        if not f32(v):
            raise self.err(key, f"{v:g} is outside float32's range (+-3.4e38), in which it is rendered")
        if lo is not None and (v < lo or (lo_open and v == lo)):
            raise self.err(key, f"must be {'>' if lo_open else '>='} {lo}, got {v}")
        if hi is not None and (v > hi or (hi_open and v == hi)):
            raise self.err(key, f"must be {'<' if hi_open else '<='} {hi}, got {v}")
        return v

    def vec(self, key: str, n: int = 3, default=None, lo=None, hi=None):
        v = self.raw(key, default)
        if v is None:
            raise self.err(key, "missing required field")
        if (not isinstance(v, (list, tuple)) or len(v) != n
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)):
            raise self.err(key, f"expected {n} finite numbers, got {v!r}")
        if not all(f32(float(x)) for x in v):
            raise self.err(key, f"{v} is outside float32's range (+-3.4e38), in which it is rendered")
        if lo is not None and min(v) < lo:
            raise self.err(key, f"values must be >= {lo}, got {v}")
        if hi is not None and max(v) > hi:
            raise self.err(key, f"values must be <= {hi}, got {v}")
        return tuple(float(x) for x in v)

    def vecs(self, key: str, n: int = 3, default=None) -> tuple:
        v = self.raw(key, default)
        if v is None:
            raise self.err(key, "missing required field")
        if not isinstance(v, (list, tuple)):
            raise self.err(key, f"expected a list of {n}-vectors, got {v!r}")
        sub = TomlTable({str(i): x for i, x in enumerate(v)}, self.path, self._field(key))
        return tuple(sub.vec(str(i), n) for i in range(len(v)))

    def strs(self, key: str, default=()) -> tuple[str, ...]:
        v = self.raw(key, default)
        if not isinstance(v, (list, tuple)) or not all(isinstance(x, str) for x in v):
            raise self.err(key, f"expected a list of strings, got {v!r}")
        return tuple(v)

    def table(self, key: str, default=None) -> "TomlTable":
        v = self.raw(key, default if default is not None else {})
        return TomlTable(v, self.path, self._field(key))

    def finish(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            # Every getter marks its key as read, present or not: what was read is what this table allows.
            allowed = sorted(self.used)
            raise self.err(unknown[0], f"unknown key '{unknown[0]}'" + (f" (and {unknown[1:]})" if unknown[1:] else "")
                           + (f"; allowed keys: {', '.join(allowed)}" if allowed else "; this table takes no keys"))


def entries(tab: TomlTable, problem):
    """Each entry of a table of tables (``[materials]``, ``[ranges.lights]``, ...) as (key, its table),
    refusing a key for which ``problem(key)`` gives a reason; each entry, then the table, is checked for
    unknown keys once the caller has read it."""
    for key in list(tab.data):
        why = problem(key)
        if why:
            raise tab.err(key, why)
        t = tab.table(key)
        yield key, t
        t.finish()
    tab.finish()
