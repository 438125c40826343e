"""A whole run in a wall-clock budget (``gatesopt solve``'s default 10 s): what the curve
ordering may spend is what the rest of the run is estimated to leave.

A run is read -> order (build, solve, emit with the time guard) -> gate (build, solve, rotate:
render and re-parse the rotated text, build and solve again, emit) -> parse the output -> verify ->
report (planner times, travel). Everything but the ordering's solve takes time roughly in
proportion to the file's lines, at rates measured on the corpus (docs/RESULTS.md, "Default
solve: wall time"); the ordering's solve is the one stage that can use what is left, so the
ordering gets ``budget - spent - estimate of the gating and checking stages`` and spends it as
``gatesopt order --budget`` does (``rewrite.order.solve_budget_s``: its own build and emit out of
it first). An exact gating formulation's own time limit (``--time-limit``) is not estimated:
it is the user's to give.

The rates are a quiet machine's. On a machine other work shares (a loaded 2-core machine gave
this process a third of a core), every stage takes longer by about the share it does not get;
the run measures that share on itself, before the ordering: ``slowdown`` = wall seconds / CPU
seconds of the process so far (reading the file is single-threaded CPU work; start-up I/O makes
it 1.0-1.3 on a quiet machine), and the estimate of the stages after the ordering, the
ordering's own emit included, grows by that factor.
"""
from __future__ import annotations

import importlib.util
import os
import sys
import time

from .. import _jit
from ..program import Program
from .order import FINISH_FIXED_S, FINISH_S_PER_LINE, READ_S_PER_LINE

#: seconds per input line of the stages after the ordering, without a rotation: the gating
#: problem's build and dp solve, the emit, parsing the output, the verifier and the report's
#: planner times and travel. Measured (docs/BENCHMARKS.md "Default solve: wall time", 79 files at
#: load ~1.5, files over 20k lines, the 0.3 s fixed part taken out): at most 8.5 us per line
#: without a rotation (prusa25_xend_honey25_acp), the Cura bunny 6.3; 16e-6 left the ordering
#: ~1.2 s less than the rest took on the bunny
AFTER_ORDER_S_PER_LINE = 10e-6
#: and with a rotation: rendering the rotated text (``gating.emit.render``), parsing it, and
#: building the gating problem again (``gating.rotation``: the rotated text is solved again):
#: the same runs, at most 23.3 us per line in all (real_prusa274_screw_arcs), lh01 18.4
ROTATE_S_PER_LINE = 14e-6
#: per file, whatever its size
AFTER_ORDER_FIXED_S = 0.3
#: the slowdown is measured only after this much wall time (less: too short to tell), and taken
#: at most this large (beyond it the run cannot keep its budget anyway: the ordering is skipped,
#: ``rewrite.order.stage_floor_s``)
SLOWDOWN_PROBE_S = 0.5
MAX_SLOWDOWN = 4.0
#: a run that spent at least this many seconds compiling numba kernels before its ordering is a
#: first run after an install or an update (``budget_clock``)
FIRST_RUN_COMPILE_S = 1.0
#: a file's reading, per file: interpreter start-up and imports, counted from the process's start
#: (``cli.clock``; ~0.7 s measured on this project's 2-core machine, quiet, warm disk)
READ_FIXED_S = 1.0


def rotates(options) -> bool:
    """Whether gating with ``options`` (``GatingOptions``) may turn the print: a rotation not
    "none" nor a whole turn (the rotated text is rendered, parsed and solved again)."""
    r = options.rotate
    return r != "none" and not (not isinstance(r, str) and float(r) % 360.0 == 0.0)


def after_order_s(n_lines: int, rotate: bool) -> float:
    """Estimated seconds of a run after its ordering (module docstring)."""
    return AFTER_ORDER_FIXED_S + n_lines * (AFTER_ORDER_S_PER_LINE + (ROTATE_S_PER_LINE if rotate else 0.0))


def slowdown_factor(started_s: float, cpu_started_s: float | None, wall_now_s: float | None = None,
             cpu_now_s: float | None = None) -> float:
    """Wall seconds per CPU second of this process since ``started_s`` (``time.perf_counter()``)
    / ``cpu_started_s`` (``time.process_time()`` at that moment; None: unknown, 1.0), clipped to
    [1, ``MAX_SLOWDOWN``] (module docstring). ``wall_now_s`` / ``cpu_now_s``: the clocks' readings
    now (default: read them)."""
    if cpu_started_s is None:
        return 1.0
    wall = (time.perf_counter() if wall_now_s is None else wall_now_s) - started_s
    cpu = (time.process_time() if cpu_now_s is None else cpu_now_s) - cpu_started_s
    if wall < SLOWDOWN_PROBE_S or cpu <= 0.0:
        return 1.0
    return min(max(wall / cpu, 1.0), MAX_SLOWDOWN)


#: the dependencies whose bytecode a first run after an install writes as it imports them
#: (``fresh_install``)
FIRST_IMPORTS = ("numpy", "scipy", "numba", "highspy")


def fresh_install(started_s: float, modules=FIRST_IMPORTS, now_s: float | None = None) -> bool:
    """Whether this process, started at ``started_s`` (``time.perf_counter()``), wrote the
    bytecode of any of ``modules`` it imported: the first run after an install (a fresh venv's
    first imports compile thousands of files: README's first command after `.ci/run` in a
    fresh venv read for 62.6 s at 1/4 of a core, numba's kernels cached already, and skipped its
    ordering). Not detected where no bytecode is written (PYTHONDONTWRITEBYTECODE, read-only
    site-packages)."""
    now = time.perf_counter() if now_s is None else now_s
    wall_started = time.time() - (now - started_s)
    for name in modules:
        mod = sys.modules.get(name)
        src = getattr(mod, "__file__", None)
        if not src:
            continue
        try:
            pyc = importlib.util.cache_from_source(src)
            if os.path.getmtime(pyc) >= wall_started - 1.0:
                return True
        except (OSError, NotImplementedError, ValueError):
            continue
    return False


def budget_clock(started_s: float, cpu_started_s: float | None, n_lines: int,
                 now_s: float | None = None, compiled_s: float | None = None,
                 cpu_now_s: float | None = None, fresh: bool | None = None) -> tuple[float, float]:
    """(the moment a whole-run budget counts from, ``slowdown_factor``), read before the curve
    ordering of a run that started at ``started_s`` / ``cpu_started_s`` (``slowdown_factor``).

    A later run: ``started_s`` and the wall / CPU ratio as measured. A first run after an install
    or an update (at least ``FIRST_RUN_COMPILE_S`` of numba compiling so far, ``_jit``, or its
    dependencies' bytecode written by this process, ``fresh_install``; ``fresh``: that, given): its
    reading counted at the quiet rate (``READ_FIXED_S`` + ``READ_S_PER_LINE`` per line) and a
    slowdown of 1, so that it solves as a later run on a quiet machine does, as the CLI's note
    says. What such a run measures on itself is no measure of load: a fresh clone's first
    ``gatesopt solve`` (README's first command) read for 106 s, 35 s of it compiling and the rest
    waiting (wall / CPU 2.8: the first imports and the kernel cache's writes, on a machine booted
    a minute before), and skipped its ordering; the same command on a warm disk read for 37 s and
    re-ordered. Compiling after this moment stays uncounted as before (``compile_s_since``).
    ``now_s``, ``cpu_now_s``, ``compiled_s``: the clocks' and ``_jit``'s readings now (default:
    read them)."""
    now = time.perf_counter() if now_s is None else now_s
    if compiled_s is None:
        compiled_s = _jit.compile_s_since(started_s)
    if fresh is None:
        fresh = fresh_install(started_s, now_s=now)
    if compiled_s < FIRST_RUN_COMPILE_S and not fresh:
        return started_s, slowdown_factor(started_s, cpu_started_s, now, cpu_now_s)
    return now - (READ_FIXED_S + READ_S_PER_LINE * int(n_lines)), 1.0


#: with ``budget_s`` and an exact gating formulation (milp, cpsat), the share of what the budget
#: would leave the curve ordering that goes to the gating solves instead
EXACT_GATING_SHARE = 0.5
#: and at most this many seconds (the rest of the budget goes to the ordering, which gains
#: percents where the search over dp's warm start gains hundredths): milp's gating solves took
#: 0.02-0.08 s on budget-bound Cura files (pins__cura_ender3, holes__cura_mk3, plate__cura_ender3)
#: while the half share kept ~3 s from the ordering: milp saved 2.72 % against dp's 3.66 % there
EXACT_GATING_RESERVE_S = 1.0
#: the least time limit the budget leaves an exact gating solve (it then answers with its warm
#: start, dp's answer, and says it stopped on its time limit)
MIN_EXACT_GATING_S = 0.5


def gating_limit_s(program: Program, o, budget_s: float, t0: float, time_limit_s, slow: float,
                   notes: list):
    """The exact gating solves' time limit (``o``: the run's ``GatingOptions``) within the whole run's ``budget_s`` (counted from
    ``t0``): what is left after the time spent and the estimate of building, rotating, emitting
    and checking (``budget.after_order_s``, at the machine's ``slow`` rate), at most
    ``time_limit_s``, at least ``MIN_EXACT_GATING_S``; a note where it is less than
    ``time_limit_s``. So that the run's time, solves included, is the budget's (issue 37)."""
    rotate = rotates(o)
    spent_s = time.perf_counter() - t0 - _jit.compile_s_since(t0)
    left_s = budget_s - spent_s - slow * after_order_s(max(int(program.n_lines), int(program.n_steps)), rotate)
    limit = max(left_s, MIN_EXACT_GATING_S)
    if time_limit_s is not None and limit >= float(time_limit_s):
        return time_limit_s
    notes.append(f"gating: the {budget_s:g} s budget (--budget) leaves the solver {limit:.1f} s"
                 + (f" of its {float(time_limit_s):g} s time limit" if time_limit_s is not None else "")
                 + " (a larger --budget gives it more)")
    return limit


def ordering_budget_s(budget_s: float, program: Program, options, formulation: str, gating: bool,
                      spent_s: float, time_limit_s: float | None = None, slow: float = 1.0) -> float:
    """What a whole-run ``budget_s`` leaves the curve ordering (build, solve, emit), ``spent_s``
    (reading the file) already gone, the stages after it estimated ``slow`` times their quiet
    rates (``slowdown_factor``). ``rewrite.order.solve_budget_s`` keeps at least a share of it for the
    solve however little is left."""
    n = max(int(program.n_lines), int(program.n_steps))
    rotate = gating and options is not None and rotates(options)
    rest = after_order_s(n, rotate) if gating else AFTER_ORDER_FIXED_S + n * AFTER_ORDER_S_PER_LINE / 2
    # the ordering's own emit (``rewrite.order.solve_budget_s`` estimates it at quiet rates)
    emit = FINISH_FIXED_S + FINISH_S_PER_LINE * int(program.n_lines)
    return budget_s - spent_s - slow * rest - (slow - 1.0) * emit


def no_time_note(budget_s: float, spent_s: float, slow: float, left_s: float | None = None,
                 floor_s: float | None = None) -> str:
    """The note of a run whose budget left the curve ordering no time: ``left_s`` what the budget
    left it, ``floor_s`` what it takes without searching (``rewrite.order.stage_floor_s``)."""
    load = (f"; the machine is loaded: this run got 1/{slow:.1f} of a core so far"
            if slow > 1.5 else "")
    than = (f" ({left_s:.1f} s, less than the {floor_s:.1f} s its build, group pass and emit "
            "take without searching)" if left_s is not None and floor_s is not None else "")
    return (f"curve ordering skipped: the {budget_s:g} s budget (--budget) leaves it no time{than} "
            f"after {spent_s:.1f} s of reading and the estimate of gating and checking{load}: the "
            "slicer's order kept (a larger --budget re-orders)")


def on_print(sol, after_s: float, limit_s: float):
    """``sol`` (a ``GatingSolution``) judged on the print time a run's time budget is on: the
    output's planner time ``after_s`` against ``limit_s`` (``pipeline.budget_limit_s``), what
    `solve`'s "time budget" line and `compare`'s "print +%" column give. Only greedy's status
    changes: the paper's re-compiler knows no budget, and its own solve can judge it only by the
    gating model's time (T = L/F plus stalls: 7.6 % added where the planner's print time is
    +0.48 %, bambustudio020301_cube20mm), so a run that keeps the budget was labelled infeasible
    (and one that breaks it could have been labelled feasible). Every other formulation keeps
    the budget by solving (``pipeline._within_limit``)."""
    if sol.formulation != "greedy":
        return sol
    from ..gating.greedy import judged
    over = None if after_s <= limit_s * (1.0 + 1e-9) else (
        f"print time {after_s:.2f} s > {limit_s:.2f} s allowed (planner model)")
    return judged(sol, over)
