"""How long this process spent compiling numba kernels (numba's ``numba:compile`` events).

The kernels are compiled on first use and cached (``cache=True``) beside their modules, so only
the first run after an install or an update pays for it: measured ~37 s on this project's 2-core
machine for a budgeted ``gatesopt order`` (parser ~15 s, ordering kernels ~22 s), against ~0.05 s
to load them from the cache afterwards. A budget cannot shorten that time, so the CLI says where
it went (``compile_note``) rather than leave a first run's overrun unexplained.
"""
from __future__ import annotations

from numba.core import event

#: below this many seconds of compiling, nothing is said (loading cached kernels fires the same
#: events: ~0.05 s per run)
NOTE_MIN_S = 1.0

_clock = event.TimingListener()
event.register("numba:compile", _clock)


def compile_s() -> float:
    """Seconds this process has spent compiling (or loading) numba kernels so far."""
    return float(_clock.duration) if _clock.done else 0.0


def compile_note(since_s: float = 0.0) -> str | None:
    """A line for the user when compiling since ``since_s`` (an earlier ``compile_s()``) took
    long enough to matter, else None."""
    s = compile_s() - since_s
    if s < NOTE_MIN_S:
        return None
    return (f"{s:.1f} s of this run went to compiling numba kernels: the first run after an "
            "install or an update compiles them, later runs load them from the cache")
