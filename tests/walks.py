"""Walks through diviewer, recorded with `sys.setprofile`: what `tests/test_walks.py` and
`tests/viewer/test_frame_walk.py` measure (the definitions of a stop, a re-entry and a trip back are there)."""

from __future__ import annotations

import sys
from collections import Counter
from dataclasses import dataclass, field


def _module(frame) -> str | None:
    name = frame.f_globals.get("__name__", "")
    return name if name == "diviewer" or name.startswith("diviewer.") else None


@dataclass
class Walk:
    """What one call of a function did inside diviewer: its calls, in order, as (module, function, caller module)."""

    calls: list[tuple[str, str, str | None]] = field(default_factory=list)
    result: object = None

    @property
    def stops(self) -> list[str]:
        """The modules the walk passes through, consecutive calls into one module collapsed."""
        out: list[str] = []
        for module, _, _ in self.calls:
            if not out or out[-1] != module:
                out.append(module)
        return out

    def reentries(self) -> list[tuple[str | None, str]]:
        """(caller module, module) of each stop into a module the walk had left before."""
        seen, out, last = set(), [], None
        for module, _, caller in self.calls:
            if module != last:
                if module in seen:
                    out.append((caller, module))
                seen.add(module)
            last = module
        return out

    def edges(self) -> Counter:
        """How often each module called each other module."""
        return Counter((caller, module) for module, _, caller in self.calls if caller and caller != module)

    def trips_back(self) -> dict[tuple[str, str], list[str]]:
        """Each call from N into M made when M had already led to N (directly or through others) in this walk, as
        (N, M) and the functions of M so called."""
        graph: dict[str, set[str]] = {}

        def reaches(a: str, b: str) -> bool:
            seen, todo = {a}, [a]
            while todo:
                for y in graph.get(todo.pop(), ()):
                    if y == b:
                        return True
                    if y not in seen:
                        seen.add(y)
                        todo.append(y)
            return False

        back: dict[tuple[str, str], list[str]] = {}
        for module, function, caller in self.calls:
            if not caller or caller == module:
                continue
            if reaches(module, caller):
                names = back.setdefault((caller, module), [])
                if function not in names:
                    names.append(function)
            graph.setdefault(caller, set()).add(module)
        return back

    def calls_out_of(self, module: str) -> set[str]:
        """The other diviewer modules ``module`` called in this walk."""
        return {m for m, _, caller in self.calls if caller == module and m != module}

    def summary(self) -> str:
        reentered = Counter(m for _, m in self.reentries())
        return (f"{len(self.calls)} calls, {len(self.stops)} stops through {len(set(self.stops))} modules, "
                f"{len(self.reentries())} re-entries ({dict(reentered.most_common(8))} ...), "
                f"trips back: {self.trips_back()}")


def walk(fn, *args, **kwargs) -> Walk:
    """Run ``fn(*args, **kwargs)`` under `sys.setprofile` and return its walk through diviewer."""
    w = Walk()

    def profile(frame, event, arg):
        if event != "call":
            return
        module = _module(frame)
        if module is None:
            return
        caller, f = None, frame.f_back
        while f is not None and caller is None:
            caller, f = _module(f), f.f_back
        w.calls.append((module, frame.f_code.co_name, caller))

    previous = sys.getprofile()
    sys.setprofile(profile)
    try:
        w.result = fn(*args, **kwargs)
    finally:
        sys.setprofile(previous)
    return w
