"""Every numeric option of every subcommand, found by walking the parser (`diviewer.commands.common.leaves` and
each parser's recorded `arguments`): NaN, infinities, -1, 0 and huge values
are refused before any work, exit 2, one line naming the option, no traceback; an option added without a range
(`diviewer.options.OPTIONS`) or a text kind (`TEXT_OPTIONS`) fails here."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import pytest
from hypothesis import given, strategies as st

import diviewer.cli as cli
from diviewer.commands.parser import arguments, leaves, option_table
from diviewer.fieldspec import Float, Int, Invalid
from diviewer.options import OPTIONS, TEXT_OPTIONS, check_options, option_spec

BAD = ["nan", "inf", "-inf", "-1", "0", "99999999999", "1e30", "1e-30"]
"""What a hostile user types into a number."""


def _kind(action: argparse.Action) -> str | None:
    """'flag', 'choice', 'path' or None (a value the options table must place)."""
    if action.nargs == 0:  # a flag, --help and --version included
        return "flag"
    if action.choices is not None:
        return "choice"
    if action.type is Path:
        return "path"
    return None


def _options():
    """(command words, subparser, action) for every option that takes a free value."""
    ap = cli.build_parser()
    for words, parser in leaves(ap):
        for action in arguments(parser):
            if action.option_strings and _kind(action) is None:
                yield words, parser, action


OPTIONS_SEEN = list(_options())
AP = cli.build_parser()


def test_every_option_is_numeric_with_a_range_or_declared_text():
    numeric = [(w, a.dest) for w, _, a in OPTIONS_SEEN if a.type in (int, float)]
    assert len(numeric) > 60, "the walk found the subcommands' options"
    unplaced = [f"{' '.join(w)} {a.option_strings[0]}" for w, _, a in OPTIONS_SEEN
                if option_spec(w[0], a.dest) is None and a.dest not in TEXT_OPTIONS]
    assert not unplaced, f"give each a range in diviewer.options.OPTIONS (or list it in TEXT_OPTIONS): {unplaced}"
    assert not [d for d in TEXT_OPTIONS if d in OPTIONS]


def test_the_option_table_lists_every_leaf_option_once():
    """`option_table` is the walk's public face: each leaf command's options with their dest, type and nargs."""
    rows = option_table(cli.build_parser())
    seen = {(r["command"], r["option_strings"][0]) for r in rows if r["option_strings"]}
    assert {(w, a.option_strings[0]) for w, _, a in OPTIONS_SEEN} <= seen
    assert len(seen) == len([r for r in rows if r["option_strings"]]), "an option recorded twice"
    spp = next(r for r in rows if r["command"] == ("data", "refine") and r["dest"] == "spp")
    assert spp["type"] is int and spp["required"] and spp["option_strings"] == ("--spp",)
    res = next(r for r in rows if r["command"] == ("bench",) and r["dest"] == "res")
    assert res["nargs"] == "+" and res["type"] is int


def _minimal_argv(words, parser, tmp: Path) -> list[str]:
    """The subcommand with its required arguments filled (paths that need not exist: nothing runs)."""
    argv = list(words)
    for action in arguments(parser):
        if not action.option_strings and action.dest not in ("help",) and action.nargs != "?":
            argv.append(str(tmp / "x"))
        elif action.required:
            spec = option_spec(words[0], action.dest)
            value = str(spec.lo) if isinstance(spec, (Int, Float)) else str(tmp / "y.onnx")
            argv += [action.option_strings[0], value]
    return argv


def _accepts(command: str, action, text: str) -> bool:
    """Whether the option's own type and spec take ``text`` (then the command would run: not tried here)."""
    try:
        value = action.type(text) if action.type else text
    except (ValueError, TypeError, argparse.ArgumentTypeError):
        return False
    try:
        for v in value if isinstance(value, tuple) and action.dest != "aspect_crops" else [value]:
            option_spec(command, action.dest).check(v)
    except Invalid:
        return False
    return True


@pytest.fixture
def no_work(monkeypatch):
    """The parser with every subcommand's function replaced: a bad value that got through fails the test."""
    real = cli.build_parser

    def build():
        ap = real()
        for _, parser in leaves(ap):
            parser.set_defaults(func=lambda args: pytest.fail(f"{args.command} started its work"))
        return ap

    monkeypatch.setattr(cli, "build_parser", build)


CASES = [(w, p, a, bad) for w, p, a in OPTIONS_SEEN if a.dest not in TEXT_OPTIONS for bad in BAD]


@pytest.mark.parametrize("words,parser,action,bad", CASES,
                         ids=[f"{' '.join(w)} {a.option_strings[0]} {b}" for w, _, a, b in CASES])
def test_a_bad_number_is_one_line_naming_the_option_and_exit_2(no_work, tmp_path, capsys, words, parser, action,
                                                                bad):
    if _accepts(words[0], action, bad):  # a value this option takes (0 for a count that may be none, -1 EV)
        assert bad not in ("nan", "inf", "-inf", "99999999999", "1e30"), f"{action.option_strings[0]} takes {bad}"
        return
    argv = [*_minimal_argv(words, parser, tmp_path), f"{action.option_strings[0]}={bad}"]
    try:
        rc = cli.main(argv)
    except SystemExit as exc:  # argparse's own: a usage line, then the error
        rc = exc.code
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith(("usage:", " "))]
    assert rc == 2 and "Traceback" not in err, err
    assert len(lines) == 1 and action.option_strings[0] in lines[0], err


def _numeric():
    return [(w, a) for w, _, a in OPTIONS_SEEN if isinstance(option_spec(w[0], a.dest), (Int, Float))]


def _outside(spec):
    """Values a spec refuses: beyond either end, and (for floats) not finite."""
    if isinstance(spec, Int):
        return st.one_of(st.integers(max_value=spec.lo - 1), st.integers(min_value=spec.hi + 1))
    edges = [st.floats(max_value=spec.lo, exclude_max=not spec.lo_open, allow_nan=False),
             st.floats(min_value=spec.hi, exclude_min=not spec.hi_open, allow_nan=False)]
    return st.one_of(*edges, st.just(math.nan))


@pytest.mark.parametrize("words,action", _numeric(), ids=[f"{' '.join(w)} {a.option_strings[0]}"
                                                          for w, a in _numeric()])
@given(data=st.data())
def test_any_value_outside_an_options_range_is_refused_and_any_inside_taken(words, action, data):
    spec = option_spec(words[0], action.dest)
    ap = AP
    ns = argparse.Namespace(command=words[0], data_command=words[1] if len(words) > 1 else None,
                            ship_command=words[1] if len(words) > 1 else None)
    bad = data.draw(_outside(spec))
    setattr(ns, action.dest, [bad] if action.nargs in ("+", "*") else bad)
    with pytest.raises(cli.DiviewerError, match=action.option_strings[0]):
        check_options(ap, ns)
    good = data.draw(st.integers(spec.lo, spec.hi) if isinstance(spec, Int) else
                     st.floats(spec.lo, spec.hi, exclude_min=spec.lo_open, exclude_max=spec.hi_open))
    setattr(ns, action.dest, [good] if action.nargs in ("+", "*") else good)
    if not (isinstance(spec, Int) and spec.power_of_two and good & (good - 1)):
        check_options(ap, ns)
