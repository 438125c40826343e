"""The command line's files: what a command reads, and how it writes without harming the user's.

Every command reads its G-code and writes its outputs through here, so that a rule about files
is made in one place: an argument names a file (a name that is no file is "no such file", never
G-code text), ``-`` is standard input or output, an existing file is replaced only with
``--force``, never an input, outputs are written to a temporary file beside the target and
renamed (a failed run leaves nothing half-written) with the permissions a new file gets, and a
name ending in ``.gz`` is written gzipped.
"""
from __future__ import annotations

import gzip
import json
import os
import shutil
import sys
import tempfile

from ..errors import GatesoptError
from ..parse import parse

GZIP_MAGIC = b"\x1f\x8b"
STDIO = "-"     # the file name that means standard input (to read) or standard output (to write)


STDIN_NAME = "<stdin>"


def check_input(path: str, what: str = "file") -> None:
    """``path`` is an existing file one can read (``-``: standard input), else one line saying
    why not: a name that is no file is never taken for G-code text (``gatesopt profile benchy``)."""
    if path == STDIO:
        return
    if not path:
        raise GatesoptError(f"an empty file name: give a {what}")
    if not os.path.exists(path):
        raise GatesoptError(f"{path}: no such {what}")
    if os.path.isdir(path):
        raise GatesoptError(f"{path}: is a directory, not a {what}")
    if not os.access(path, os.R_OK):
        raise GatesoptError(f"{path}: cannot read it (permission denied)")


def check_one_stdin(paths, flags: str = "") -> None:
    """At most one of ``paths`` is ``-``: standard input can be read once."""
    if sum(1 for p in paths if p == STDIO) > 1:
        raise GatesoptError("standard input (-) can be read only once" + (f": {flags}" if flags else ""))


def read_bytes(path: str) -> bytes:
    """The bytes of ``path`` (``check_input``), or of standard input for ``-``."""
    check_input(path)
    if path == STDIO:
        return sys.stdin.buffer.read()
    with open(path, "rb") as f:
        return f.read()


def read_program(path: str, warn: bool = True):
    """The parsed G-code file ``path`` (``.gz`` too), or standard input for ``-``; its parse
    warnings (``Program.warnings``: each one line naming file and line) on stderr, unless not
    ``warn``."""
    check_input(path)
    if path == STDIO:
        program = parse(sys.stdin.buffer.read(), source=STDIN_NAME)
    else:
        program = parse(path)
    if warn:
        print_warnings(program.warnings)
    return program


def print_warnings(warnings) -> None:
    """Each warning as one line on stderr (stdout may carry G-code or JSON)."""
    for w in warnings:
        print(f"gatesopt: warning: {w}", file=sys.stderr)


def refuse_existing(path: str, force: bool, advice: str = "pass --force to overwrite it") -> None:
    """Before any work: ``path`` is no folder, and an existing file is replaced only with
    ``force``."""
    if not path:
        raise GatesoptError("an empty file name: give a file name")
    if os.path.isdir(path):
        raise GatesoptError(f"{path}: is a directory; give a file name")
    if os.path.lexists(path) and not force:
        raise GatesoptError(f"{path}: exists; {advice}")


def check_output(inp: str, out: str, force: bool) -> None:
    """Before any work (and again before writing): ``out`` is not the input ``inp`` (``-``:
    standard input, never a file), its folder exists, and an existing file is replaced only
    with ``force``."""
    if inp != STDIO and (os.path.abspath(inp) == os.path.abspath(out) or (
            os.path.exists(out) and os.path.exists(inp) and os.path.samefile(inp, out))):
        raise GatesoptError(f"{out}: the output must not be the input file")
    refuse_existing(out, force)
    folder = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(folder):
        raise GatesoptError(f"{out}: folder {folder} does not exist")


def check_new_file(path: str, inputs, force: bool, png: bool = False) -> None:
    """Before any work: ``path`` (a report or plot the command will write) is none of ``inputs``,
    its folder exists, and an existing file is overwritten only with ``force``; ``png``: the
    name ends in .png (``gatesopt.plot.check_png_path``)."""
    if png:
        from ..plot import check_png_path
        check_png_path(path)
    for inp in list(inputs) or [STDIO]:
        check_output(inp, path, force)


def check_distinct(named: dict) -> None:
    """Before any work: the files one command writes (``{"--json": path, ...}``; None and "-"
    skipped) are different files; else the last write would silently replace the first."""
    seen = {}
    for flag, path in named.items():
        if not path or path == STDIO:
            continue
        key = os.path.abspath(path)
        if key in seen:
            raise GatesoptError(f"{path}: {seen[key]} and {flag} must name different files")
        seen[key] = flag


def wants_gzip(path: str, like: str | None = None) -> bool:
    """A file written to ``path`` is gzipped: its name ends in ``.gz``, or (replacing ``like`` in
    place) ``like`` is gzipped."""
    if like is not None:
        with open(like, "rb") as f:
            return f.read(2) == GZIP_MAGIC
    return path.lower().endswith(".gz")


def write_atomic(path: str, text: str, like: str | None = None) -> None:
    """Write ``text`` to a temporary file beside ``path`` and rename it into place; gzipped when
    ``wants_gzip`` (with no time stamp in the gzip header: the same text gives the same bytes).

    ``like``: an existing file whose permissions (and gzip compression) the new file keeps, for
    replacing a file in place.
    """
    if os.path.isdir(path):     # os.replace would fail after the work, with a traceback
        raise GatesoptError(f"{path}: is a directory; give a file name")
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".gatesopt-", suffix=".tmp", dir=folder)
    try:
        data = text.encode("utf-8", "surrogateescape")
        if wants_gzip(path, like):
            data = gzip.compress(data, mtime=0)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        if like is not None:
            shutil.copymode(like, tmp)
        else:       # mkstemp makes a private 0600 file; a new output gets the usual permissions
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_stdout(text: str) -> None:
    """G-code text to standard output, its bytes as read (``-o -``)."""
    sys.stdout.buffer.write(text.encode("utf-8", "surrogateescape"))
    sys.stdout.flush()


def jsonable(v):
    """A report value JSON cannot hold as it is (numpy numbers, enums): as a float, else as text."""
    try:
        return float(v)
    except (TypeError, ValueError):
        return str(v)


def write_json(path: str, obj, default=jsonable) -> None:
    """``obj`` as indented JSON into ``path`` (``write_atomic``)."""
    write_atomic(path, json.dumps(obj, indent=2, default=default) + "\n")
