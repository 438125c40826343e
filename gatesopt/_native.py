"""Keep native solver output off standard output.

HiGHS 1.12 writes a debug line from C (``printf``) in some MIP solves, whatever ``output_flag``
says. Standard output carries the G-code in ``gatesopt solve - -o -``, so native output must never
reach it: while a native solver runs, file descriptor 1 points at standard error.
"""
from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import threading

_lock = threading.Lock()
try:
    _libc = ctypes.CDLL(None)
except OSError:  # pragma: no cover - no C library to flush
    _libc = None


def _flush_c():
    if _libc is not None:
        try:
            _libc.fflush(None)
        except Exception:  # pragma: no cover
            pass


@contextlib.contextmanager
def native_stdout_to_stderr():
    """Run a block with C-level stdout redirected to stderr (Python's sys.stdout is untouched)."""
    try:
        out_fd = sys.__stdout__.fileno() if sys.__stdout__ else 1
        err_fd = sys.__stderr__.fileno() if sys.__stderr__ else 2
    except (AttributeError, OSError, ValueError):   # no real file descriptors (embedded, tests)
        yield
        return
    with _lock:
        try:
            sys.stdout.flush()
        except Exception:
            pass
        _flush_c()
        saved = os.dup(out_fd)
        try:
            os.dup2(err_fd, out_fd)
            yield
        finally:
            _flush_c()
            os.dup2(saved, out_fd)
            os.close(saved)


def run_highs(h, deadline: float | None = None, start=None) -> bool:
    """Run the HiGHS model ``h`` with native stdout on stderr: until ``deadline`` (a
    ``time.perf_counter()`` value; None: the model's own time limit), from the start solution
    ``start`` (column values) if given. Returns False, without running, when the deadline has
    passed."""
    import time
    if deadline is not None:
        left = deadline - time.perf_counter()
        if left <= 0:
            return False
        # HiGHS's time_limit is checked against the run time the instance has accumulated over
        # all its runs (getRunTime), not this run's: a model solved again and again (cuts, node
        # LPs) would otherwise stop at "time limit" long before the deadline
        h.setOptionValue("time_limit", float(h.getRunTime() + left))
    if start is not None:
        import highspy
        sol = highspy.HighsSolution()
        sol.col_value = list(start)
        sol.value_valid = True
        h.setSolution(sol)
    with native_stdout_to_stderr():     # HiGHS may printf; stdout can carry G-code
        h.run()
    return True
