"""`CommandParser` records what is added to it, through argument groups too, and the chosen (sub)subparser is
found from the parsed names alone: what the option checks and the options test walk instead of argparse's
internals."""

from __future__ import annotations

import argparse

import pytest

from diviewer.cli import build_parser
from diviewer.commands import COMMANDS
from diviewer.commands.common import PROVIDERS, add_number, add_provider
from diviewer.commands.parser import CommandParser, arguments, chosen_parser, leaves, option_table, subcommands


def _tree() -> CommandParser:
    ap = CommandParser(prog="t")
    sub = ap.add_subparsers(dest="command", required=True)
    a = sub.add_parser("a")
    a.add_argument("--x", type=int)
    g = a.add_argument_group("group")
    g.add_argument("--y", type=float)
    b = sub.add_parser("b")
    inner = b.add_subparsers(dest="b_command", required=True)
    inner.add_parser("c").add_argument("path")
    return ap


def test_options_are_recorded_with_their_groups_and_subcommands_by_name():
    ap = _tree()
    a = subcommands(ap)["a"]
    assert [x.dest for x in arguments(a)] == ["help", "x", "y"]
    assert isinstance(a, CommandParser) and set(subcommands(ap)) == {"a", "b"}
    assert [w for w, _ in leaves(ap)] == [("a",), ("b", "c")]
    rows = {(r["command"], r["dest"]): r for r in option_table(ap)}
    assert rows[(("a",), "y")]["type"] is float and rows[(("b", "c"), "path")]["option_strings"] == ()


@pytest.mark.parametrize("argv,leaf", [(["a", "--x", "1"], ("a",)), (["b", "c", "p"], ("b", "c"))])
def test_the_chosen_parser_is_the_leaf_that_parsed(argv, leaf):
    ap = _tree()
    expected = dict(leaves(ap))[leaf]
    assert chosen_parser(ap, ap.parse_args(argv)) is expected
    names = dict(zip(("command", "b_command"), leaf))  # the names alone, as the options test builds them
    assert chosen_parser(ap, argparse.Namespace(**names)) is expected
    assert chosen_parser(ap, argparse.Namespace(command="zz")) is ap  # a name no level has: the top


def test_the_command_line_is_one_module_per_command():
    ap = build_parser()
    assert tuple(subcommands(ap)) == COMMANDS
    providers = [a.choices for _, p in leaves(ap) for a in arguments(p) if a.dest == "provider"]
    assert len(providers) >= 4 and all(tuple(c) == PROVIDERS for c in providers)


def test_a_number_without_a_range_is_refused_when_the_parser_is_built():
    p = CommandParser()
    add_provider(p)
    add_number(p, "--spp", default=4)
    with pytest.raises(KeyError, match="OPTIONS"):
        add_number(p, "--not-an-option", default=1)


def test_a_mutually_exclusive_groups_options_are_recorded_and_still_exclusive(capsys):
    p = CommandParser(prog="t")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--a", action="store_true")
    g.add_argument("--b", action="store_true")
    assert [x.dest for x in arguments(p)] == ["help", "a", "b"]
    with pytest.raises(SystemExit):
        p.parse_args(["--a", "--b"])
    assert "not allowed with argument" in capsys.readouterr().err
