"""How long this process spent compiling numba kernels (numba's ``numba:compile`` events), a
note the moment a long compile starts, and a clock kernels can read.

The kernels are compiled on first use and cached (``cache=True``, one directory per version of
the sources: ``use_versioned_cache``), so only
the first run after an install or an update pays for it: measured ~37 s on this project's 2-core
machine for a budgeted ``gatesopt order`` (parser ~15 s, ordering kernels ~22 s), 115 s for a
default ``gatesopt solve`` at a load of ~4 (scan 23 s, the ordering's matching 33 s, ILS 16 s,
...), against nothing afterwards: numba fires ``numba:compile`` only on a cache miss
(dispatcher.py ``compile``). A budget cannot shorten that time, so budgets do not count it
(``compile_s_since``: a first run solves as a later one does, and takes that much longer), and
the CLI says so as it starts (``on_long_compile``).

A kernel that reads the clock calls ``now_ns`` (``clock_gettime`` called from the compiled code),
never ``numba.objmode``: a function with an objmode block is cached, but its object-mode part is
compiled again in every process (0.1-0.15 s each, measured; 1-6 s on a loaded machine, which the
first-hour survey took for kernels recompiling on later runs).
"""
from __future__ import annotations

import bisect
import sys
import threading
import time

#: when this process first imported gatesopt (its package imports this module first, before
#: numpy and numba): ``cli.clock``, the process itself may have started long before, where a
#: shell ran other commands in it before it exec'd the interpreter
FIRST_IMPORT_S = time.perf_counter()

import hashlib
import os
from pathlib import Path

import numba
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils, event
from numba.extending import intrinsic


def source_digest(package_dir: Path) -> str:
    """A digest of every module of the package (path and bytes)."""
    h = hashlib.sha1()
    for path in sorted(package_dir.rglob("*.py")):
        h.update(str(path.relative_to(package_dir)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def use_versioned_cache(package_dir: Path) -> None:
    """Cache the kernels under ``<package>/__pycache__/numba-<digest of the sources>``.

    numba keys a cached kernel on its own file's time stamp and size only (caching.py
    ``_SourceFileBackedLocatorMixin.get_source_stamp``): a kernel that inlines a kernel or reads a
    constant of another module keeps its old machine code when only that other module changes
    (e.g. ``DECIMALS_SPLIT`` read by the emit kernels, an ``inline="always"`` helper). A
    directory per version of the sources makes every update compile afresh (the first run's
    note says so). Where the directory cannot be written numba falls back
    to its own locations (``from_function`` returns None on OSError); a NUMBA_CACHE_DIR the user
    set is left alone."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    numba.config.CACHE_DIR = str(package_dir / "__pycache__" / f"numba-{source_digest(package_dir)}")


use_versioned_cache(Path(__file__).resolve().parent)

#: below this many seconds of compiling, nothing is said
NOTE_MIN_S = 1.0
#: a compile still running after this many seconds gets the note at once (``on_long_compile``)
NOTE_AFTER_S = 0.5


class _Spans(event.Listener):
    """The outermost compile spans, in time order (numba compiles under one lock: they do not
    overlap), with their running total."""

    def __init__(self):
        self._depth = 0
        self._lock = threading.Lock()
        self.starts: list[float] = []
        self.ends: list[float] = []
        self.cum: list[float] = [0.0]       # cum[i]: total of the first i spans
        self.callbacks: list = []           # ``on_long_compile``: called once, then dropped
        self._timer = None

    def on_start(self, ev):
        if self._depth == 0:
            self._t = time.perf_counter()
            if self.callbacks:
                self._timer = threading.Timer(NOTE_AFTER_S, self._fire, args=(len(self.ends),))
                self._timer.daemon = True
                self._timer.start()
        self._depth += 1

    def on_end(self, ev):
        self._depth -= 1
        if self._depth == 0:
            t = time.perf_counter()
            with self._lock:
                self.starts.append(self._t)
                self.ends.append(t)
                self.cum.append(self.cum[-1] + (t - self._t))
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
                if t - self._t >= NOTE_AFTER_S:     # ended before the timer could fire
                    self._fire(len(self.ends) - 1)

    def _fire(self, span: int) -> None:
        """The callbacks, once, if span number ``span`` is still open or was long."""
        with self._lock:
            if len(self.ends) > span + 1:
                return
            callbacks, self.callbacks = self.callbacks, []
        for f in callbacks:
            f()

    @property
    def compiling(self) -> bool:
        return self._depth > 0


_spans = _Spans()
event.register("numba:compile", _spans)


def compile_s() -> float:
    """Seconds this process has spent compiling (or loading) numba kernels so far."""
    return _spans.cum[-1]


def compile_s_since(t: float) -> float:
    """Seconds spent compiling after ``t`` (a ``time.perf_counter()`` reading)."""
    with _spans._lock:
        i = bisect.bisect_right(_spans.ends, t)     # spans from i on end after t
        if i == len(_spans.ends):
            return 0.0
        s = _spans.cum[-1] - _spans.cum[i + 1]       # those wholly or partly after t: all but i
        return s + (_spans.ends[i] - max(_spans.starts[i], t))


def on_long_compile(callback) -> None:
    """Call ``callback()`` once (from a timer thread, or the compiling thread) when a compile span
    of this process has lasted ``NOTE_AFTER_S``: a first run's kernels are being compiled, and the
    user should hear it before waiting for it. Returns a function that withdraws ``callback``
    (a command that ended before any long compile)."""
    _spans.callbacks.append(callback)

    def withdraw() -> None:
        with _spans._lock:
            if callback in _spans.callbacks:
                _spans.callbacks.remove(callback)
    return withdraw


def compiling() -> bool:
    """A kernel is being compiled right now (in this process)."""
    return _spans.compiling


def compile_note(since_s: float = 0.0) -> str | None:
    """A line for the user when compiling since ``since_s`` (an earlier ``compile_s()``) took
    long enough to matter, else None."""
    s = compile_s() - since_s
    if s < NOTE_MIN_S:
        return None
    return (f"{s:.1f} s of this run went to compiling numba kernels (not counted against a "
            "budget): the first run after an install or an update compiles them, later runs "
            "load them from the cache")


# ------------------------------------------------------------------------------------------------
# a clock for kernels: CLOCK_MONOTONIC, the clock of time.perf_counter_ns() on Linux (CPython's
# pytime.c); CLOCK_UPTIME_RAW (mach_absolute_time) on macOS
CLOCK_ID = 8 if sys.platform == "darwin" else 1


@intrinsic
def _clock_gettime_ns(typingctx):
    """``clock_gettime(CLOCK_ID)`` in ns, called from compiled code by its C name (resolved when
    the cached kernel is loaded: no address is baked in, so a kernel calling it is cached whole).
    The struct is ``timespec`` of a 64-bit C library (two 64-bit integers)."""
    def codegen(context, builder, signature, args):
        i32, i64 = ir.IntType(32), ir.IntType(64)
        ts_t = ir.LiteralStructType([i64, i64])
        fnty = ir.FunctionType(i32, [i32, ts_t.as_pointer()])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "clock_gettime")
        ts = cgutils.alloca_once(builder, ts_t)
        builder.call(fn, [ir.Constant(i32, CLOCK_ID), ts])
        sec = builder.load(cgutils.gep_inbounds(builder, ts, 0, 0))
        nsec = builder.load(cgutils.gep_inbounds(builder, ts, 0, 1))
        return builder.add(builder.mul(sec, ir.Constant(i64, 1_000_000_000)), nsec)
    return types.int64(), codegen


@njit(cache=True)
def now_ns():
    """``time.perf_counter_ns()``, for compiled code (no objmode: see the module's docstring)."""
    return _clock_gettime_ns()
