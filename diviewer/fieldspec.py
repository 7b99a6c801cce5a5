"""What a settings field accepts, declared once beside the field: its type (a bool is not a number, 12.7 not a
whole number), its range (finite, bounded where a larger value would exhaust memory or time) or its names.

A recipe's tables (`diviewer.train.recipe_fields`), `TrainConfig` and the command line's numeric options
(`diviewer.options`) are checked through these, so a value is refused the same way wherever it comes from:
``check`` returns the value as the settings hold it (a TOML array as a tuple, an int as a float where a number is
asked for) or raises `Invalid` with what the field takes; `check_fields` names the file and ``table.field``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from diviewer.errors import DiviewerError

MAX_SIZE = 8192
"""The largest frame side a setting or an option may ask for (a recipe's capture, `view --size`, `--res`): half of
what every OpenGL 4.3 context guarantees (GL_MAX_TEXTURE_SIZE >= 16384), and one float32 RGBA buffer of 8192 x 8192
is already 1 GiB."""


class Invalid(ValueError):
    """A value a field refuses; the message says what the field takes (``sub``, ``value``: the nested field of a
    `Table` that refused, and its value)."""

    def __init__(self, message: str, sub: str | None = None, value: Any = None):
        super().__init__(message)
        self.sub, self.value = sub, value


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _g(v: float) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


@dataclass(frozen=True)
class Int:
    """A whole number in [lo, hi] (bool refused: Python counts True as 1)."""

    lo: int
    hi: int
    power_of_two: bool = False

    def describe(self) -> str:
        two = " (a power of two)" if self.power_of_two else ""
        return f"a whole number from {self.lo} to {self.hi}{two}"

    def check(self, v: Any) -> int:
        if not (isinstance(v, int) and not isinstance(v, bool) and self.lo <= v <= self.hi
                and (not self.power_of_two or v & (v - 1) == 0)):
            raise Invalid(f"must be {self.describe()}")
        return v


@dataclass(frozen=True)
class Float:
    """A finite number in [lo, hi] (an open end where ``lo_open``/``hi_open``); ints are taken as floats."""

    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False

    def describe(self) -> str:
        low = f"above {_g(self.lo)}" if self.lo_open else f"at least {_g(self.lo)}"
        high = f"below {_g(self.hi)}" if self.hi_open else f"at most {_g(self.hi)}"
        return f"a finite number {low} and {high}"

    def check(self, v: Any) -> float:
        ok = (_number(v) and math.isfinite(v) and (v > self.lo if self.lo_open else v >= self.lo)
              and (v < self.hi if self.hi_open else v <= self.hi))
        if not ok:
            raise Invalid(f"must be {self.describe()}")
        return float(v)


@dataclass(frozen=True)
class Bool:
    """true or false (not 0/1, not "no")."""

    def describe(self) -> str:
        return "true or false"

    def check(self, v: Any) -> bool:
        if not isinstance(v, bool):
            raise Invalid("must be true or false")
        return v


@dataclass(frozen=True)
class Choice:
    """One of a few names."""

    names: tuple[str, ...]

    def describe(self) -> str:
        return "one of " + ", ".join(self.names)

    def check(self, v: Any) -> str:
        if not (isinstance(v, str) and v in self.names):
            raise Invalid(f"must be {self.describe()}")
        return v


@dataclass(frozen=True)
class Text:
    """A string of at most ``max_len`` characters (a name, a description, a path)."""

    max_len: int = 4096

    def describe(self) -> str:
        return "a string"

    def check(self, v: Any) -> str:
        if not isinstance(v, str) or len(v) > self.max_len:
            raise Invalid(f"must be a string of at most {self.max_len} characters")
        return v


@dataclass(frozen=True)
class Ints:
    """A list of whole numbers, each as ``item``; ``increasing``: strictly; ``distinct``: no repeats."""

    item: Int
    min_len: int = 1
    max_len: int = 64
    increasing: bool = False
    distinct: bool = False

    def describe(self) -> str:
        order = "increasing " if self.increasing else "distinct " if self.distinct else ""
        return f"a list of {self.min_len} to {self.max_len} {order}whole numbers, each from {self.item.lo} to " \
               f"{self.item.hi}"

    def check(self, v: Any) -> tuple[int, ...]:
        try:
            if not isinstance(v, (list, tuple)) or not self.min_len <= len(v) <= self.max_len:
                raise Invalid("")
            out = tuple(self.item.check(x) for x in v)
        except Invalid:
            raise Invalid(f"must be {self.describe()}") from None
        if (self.increasing and list(out) != sorted(set(out))) or (self.distinct and len(set(out)) != len(out)):
            raise Invalid(f"must be {self.describe()}")
        return out


@dataclass(frozen=True)
class Floats:
    """A list of exactly ``n`` numbers, each as ``item``."""

    n: int
    item: Float

    def describe(self) -> str:
        return f"a list of {self.n} numbers, each {self.item.describe()}"

    def check(self, v: Any) -> tuple[float, ...]:
        try:
            if not isinstance(v, (list, tuple)) or len(v) != self.n:
                raise Invalid("")
            return tuple(self.item.check(x) for x in v)
        except Invalid:
            raise Invalid(f"must be {self.describe()}") from None


@dataclass(frozen=True)
class Maybe:
    """``spec``, or None (the field's "not set")."""

    spec: Any

    def describe(self) -> str:
        return self.spec.describe()

    def check(self, v: Any) -> Any:
        return None if v is None else self.spec.check(v)


@dataclass(frozen=True)
class Table:
    """A nested table of named fields (e.g. a recipe's ``[capture] truth_filter``)."""

    fields: Mapping[str, Any]

    def describe(self) -> str:
        return "a table of " + ", ".join(self.fields)

    def check(self, v: Any) -> dict[str, Any]:
        if not isinstance(v, dict):
            raise Invalid(f"must be {self.describe()}")
        unknown = sorted(set(v) - set(self.fields))
        if unknown:
            raise Invalid(f"has an unknown key '{unknown[0]}'; it takes {', '.join(self.fields)}")
        out = {}
        for name, value in v.items():
            try:
                out[name] = self.fields[name].check(value)
            except Invalid as exc:
                raise Invalid(str(exc), sub=name, value=value) from None
        return out


def check_value(spec: Any, value: Any, field: str, path: object | None = None) -> Any:
    """``spec.check(value)``, a refusal as a DiviewerError naming ``path`` and ``field``."""
    try:
        return spec.check(value)
    except Invalid as exc:
        if exc.sub is not None:  # a nested table's field
            field, value = f"{field}.{exc.sub}", exc.value
        raise DiviewerError(f"{exc}, got {value!r}", path=path, field=field) from None


def check_fields(values: Mapping[str, Any], specs: Mapping[str, Any], table: str,
                 path: object | None = None) -> dict[str, Any]:
    """Each of ``values`` checked by its spec (``specs``: field -> spec); a key without one is unknown. Returns the
    checked values; a refusal names ``path`` and ``table.field``."""
    unknown = sorted(set(values) - set(specs))
    if unknown:
        raise DiviewerError(f"unknown key '{unknown[0]}'; [{table}] takes {', '.join(sorted(specs))}", path=path,
                            field=f"{table}.{unknown[0]}")
    return {name: check_value(specs[name], v, f"{table}.{name}", path) for name, v in values.items()}
