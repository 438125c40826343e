"""How long this process spent compiling numba kernels (numba's ``numba:compile`` events).

The kernels are compiled on first use and cached (``cache=True``) beside their modules, so only
the first run after an install or an update pays for it: measured ~37 s on this project's 2-core
machine for a budgeted ``gatesopt order`` (parser ~15 s, ordering kernels ~22 s), against ~0.05 s
to load them from the cache afterwards. A budget cannot shorten that time, so budgets do not
count it (``compile_s_since``: a first run solves as a later one does, and takes that much
longer), and the CLI says where it went (``compile_note``).
"""
from __future__ import annotations

import bisect
import threading
import time

from numba.core import event

#: below this many seconds of compiling, nothing is said (loading cached kernels fires the same
#: events: ~0.05 s per run)
NOTE_MIN_S = 1.0


class _Spans(event.Listener):
    """The outermost compile spans, in time order (numba compiles under one lock: they do not
    overlap), with their running total."""

    def __init__(self):
        self._depth = 0
        self._lock = threading.Lock()
        self.starts: list[float] = []
        self.ends: list[float] = []
        self.cum: list[float] = [0.0]       # cum[i]: total of the first i spans

    def on_start(self, ev):
        if self._depth == 0:
            self._t = time.perf_counter()
        self._depth += 1

    def on_end(self, ev):
        self._depth -= 1
        if self._depth == 0:
            t = time.perf_counter()
            with self._lock:
                self.starts.append(self._t)
                self.ends.append(t)
                self.cum.append(self.cum[-1] + (t - self._t))


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


def compile_note(since_s: float = 0.0) -> str | None:
    """A line for the user when compiling since ``since_s`` (an earlier ``compile_s()``) took
    long enough to matter, else None."""
    s = compile_s() - since_s
    if s < NOTE_MIN_S:
        return None
    return (f"{s:.1f} s of this run went to compiling numba kernels (not counted against a "
            "budget): the first run after an install or an update compiles them, later runs "
            "load them from the cache")
