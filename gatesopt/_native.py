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

from .solvers import Stopped, in_stop_scope, native_call, request_stop, stop_requested, stop_scope

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


class HighsRun:
    """What ``run_highs`` did: ``ran`` (False: the deadline had passed, nothing run; the object is
    falsy then), and why HiGHS was stopped early, if it was: ``stopped`` (a stop request:
    Ctrl-C) or ``by_rule`` (the caller's ``stop_when`` said its answer was good enough)."""

    __slots__ = ("ran", "stopped", "by_rule")

    def __init__(self, ran: bool):
        self.ran = ran
        self.stopped = Stopped.NO
        self.by_rule = False

    def __bool__(self) -> bool:
        return self.ran


def _time_left(h, deadline: float | None) -> bool:
    """Give HiGHS instance ``h`` the time left to ``deadline`` (a ``time.perf_counter()`` value;
    None: its own time limit); False where none is left."""
    import time
    if deadline is None:
        return True
    left = deadline - time.perf_counter()
    if left <= 0:
        return False
    # HiGHS's time_limit is checked against the run time the instance has accumulated over all
    # its runs (getRunTime), not this run's: a model solved again and again (cuts, node LPs)
    # would otherwise stop at "time limit" long before the deadline
    h.setOptionValue("time_limit", float(h.getRunTime() + left))
    return True


def run_highs(h, deadline: float | None = None, start=None, stop_when=None) -> HighsRun:
    """Run the HiGHS model ``h`` with native stdout on stderr: until ``deadline`` (a
    ``time.perf_counter()`` value; None: the model's own time limit), from the start solution
    ``start`` (column values) if given. Returns a falsy ``HighsRun``, without running, when the
    deadline has passed.

    HiGHS asks its interrupt callbacks (simplex and MIP) whether to stop: it stops on a stop
    request (``solvers.stop_requested``: Ctrl-C inside a ``stop_scope``) and, in a MIP, when
    ``stop_when(data_out)`` (the callback's ``HighsCallbackOutput``: ``mip_primal_bound``,
    ``mip_dual_bound``, ``mip_solution``...) is true: the caller's stopping rule, e.g. the gap it
    will report (``gating.milp``). The callbacks run in this thread between HiGHS's own steps,
    which is also where a pending Ctrl-C reaches Python (``stop_scope``'s handler only records
    it; a second one is raised after the call, ``native_call``)."""
    run = HighsRun(False)
    if not _time_left(h, deadline):
        return run
    if start is not None:
        import highspy
        sol = highspy.HighsSolution()
        sol.col_value = list(start)
        sol.value_valid = True
        h.setSolution(sol)
    run.ran = True

    def interrupt(e):
        try:
            if stop_requested():
                run.stopped = Stopped.INTERRUPTED
                e.interrupt()
        except KeyboardInterrupt:       # no stop_scope here: never raise through HiGHS
            request_stop()
            run.stopped = Stopped.INTERRUPTED
            e.interrupt()

    def mip_interrupt(e):
        interrupt(e)
        if stop_when is not None and not run.stopped:
            try:
                if stop_when(e.data_out):
                    run.by_rule = True
                    e.interrupt()
            except KeyboardInterrupt:
                request_stop()
                run.stopped = Stopped.INTERRUPTED
                e.interrupt()
    h.cbSimplexInterrupt.subscribe(interrupt)
    h.cbMipInterrupt.subscribe(mip_interrupt)
    # outside a caller's stop_scope a Ctrl-C is Python's KeyboardInterrupt, as anywhere: raised
    # once HiGHS has stopped (its own scope only keeps it from raising inside HiGHS)
    raise_after = not in_stop_scope()
    try:
        with stop_scope(), native_call(), native_stdout_to_stderr():   # HiGHS may printf
            h.run()
    finally:
        h.cbSimplexInterrupt.unsubscribe(interrupt)
        h.cbMipInterrupt.unsubscribe(mip_interrupt)
    if raise_after and run.stopped == Stopped.INTERRUPTED:
        raise KeyboardInterrupt
    return run


def run_lp(h, deadline: float | None = None) -> HighsRun:
    """``run_highs`` for the small LPs solved one after another (the curve ordering's cutting-plane
    rounds and branch-and-cut nodes: ~0.2-1 ms each): a stop request (Ctrl-C) is looked at
    before each run, not from HiGHS's interrupt callbacks, whose Python calls (~28 a run) and
    subscriptions took ~10 % of the ordering's exact step (docs/BENCHMARKS.md, "LP runs without
    callbacks"); a run this short ends a millisecond or two after the request. Native stdout
    still goes to stderr; a second Ctrl-C waits for HiGHS to return (``native_call``). Falsy,
    without running, where the deadline has passed or a stop was requested (``stopped`` set)."""
    run = HighsRun(False)
    if stop_requested():
        run.stopped = Stopped.INTERRUPTED
        return run
    if not _time_left(h, deadline):
        return run
    run.ran = True
    with native_call(), native_stdout_to_stderr():
        h.run()
    return run
