"""The command line's files: what a command reads, and how it writes without harming the user's.

Every command reads its G-code and writes its outputs through here, so that a rule about files
is made in one place: ``-`` for standard input and output, an existing file replaced only with
``--force``, never the input, outputs written to a temporary file beside the target and renamed
(a failed run leaves nothing half-written), the permissions a new file gets.
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

STDIO = "-"     # the file name that means standard input (to read) or standard output (to write)


def read_program(path: str):
    """The parsed G-code file ``path`` (``.gz`` too), or standard input for ``-``."""
    if path == STDIO:
        return parse(sys.stdin.buffer.read(), source="<stdin>")
    return parse(path)


def refuse_existing(path: str, force: bool, advice: str = "pass --force to overwrite it") -> None:
    """Before any work: an existing ``path`` is replaced only with ``force``."""
    if os.path.exists(path) and not force:
        raise GatesoptError(f"{path}: exists; {advice}")


def check_output(inp: str, out: str, force: bool) -> None:
    """Before any work (and again before writing): ``out`` is not the input ``inp``, its folder
    exists, and an existing file is replaced only with ``force``."""
    if os.path.abspath(inp) == os.path.abspath(out) or (
            os.path.exists(out) and os.path.exists(inp) and os.path.samefile(inp, out)):
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
    for inp in inputs:
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


def write_atomic(path: str, text: str, like: str | None = None) -> None:
    """Write ``text`` to a temporary file beside ``path`` and rename it into place.

    ``like``: an existing file whose permissions (and gzip compression) the new file keeps, for
    replacing a file in place.
    """
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".gatesopt-", suffix=".tmp", dir=folder)
    try:
        data = text.encode("utf-8", "surrogateescape")
        if like is not None:
            with open(like, "rb") as f:
                if f.read(2) == b"\x1f\x8b":
                    data = gzip.compress(data)
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
