"""Curve ordering (Fleming et al.): re-order each layer's extrusion curves, each in either
direction, to cut non-extruding travel — an open-path ATSP with endpoint flips.

    problem = build(program, OrderingOptions(mode="safe"))     # or from_polylines(...)
    solution = solve(problem, "auto", time_limit_s=2.0)
    text = emit(program, problem, solution)

Formulations (``gatesopt/ordering/<name>.py``, math in formulations/ordering.md): greedy, tsp,
cpsat, milp, auto.
"""
from __future__ import annotations

from .layers import FORMULATIONS, solve
from .polylines import from_polylines
from .problem import (Group, GroupSolution, OrderingOptions, OrderingProblem, OrderingSolution)
# The functions, bound after their modules have loaded: ``gatesopt.ordering.build`` and
# ``gatesopt.ordering.emit`` are the functions, not the submodules of the same names.
from .build import build  # noqa: E402
from .emit import emit  # noqa: E402


__all__ = ["build", "solve", "emit", "from_polylines", "FORMULATIONS", "Group", "GroupSolution",
           "OrderingOptions", "OrderingProblem", "OrderingSolution"]
