"""The parser every command line level is made of: it records the options added to it (``arguments``) and its
subcommands (``subcommands``), so the option checks (`diviewer.options`) and the tests walk the command line through
these two attributes and the functions below alone, never through argparse's internals."""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from typing import Any


class CommandParser(argparse.ArgumentParser):
    """An ArgumentParser that records the options added to it (also through its argument groups) and its
    subcommands."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.arguments: list[argparse.Action] = []  # before argparse adds --help
        self.subcommands: argparse.Action | None = None
        self.built = False  # argparse's own groups (positionals, options) are not wrapped
        super().__init__(*args, **kwargs)
        self.built = True

    def add_argument(self, *args: Any, **kwargs: Any) -> argparse.Action:
        action = super().add_argument(*args, **kwargs)
        self.arguments.append(action)
        return action

    def add_argument_group(self, *args: Any, **kwargs: Any) -> Any:
        group = super().add_argument_group(*args, **kwargs)
        return _RecordedGroup(group, self) if self.built else group

    def add_mutually_exclusive_group(self, **kwargs: Any) -> Any:
        return _RecordedGroup(super().add_mutually_exclusive_group(**kwargs), self)

    def add_subparsers(self, **kwargs: Any) -> argparse.Action:
        kwargs.setdefault("parser_class", CommandParser)
        self.subcommands = super().add_subparsers(**kwargs)
        return self.subcommands


class _RecordedGroup:
    """An argument group (or a mutually exclusive one) whose options are recorded in its parser's ``arguments``
    too."""

    def __init__(self, group: Any, parser: CommandParser) -> None:
        self.group, self.parser = group, parser

    def add_argument(self, *args: Any, **kwargs: Any) -> argparse.Action:
        action = self.group.add_argument(*args, **kwargs)
        self.parser.arguments.append(action)
        return action


def arguments(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The options (``--help`` included) and positionals added to ``parser``, a `CommandParser` (none for another
    parser)."""
    return list(getattr(parser, "arguments", ()))


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """``parser``'s subcommands by name (none for a leaf)."""
    sub = getattr(parser, "subcommands", None)
    return dict(sub.choices) if sub is not None else {}


def chosen_parser(ap: argparse.ArgumentParser, args: argparse.Namespace) -> argparse.ArgumentParser:
    """The (sub)subparser that parsed ``args``: each level's subcommand is the value of its own dest."""
    parser = ap
    while (sub := getattr(parser, "subcommands", None)) is not None and getattr(args, sub.dest, None) in sub.choices:
        parser = sub.choices[getattr(args, sub.dest)]
    return parser


def leaves(ap: argparse.ArgumentParser, words: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...],
                                                                                         argparse.ArgumentParser]]:
    """(command words, parser) for every leaf subcommand under ``ap`` (``("data", "check")``)."""
    children = subcommands(ap)
    if not children:
        yield words, ap
        return
    for name, sub in children.items():
        yield from leaves(sub, (*words, name))


def option_table(ap: argparse.ArgumentParser) -> list[dict[str, Any]]:
    """Each leaf subcommand's options: its words, option strings, dest, type, nargs, choices and whether required."""
    return [{"command": words, "option_strings": tuple(a.option_strings), "dest": a.dest, "type": a.type,
             "nargs": a.nargs, "choices": a.choices, "required": a.required}
            for words, parser in leaves(ap) for a in arguments(parser)]
