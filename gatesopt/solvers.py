"""One solver vocabulary for both problem families (power gating, curve ordering).

As cvxpy does it: every formulation answers with one of four statuses, a bound where it has one,
and one definition of the optimality gap; formulations are registered by name with the Python
packages they need and what they can do, and are imported on first use (``is_installed`` looks
for the backend with ``importlib.util.find_spec`` without importing it).

Status
    ``optimal``    proven optimal: the objective meets the bound (within the formulation's
                   tolerance: ``mip_rel_gap`` for HiGHS, an absolute 1e-6 mm for travel);
    ``feasible``   a valid answer without a proof, with its gap to the bound;
    ``fallback``   a valid answer from a simpler method after the named one could not give one
                   (a time limit hit before the first solution, an interrupted solve);
    ``infeasible`` no valid answer exists under the constraints (budgets that cannot be met).

Gap
    ``relative_gap(objective, bound) = (objective - bound) / |objective|``, a unitless fraction
    (0.02 is 2 %), >= 0; NaN where the formulation has no finite bound. Objective and bound are in
    the problem's own unit (J for gating, mm or s of travel for ordering). "Gap" means only this;
    a motor's idle time between two steps is an *idle interval*. It is also the stopping rule: an
    exact formulation stops when this gap, of the answer it would report, is at most its
    tolerance (``mip_rel_gap``), not on its backend's own measure of a model objective.

Stopped
    Why a search ended before its proof (``Stopped``): its time limit, or a request to stop
    (Ctrl-C). Inside ``stop_scope()`` the first Ctrl-C only *asks* every solver to stop
    (``stop_requested``): HiGHS sees it in its interrupt callback, CP-SAT through ``run_native``,
    loops of our own at their next check; each answers with the best it has, and the run goes on
    with that (emit, verify). A second Ctrl-C raises ``KeyboardInterrupt`` as usual (after a
    native call returns, never inside one).
"""
from __future__ import annotations

import contextlib
import enum
import importlib
import importlib.util
import math
import signal
import threading
import time
from dataclasses import dataclass

from .errors import GatesoptError


class Status(str, enum.Enum):
    """What a formulation's answer is (module docstring)."""

    OPTIMAL = "optimal"
    FEASIBLE = "feasible"
    FALLBACK = "fallback"
    INFEASIBLE = "infeasible"

    def __str__(self) -> str:           # "optimal", as the reports have always written it
        return self.value

    def __format__(self, spec: str) -> str:
        return format(self.value, spec)


STATUSES = tuple(s.value for s in Status)


def relative_gap(objective: float, bound: float, *, abs_tol: float = 0.0) -> float:
    """(objective - bound) / |objective|, >= 0; 0 where they differ by at most ``abs_tol`` (float
    noise in the objective's unit); NaN where ``bound`` is not finite (no bound)."""
    if not math.isfinite(bound):
        return math.nan
    if objective - bound <= abs_tol:
        return 0.0
    return max(0.0, (objective - bound) / max(abs(objective), 1e-12))


@dataclass(frozen=True)
class Formulation:
    """A registered formulation: where its ``solve`` lives, what it needs, what it can do."""

    name: str
    module: str                         # dotted module path holding ``solve``
    backends: tuple = ()                # Python packages it needs beyond the core dependencies
    capabilities: frozenset = frozenset()   # e.g. {"exact", "budgets", "warm_start"}
    description: str = ""

    def is_installed(self) -> bool:
        return all(importlib.util.find_spec(b) is not None for b in self.backends)

    def load(self):
        """The module, imported on first use; a clear error where a backend is missing."""
        if not self.is_installed():
            missing = [b for b in self.backends if importlib.util.find_spec(b) is None]
            raise GatesoptError(f"formulation {self.name!r} needs the Python package "
                                f"{missing[0]!r}, which is not installed")
        return importlib.import_module(self.module)


def lookup(registry: dict, name: str, family: str) -> Formulation:
    """``registry[name]``, or a ``GatesoptError`` naming the choices."""
    try:
        return registry[name]
    except KeyError:
        raise GatesoptError(f"unknown {family} formulation {name!r}: choose one of "
                            f"{', '.join(registry)}") from None


class Stopped(str, enum.Enum):
    """Why a search ended without reaching its gap (module docstring); "" where it did."""

    NO = ""
    TIME_LIMIT = "time limit"
    INTERRUPTED = "interrupted (Ctrl-C)"

    def __str__(self) -> str:
        return self.value

    def __format__(self, spec: str) -> str:
        return format(self.value, spec)


# ------------------------------------------------------------------------------------------------
# Stopping on request (Ctrl-C)
class Interrupted(KeyboardInterrupt):
    """Raised by a loop of our own that was asked to stop (``stop_requested``) and has no whole
    answer to give (the curve ordering between two groups); callers that have one catch it."""


class _StopState:
    """The process's stop request and the SIGINT handler of the outermost ``stop_scope``."""

    def __init__(self):
        self.requested = threading.Event()
        self.abort = False          # a second Ctrl-C came while native code ran: raise after it
        self.depth = 0              # nested stop_scope()s
        self.native = 0             # native calls running in the main thread (``native_call``)
        self.saved = None           # the handler the outermost scope replaced
        self.lock = threading.Lock()


_state = _StopState()


def stop_requested() -> bool:
    """True once a stop was asked for in the current ``stop_scope`` (Ctrl-C, ``request_stop``)."""
    return _state.requested.is_set()


def in_stop_scope() -> bool:
    """True inside a ``stop_scope`` (where the first Ctrl-C asks solvers to stop instead of raising)."""
    return _state.depth > 0


def request_stop() -> None:
    """Ask every solver of the current ``stop_scope`` to stop and answer with what it has."""
    _state.requested.set()


def _on_sigint(signum, frame):
    if not _state.requested.is_set():
        _state.requested.set()          # first Ctrl-C: solvers stop, the run goes on
        return
    if _state.native:
        _state.abort = True             # never raise through native frames: after the call
        return
    raise KeyboardInterrupt


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def stop_scope():
    """A run whose solvers stop on the first Ctrl-C (module docstring, "Stopped"). Nested scopes
    share the outermost one's request; the outermost clears it on entry and on exit. The handler
    is installed only in the main thread and only over Python's default one."""
    with _state.lock:
        _state.depth += 1
        outer = _state.depth == 1
        if outer:
            _state.requested.clear()
            _state.abort = False
            if _in_main_thread() and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
                _state.saved = signal.signal(signal.SIGINT, _on_sigint)
    try:
        yield
    finally:
        with _state.lock:
            _state.depth -= 1
            if outer:
                if _state.saved is not None:
                    signal.signal(signal.SIGINT, _state.saved)
                    _state.saved = None
                _state.requested.clear()
                _state.abort = False


@contextlib.contextmanager
def native_call():
    """Around a native solver call in this thread: a second Ctrl-C waits until it returns."""
    main = _in_main_thread()
    if main:
        _state.native += 1
    try:
        yield
    finally:
        if main:
            _state.native -= 1
            if _state.abort and not _state.native:
                _state.abort = False
                raise KeyboardInterrupt


#: how often ``run_native`` looks at the stop request and the deadline while a solver runs
POLL_S = 0.05


def run_native(fn, stop, deadline_s=None):
    """``fn()`` (a native solver's blocking call that releases the GIL, CP-SAT's ``solve``) in a
    worker thread, the calling thread watching: when a stop is requested (Ctrl-C) or the
    ``deadline_s`` (a ``time.perf_counter()`` reading, or a callable giving the current one: a
    stopping rule's) passes, ``stop()`` is called once (``CpSolver.stop_search``) and the call is
    waited for. Returns (fn's result, ``Stopped``: INTERRUPTED for a stop request, TIME_LIMIT for
    the deadline, "" if ``stop()`` was not called)."""
    box = {}

    def target():
        try:
            box["value"] = fn()
        except BaseException as exc:    # re-raised in the calling thread
            box["error"] = exc
    t = threading.Thread(target=target, daemon=True, name="gatesopt-native")
    why = Stopped.NO
    with native_call():
        t.start()
        try:
            while t.is_alive():
                t.join(POLL_S)
                if why == Stopped.NO and t.is_alive():
                    at = deadline_s() if callable(deadline_s) else deadline_s
                    if stop_requested():
                        why = Stopped.INTERRUPTED
                    elif at is not None and time.perf_counter() >= at:
                        why = Stopped.TIME_LIMIT
                    if why != Stopped.NO:
                        stop()
        except BaseException:
            # Ctrl-C outside a stop_scope (a KeyboardInterrupt here): the search must not run on
            # in its thread to its time limit
            stop()
            t.join()
            raise
    if "error" in box:
        raise box["error"]
    return box.get("value"), why
