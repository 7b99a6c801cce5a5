"""A recipe's every field, each with values a hostile user writes: any value its spec refuses (a wrong type, bool
for a number, 12.7 for a whole number, NaN, out of range, an unknown name) is refused when the recipe is read,
naming the file and ``table.field``; any value it takes loads; and the rules between fields hold at the read, so
`diviewer build --dry-run` stops where the run would."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given, strategies as st

from diviewer.cli import main
from diviewer.errors import DiviewerError
from diviewer.fieldspec import Bool, Choice, Float, Floats, Int, Ints, Maybe, Table, Text
from diviewer.train.recipe import load_recipe
from diviewer.train.recipe_fields import TABLES


def toml_value(v) -> str:
    """``v`` as a TOML value (inline tables and arrays; NaN and the infinities as TOML spells them)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()) + " }"
    return "[" + ", ".join(toml_value(x) for x in v) + "]"


INT64 = (-(2**63), 2**63 - 1)
WORDS = st.text(alphabet="abcdefghijklmnopqrstuvwxyz_0123456789", min_size=1, max_size=12)
NOT_NUMBERS = st.one_of(st.booleans(), WORDS, st.lists(st.integers(0, 9), max_size=2))


def invalid(spec):
    """Values ``spec`` refuses (that TOML can hold)."""
    if isinstance(spec, Maybe):
        return invalid(spec.spec)
    if isinstance(spec, Int):
        out = [st.integers(INT64[0], spec.lo - 1), st.floats(allow_nan=True), NOT_NUMBERS]
        if spec.hi < INT64[1]:
            out.append(st.integers(spec.hi + 1, INT64[1]))
        if spec.power_of_two:
            out.append(st.integers(spec.lo, spec.hi).filter(lambda v: v & (v - 1)))
        return st.one_of(*out)
    if isinstance(spec, Float):
        below = st.floats(max_value=spec.lo, exclude_max=not spec.lo_open)
        above = st.floats(min_value=spec.hi, exclude_min=not spec.hi_open)
        return st.one_of(below, above, st.just(math.nan), NOT_NUMBERS)
    if isinstance(spec, Bool):
        return st.one_of(st.integers(0, 1), st.sampled_from(["no", "yes", "true", "false"]), st.floats())
    if isinstance(spec, Choice):
        return st.one_of(WORDS.filter(lambda w: w not in spec.names), st.integers(), st.booleans())
    if isinstance(spec, Text):
        return st.one_of(st.integers(), st.booleans(), st.floats(), st.lists(WORDS, max_size=2),
                         st.just("x" * (spec.max_len + 1)))
    if isinstance(spec, Ints):
        bad_item = st.lists(valid(spec.item), min_size=max(spec.min_len - 1, 0), max_size=spec.max_len - 1).flatmap(
            lambda good: invalid(spec.item).map(lambda b: [*good, b]))
        out = [bad_item, st.integers(), WORDS, st.lists(valid(spec.item), min_size=spec.max_len + 1,
                                                         max_size=spec.max_len + 2)]
        if spec.increasing:
            out.append(st.lists(valid(spec.item), min_size=2, max_size=4).filter(lambda v: v != sorted(set(v))))
        return st.one_of(*out)
    if isinstance(spec, Floats):
        wrong_length = st.lists(valid(spec.item), max_size=spec.n + 2).filter(lambda v: len(v) != spec.n)
        one_bad = st.tuples(st.lists(valid(spec.item), min_size=spec.n - 1, max_size=spec.n - 1),
                            invalid(spec.item)).map(lambda t: [*t[0], t[1]])
        return st.one_of(wrong_length, one_bad, NOT_NUMBERS)
    if isinstance(spec, Table):
        name = st.sampled_from(sorted(spec.fields))
        return st.one_of(st.integers(), WORDS, st.just({"no_such_field": 1}),
                         name.flatmap(lambda n: invalid(spec.fields[n]).map(lambda b: {n: b})))
    raise AssertionError(f"no strategy for {spec!r}")


def valid(spec):
    """Values ``spec`` takes."""
    if isinstance(spec, Maybe):
        return valid(spec.spec)
    if isinstance(spec, Int):
        if spec.power_of_two:
            return st.sampled_from([1 << k for k in range(64) if spec.lo <= 1 << k <= spec.hi])
        return st.integers(spec.lo, spec.hi)
    if isinstance(spec, Float):
        return st.floats(spec.lo, spec.hi, exclude_min=spec.lo_open, exclude_max=spec.hi_open)
    if isinstance(spec, Bool):
        return st.booleans()
    if isinstance(spec, Choice):
        return st.sampled_from(spec.names)
    if isinstance(spec, Text):
        return WORDS
    if isinstance(spec, Ints):
        items = st.lists(valid(spec.item), min_size=spec.min_len, max_size=min(spec.max_len, 4), unique=True)
        return items.map(sorted) if spec.increasing else items
    if isinstance(spec, Floats):
        return st.lists(valid(spec.item), min_size=spec.n, max_size=spec.n)
    if isinstance(spec, Table):
        return st.fixed_dictionaries({}, optional={k: valid(v) for k, v in spec.fields.items()})
    raise AssertionError(f"no strategy for {spec!r}")


FIELDS = [(table, name) for table, specs in TABLES.items() for name in specs]

CROSS = {
    ("capture", "frames"), ("capture", "split_fractions"), ("capture", "refine_from"), ("capture", "width"),
    ("capture", "height"), ("evalset", "ladder"), ("evalset", "spp"), ("evalset", "width"),
    ("evalset", "window_widths"), ("export", "fp16"), ("export", "half_weights"), ("export", "int8_weights"),
    ("train", "divide_albedo"), ("train", "ssim_exposure"), ("train", "world_inputs"), ("train", "light_inputs"),
    ("train", "world_frequencies"), ("train", "aspect_crops"), ("train", "light_scale"), ("train", "device"),
    ("train", "init_from"),
}
"""Fields whose valid values still meet a rule between fields (tested with examples below) or a form beyond the
spec (device: auto, cpu, cuda:N)."""


def _write(tmp_path, table: str, name: str, value) -> object:
    path = tmp_path / "r.toml"
    path.write_text(f"[{table}]\n{name} = {toml_value(value)}\n")
    return path


@pytest.mark.parametrize("table,name", FIELDS, ids=[f"{t}.{n}" for t, n in FIELDS])
@given(data=st.data())
def test_any_value_a_field_refuses_names_the_file_and_the_field(tmp_path, table, name, data):
    value = data.draw(invalid(TABLES[table][name]))
    path = _write(tmp_path, table, name, value)
    with pytest.raises(DiviewerError) as e:
        load_recipe(path)
    assert str(e.value).startswith(f"{path}: {table}.{name}"), (value, str(e.value))


VALID = [f for f in FIELDS if f not in CROSS]


@pytest.mark.parametrize("table,name", VALID, ids=[f"{t}.{n}" for t, n in VALID])
@given(data=st.data())
def test_any_value_a_field_takes_loads(tmp_path, table, name, data):
    value = data.draw(valid(TABLES[table][name]))
    rec = load_recipe(_write(tmp_path, table, name, value))
    held = {"recipe": {"name": rec.name, "description": rec.description, "scene": rec.scene},
            "ladder": {"K": rec.ladder, "tolerance_db": rec.tolerance_db, "max_mb": rec.max_mb}}.get(table)
    got = held[name] if held is not None else getattr(rec, table)[name]
    assert got == (tuple(value) if isinstance(value, list) else value)


@pytest.mark.parametrize("text,field", [
    ("[capture]\nsplit_fractions = [1, 0, 0]\n", "capture.split_fractions"),  # no val, no test split
    ("[capture]\nsplit_fractions = [0.5, 0.5, 0]\n", "capture.split_fractions"),  # no test split
    ("[capture]\nsplit_fractions = [0.8, 0.1, 0.2]\n", "capture.split_fractions"),  # adds up to 1.1
    ("[capture]\nframes = 5\n", "capture.split_fractions"),  # 0.1 of 5 frames is none
    ("[capture]\nspp = 16\nrefine_from = 16\n", "capture.refine_from"),
    ("[capture]\nwidth = 8\n", "capture.width"),
    ("[evalset]\nspp = 64\nladder = [1, 64]\n", "evalset.ladder"),
    ("[evalset]\nwindow_widths = [171, 228]\n", "evalset.window_widths"),
    ("[capture]\nwidth = 228\n[evalset]\nwidth = 127\n", "evalset.window_widths"),
    ("[export]\nfp16 = true\nhalf_weights = true\n", "export.half_weights"),
    ("[export]\nint8_weights = true\nfp16 = true\n", "export.int8_weights"),
    ("[train]\ntarget = 'full'\ndivide_albedo = true\n", "train.divide_albedo"),
    ("[train]\nlight_scale = false\nworld_inputs = true\n", "train.world_inputs"),
    ("[train]\nworld_frequencies = 4\n", "train.world_frequencies"),
    ("[train]\nssim_exposure = 'metered'\n", "train.ssim_exposure"),
    ("[train]\naspect_crops = [2.0, 1.0]\n", "train.aspect_crops"),
    ("[train]\ndevice = 'tpu'\n", "train.device"),
])
def test_rules_between_fields_are_held_when_the_recipe_is_read(tmp_path, text, field):
    path = tmp_path / "r.toml"
    path.write_text(text)
    with pytest.raises(DiviewerError) as e:
        load_recipe(path)
    assert str(e.value).startswith(f"{path}: {field}"), str(e.value)


# What a hostile user found: each passed `build --dry-run` and failed after hours, or shipped the wrong thing.
FOUND = [("export", "layout", '"NCWH"'), ("export", "verify_frames", "0"), ("ladder", "tolerance_db", "nan"),
         ("capture", "frames", "12.7"), ("export", "half_weights", '"no"'), ("capture", "spp", "true"),
         ("export", "verify_frames", "-1"), ("capture", "split_fractions", "[1, 0, 0]"),
         ("capture", "dtype", '"float64"'), ("capture", "thumbs", "-1"), ("capture", "gt", '"mitsuba"'),
         ("capture", "max_depth", "1"), ("capture", "vxgi_resolution", "100"), ("capture", "direct_samples", "0")]


@pytest.mark.parametrize("table,name,value", FOUND, ids=[f"{t}.{n}={v}" for t, n, v in FOUND])
def test_build_dry_run_refuses_what_the_run_would(tmp_path, capsys, table, name, value):
    text = (load_recipe("cornell").path.read_text())
    lines, out, cur = text.splitlines(), [], None
    for line in lines:  # the shipped recipe with this one field replaced (or added to its table)
        if line.startswith("["):
            if cur == table and not any(x.startswith(f"{name} =") for x in out[start:]):
                out.append(f"{name} = {value}")
            cur, start = line.strip("[] "), len(out)
        if cur == table and line.startswith(f"{name} ="):
            line = f"{name} = {value}"
        out.append(line)
    path = tmp_path / "hostile.toml"
    path.write_text("\n".join(out) + "\n")
    assert main(["build", "--recipe", str(path), "--work", str(tmp_path / "w"), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path}: {table}.{name}:" in err, err
    assert not (tmp_path / "w").exists()
