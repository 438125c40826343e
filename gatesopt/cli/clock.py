"""When this command started, on ``time.perf_counter()``'s clock: the reports' "whole run" and a
``--budget`` count from the process's start (interpreter start-up and imports included, ~0.5 s),
which is what the user waits for."""
from __future__ import annotations

import os
import time


def process_age_s() -> float:
    """Seconds since this process started (Linux: ``/proc/self/stat`` field 22 against
    ``/proc/uptime``), 0 where that cannot be read."""
    try:
        with open("/proc/self/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
        start_ticks = int(fields[19])           # field 22 of the whole line
        with open("/proc/uptime", "rb") as f:
            uptime_s = float(f.read().split()[0])
        age = uptime_s - start_ticks / os.sysconf("SC_CLK_TCK")
        return age if 0.0 <= age < 3600.0 else 0.0
    except (OSError, ValueError, IndexError, AttributeError):
        return 0.0


#: at most this long from the interpreter's start to its first import of gatesopt (measured
#: 0.04-0.06 s on this project's 2-core machine; a slow disk may take some tenths)
INTERPRETER_START_S = 0.5


def started_s() -> float:
    """``time.perf_counter()`` as it read when this process started (now, where unknown), and
    no earlier than ``INTERPRETER_START_S`` before it first imported gatesopt: a process's start
    is its fork, and a shell may run other commands before it execs the interpreter in it (bash
    execs the last command of ``( a && b && gatesopt solve ... )``: README's first command in a
    subshell counted the venv and pip install's 14 s as the run's reading and skipped its
    ordering)."""
    from .. import _jit
    now = time.perf_counter()
    return max(now - process_age_s(), _jit.FIRST_IMPORT_S - INTERPRETER_START_S)
