"""Random edits of a nested document (a parsed glTF or scene file) for the hypothesis tests of tests/extremes:
a value replaced, a key or item removed, or an item added, as a careless hand or a broken exporter would."""

from __future__ import annotations

import copy

from hypothesis import strategies as st


def paths(obj, prefix=()):
    """Every path (a tuple of keys and indices) into a nested dict/list document, the root's () first."""
    yield prefix
    items = obj.items() if isinstance(obj, dict) else enumerate(obj) if isinstance(obj, list) else ()
    for k, v in items:
        yield from paths(v, prefix + (k,))


def mutate(draw, doc, edits, values, keys) -> None:
    """Apply ``edits`` random edits to ``doc`` in place (``draw``: hypothesis's); a replaced or added value is
    drawn from the strategy ``values``, a new key of a table from the strategy ``keys``."""
    for _ in range(edits):
        path = draw(st.sampled_from([p for p in paths(doc) if p]))
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        op = draw(st.sampled_from(["replace", "replace", "delete", "add"]))
        if op == "replace":
            parent[path[-1]] = draw(values)
        elif op == "delete":
            del parent[path[-1]]
        elif isinstance(parent, list):
            parent.append(copy.deepcopy(parent[path[-1]]) if draw(st.booleans()) else draw(values))
        else:
            parent[draw(keys)] = draw(values)
