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
"""
from __future__ import annotations

from ..program import Program

#: seconds per input line of the stages after the ordering, without a rotation: the gating
#: problem's build and dp solve, the emit, parsing the output, the verifier and the report's
#: planner times and travel (measured, docs/RESULTS.md "Default solve: wall time")
AFTER_ORDER_S_PER_LINE = 16e-6
#: and with a rotation: rendering the rotated text (``gating.emit.render``), parsing it, and
#: building the gating problem again (``gating.rotation``: the rotated text is solved again)
ROTATE_S_PER_LINE = 8e-6
#: per file, whatever its size
AFTER_ORDER_FIXED_S = 0.3


def after_order_s(n_lines: int, rotate: bool) -> float:
    """Estimated seconds of a run after its ordering (module docstring)."""
    return AFTER_ORDER_FIXED_S + n_lines * (AFTER_ORDER_S_PER_LINE + (ROTATE_S_PER_LINE if rotate else 0.0))


def ordering_budget_s(budget_s: float, program: Program, options, formulation: str, gating: bool,
                      spent_s: float, time_limit_s: float | None = None) -> float:
    """What a whole-run ``budget_s`` leaves the curve ordering (build, solve, emit), ``spent_s``
    (reading the file) already gone. ``rewrite.order.solve_budget_s`` keeps at least a share of
    it for the solve however little is left."""
    n = max(int(program.n_lines), int(program.n_steps))
    rotate = gating and options is not None and options.rotate != "none" and not (
        not isinstance(options.rotate, str) and float(options.rotate) % 360.0 == 0.0)
    rest = after_order_s(n, rotate) if gating else AFTER_ORDER_FIXED_S + n * AFTER_ORDER_S_PER_LINE / 2
    return budget_s - spent_s - rest
