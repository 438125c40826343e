"""The ``gatesopt`` command line: a thin layer over the library.

One module per command (as vpype_cli does), each with ``NAME``, ``HELP``, ``DESCRIPTION``,
``add_arguments(parser)`` and ``run(args)``; a command body parses options and makes library
calls. What several commands share is in modules of its own, which import no command module:
``files`` (reading G-code, ``-`` for standard input and output, never overwriting a file without
``--force``, writing through a temporary file), ``options`` (the choices read from the library's
registries, the gating options), ``progress`` and ``summary``.
Errors the library raises on purpose (``GatesoptError``) become one line on stderr and exit code 2.
"""
from __future__ import annotations

import argparse
import sys
import time

from .. import _jit
from ..errors import GatesoptError
from . import batch, calibrate, clock, compare, order, profile, report, solve, verify

#: the commands, in the order ``gatesopt --help`` lists them
COMMANDS = (profile, solve, compare, order, verify, batch, report, calibrate)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command; with ``command``, only that command's options are added (the
    others are listed by name and help): their choices come from the library's registries, and a
    command does not import the registries of the others."""
    parser = argparse.ArgumentParser(
        prog="gatesopt",
        description="Energy profiling, motor power gating and curve ordering for 3D-printer G-code.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in COMMANDS:
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.DESCRIPTION)
        p.set_defaults(func=mod.run)
        if command is None or command == mod.NAME:
            mod.add_arguments(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    # a command run from the shell counts its time from the process's start (``clock``); one
    # called in-process (tests, scripts) from here
    started_s = clock.started_s() if argv is None else time.perf_counter()
    # and its CPU seconds from the same moment (``time.process_time`` counts from the process's
    # start): their ratio is how much of the machine the run gets (``rewrite.budget``)
    cpu_started_s = 0.0 if argv is None else time.process_time()
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv[0] if argv and not argv[0].startswith("-") else "")
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return 2
    args.started_s = started_s
    args.cpu_started_s = cpu_started_s
    compiled_before_s = _jit.compile_s()
    try:
        return int(args.func(args) or 0)
    except GatesoptError as exc:
        print(f"gatesopt: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `gatesopt profile x | head`
        return 0
    except KeyboardInterrupt:
        print("gatesopt: interrupted", file=sys.stderr)
        return 130
    finally:
        # a first run's time, explained (stderr: stdout may carry G-code or JSON)
        note = _jit.compile_note(compiled_before_s)
        if note:
            print(f"gatesopt: note: {note}", file=sys.stderr)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
