"""The ``gatesopt`` command line: a thin layer over the library.

One module per command (as vpype_cli does), each with ``NAME``, ``HELP``, ``DESCRIPTION``,
``add_arguments(parser)`` and ``run(args)``; a command body parses options and makes library
calls. What several commands share is in modules of its own, which import no command module:
``files`` (reading G-code, ``-`` for standard input and output, never overwriting a file without
``--force``, writing through a temporary file), ``options`` (the choices read from the library's
registries, the gating options), ``progress`` (a status line from a command's first second, the
compile note the moment compiling starts, the ordering's bar) and ``summary``.
Every failure is one line on stderr, ``gatesopt: error: ...``, and exit code 2: errors the
library raises on purpose (``GatesoptError``), a bad option (argparse's usage text is left out:
``--help`` gives it), a file the system cannot read or write; anything else is a bug, said in one
line too (``GATESOPT_TRACEBACK=1`` shows its traceback).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import traceback

from .. import _jit
from ..errors import GatesoptError
from .progress import command_status
from . import batch, calibrate, clock, compare, order, profile, report, solve, verify

#: the commands, in the order ``gatesopt --help`` lists them
COMMANDS = (profile, solve, compare, order, verify, batch, report, calibrate)


class UsageError(Exception):
    """A bad command line (argparse's message), raised instead of argparse's exit."""


class _Parser(argparse.ArgumentParser):
    """argparse's parser, whose errors are one line (``main`` prints it, exit code 2) instead of
    the usage text and a second line."""

    def error(self, message):
        raise UsageError(message)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command; with ``command``, only that command's options are added (the
    others are listed by name and help): their choices come from the library's registries, and a
    command does not import the registries of the others."""
    parser = _Parser(
        prog="gatesopt",
        description="Energy profiling, motor power gating and curve ordering for 3D-printer G-code.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for mod in COMMANDS:
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.DESCRIPTION)
        p.set_defaults(func=mod.run)
        if command is None or command == mod.NAME:
            mod.add_arguments(p)
    return parser


def error_line(exc: BaseException) -> str:
    """The one line a failure gets (after ``gatesopt: error: ``)."""
    if isinstance(exc, (GatesoptError, UsageError)):
        return str(exc)
    if isinstance(exc, OSError) and exc.strerror:     # a file the system refused: no bug of ours
        name = exc.filename if exc.filename is not None else ""
        return f"{name}: {exc.strerror.lower()}" if name else exc.strerror.lower()
    frame = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
    where = f" at {os.path.basename(frame.filename)}:{frame.lineno}" if frame else ""
    return (f"internal error ({type(exc).__name__}: {exc}{where}); please report it "
            "(GATESOPT_TRACEBACK=1 shows the traceback)")


def _status_words(args) -> str:
    """``gatesopt solve part.gcode``: the command and its first file, for the status line."""
    first = next((v for v in (getattr(args, k, None) for k in ("file", "original", "gcode", "results",
                                                                 "paths", "files")) if v), "")
    if isinstance(first, list):
        first = first[0] + (f" (+{len(first) - 1})" if len(first) > 1 else "")
    return f"gatesopt {args.command}" + (f" {os.path.basename(first)}" if first else "")


def main(argv: list[str] | None = None) -> int:
    # a command run from the shell counts its time from the process's start (``clock``); one
    # called in-process (tests, scripts) from here
    started_s = clock.started_s() if argv is None else time.perf_counter()
    # and its CPU seconds from the same moment (``time.process_time`` counts from the process's
    # start): their ratio is how much of the machine the run gets (``rewrite.budget``)
    cpu_started_s = 0.0 if argv is None else time.process_time()
    argv = sys.argv[1:] if argv is None else list(argv)
    command = argv[0] if argv and argv[0] in {m.NAME for m in COMMANDS} else None
    try:
        parser = build_parser(argv[0] if argv and not argv[0].startswith("-") else "")
        args = parser.parse_args(argv)
    except UsageError as exc:
        where = f"gatesopt {command}" if command else "gatesopt"
        print(f"gatesopt: error: {command + ': ' if command else ''}{exc} (see {where} --help)",
              file=sys.stderr)
        return 2
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return 2
    args.started_s = started_s
    args.cpu_started_s = cpu_started_s
    compiled_before_s = _jit.compile_s()
    noted: list = []
    try:
        with command_status(_status_words(args), _jit.compiling, _jit.on_long_compile) as noted:
            return int(args.func(args) or 0)
    except (GatesoptError, UsageError) as exc:
        print(f"gatesopt: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `gatesopt profile x | head`
        return 0
    except KeyboardInterrupt:
        print("gatesopt: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:        # one line, never a traceback (unless asked for)
        if os.environ.get("GATESOPT_TRACEBACK"):
            raise
        print(f"gatesopt: error: {error_line(exc)}", file=sys.stderr)
        return 2
    finally:
        # a first run's time, explained (stderr: stdout may carry G-code or JSON)
        # said when it started (``command_status``); here only if compiling took long in short bits
        note = None if noted else _jit.compile_note(compiled_before_s)
        if note:
            print(f"gatesopt: note: {note}", file=sys.stderr)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
