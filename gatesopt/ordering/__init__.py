"""Curve ordering (Fleming et al.): re-order each layer's extrusion curves, each in either
direction, to cut non-extruding travel — an open-path ATSP with endpoint flips.

    problem = build(program, OrderingOptions(mode="safe"))     # or from_polylines(...)
    solution = solve(problem, "auto", time_limit_s=2.0)
    text = emit(program, problem, solution)

Formulations (``FORMULATIONS``: ``gatesopt/ordering/<name>.py``, imported on first use; math in
formulations/ordering.md): greedy, tsp, cpsat, milp, auto (and dp, for small groups).

Modules: ``problem`` (options, Group, solutions), ``layout`` and ``groups`` (Program -> problem),
``polylines``; ``layers`` (the solve driver) with ``budget``, ``runner``, ``chain``, ``helper``;
the formulations and what they share (``bounds``, ``greedy``, ``ils``, ``matching``,
``blossom``, ``symmetric_graph``, ``symmetric``, ``separation``); ``emitter`` (emit) with
``writer``, ``travel``, ``gaps``, ``wipes``; the time objective's prices in ``cost`` (per link:
``link_cost``); ``plot``. No module is named after a function exported here
(``build`` lives in ``groups``, ``emit`` in ``emitter``), so ``gatesopt.ordering.emit`` is always
the function and ``import gatesopt.ordering.emitter`` always the module.
"""
from __future__ import annotations

from .emitter import emit
from .formulations import FORMULATIONS
from .groups import build
from .layers import solve
from .polylines import from_polylines
from .problem import (Group, GroupSolution, OrderingOptions, OrderingOptionsError, OrderingProblem,
                      OrderingSolution)

__all__ = ["build", "solve", "emit", "from_polylines", "FORMULATIONS", "Group", "GroupSolution",
           "OrderingOptions", "OrderingOptionsError", "OrderingProblem", "OrderingSolution"]
