"""The ``gatesopt`` command line: a thin layer over the library.

One module per command group (as vpype_cli does); each exposes ``register(subparsers)`` that adds
its commands with ``set_defaults(func=...)``. A command body parses options and makes library calls.
Errors the library raises on purpose (``GatesoptError``) become one line on stderr and exit code 2.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from .. import _jit
from ..errors import GatesoptError

# command modules, in the order ``gatesopt --help`` lists them
COMMAND_MODULES = ("profile", "gating", "ordering", "verify", "batch", "report", "calibrate")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="gatesopt",
        description="Energy profiling, motor power gating and curve ordering for 3D-printer G-code.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            mod = importlib.import_module(f".{name}", __name__)
        except ModuleNotFoundError as exc:  # a command group not written yet
            if exc.name and exc.name.endswith(f"cli.{name}"):
                continue
            raise
        mod.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return 2
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
