"""Every option of every command says what it does (``--help``), and the README's command summary
lists every option of every command and no other (issue 37: the summary omitted --in-place,
--bed, --threads, --profile, verify --firmware, ...; batch options had no help)."""
from __future__ import annotations

import argparse
import re

import pytest

from gatesopt.cli import COMMANDS, build_parser

from conftest import REPO


def command_parser(name: str) -> argparse.ArgumentParser:
    parser = build_parser(name)
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[name]


def options(name: str) -> dict[str, argparse.Action]:
    """The long option strings of command ``name`` (``-o`` as ``--output``), each to its action."""
    out = {}
    for a in command_parser(name)._actions:
        # a hidden alias kept for old scripts (help=SUPPRESS) is not part of the summary
        if a.option_strings and not isinstance(a, argparse._HelpAction) and a.help != argparse.SUPPRESS:
            out[max(a.option_strings, key=len)] = a
    return out


def readme_summary() -> dict[str, str]:
    """The README's command summary (the first code block under "## Command line"): each
    command's text, its continuation lines (indented) included; a command given twice, joined."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    block = text.split("## Command line", 1)[1].split("```", 2)[1]
    out: dict[str, str] = {}
    name = None
    for line in block.splitlines():
        m = re.match(r"gatesopt (\w+)\b(.*)", line)
        if m:
            name = m.group(1)
            out[name] = out.get(name, "") + " " + m.group(2)
        elif line.strip() and name:
            out[name] += " " + line
    return out


@pytest.mark.parametrize("name", [m.NAME for m in COMMANDS])
def test_every_option_has_help(name):
    p = command_parser(name)
    silent = [a.option_strings or [a.dest] for a in p._actions if not (a.help and a.help.strip())]
    assert silent == []
    assert p.description and p.description.strip()


@pytest.mark.parametrize("name", [m.NAME for m in COMMANDS])
def test_the_readme_summary_lists_every_option(name):
    summary = readme_summary()
    assert name in summary, f"README command summary has no 'gatesopt {name}' line"
    text = summary[name].replace(" -o ", " --output ").replace("(-o ", "(--output ")
    listed = set(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", text))
    given = options(name)
    assert sorted(set(given) - listed) == [], "options missing from the README summary"
    assert sorted(listed - set(given)) == [], "README lists options the command has not"
    # where the summary spells out the choices (a|b|c), they are the parser's
    for opt, choices in re.findall(r"(--[a-z-]+) ([a-z0-9]+(?:\|[a-z0-9]+)+)\]", text):
        action = given[opt]
        if action.choices is not None:
            assert sorted(choices.split("|")) == sorted(map(str, action.choices)), opt
