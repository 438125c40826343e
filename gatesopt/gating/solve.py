"""Formulation registry: name -> module with ``solve(problem, *, time_limit_s, hint) -> GatingSolution``.

As cvxpy's solver registry: a dict of names to ``solvers.Formulation`` records, each module
imported on first use; ``is_installed`` checks the backend with ``importlib.util.find_spec``
without importing it (gatesopt.solvers).
"""
from __future__ import annotations

from ..errors import GatesoptError
from ..solvers import Formulation, lookup
from .problem import GatingProblem
from .solution import GatingSolution

FORMULATIONS: dict[str, Formulation] = {
    "greedy": Formulation("greedy", "gatesopt.gating.greedy",
                          description="the paper's re-compiler (Algorithm 1), the baseline"),
    "dp": Formulation("dp", "gatesopt.gating.dp", capabilities=frozenset({"exact_separable"}),
                      description="exact per-motor pass where the problem separates"),
    "milp": Formulation("milp", "gatesopt.gating.milp", backends=("highspy",),
                        capabilities=frozenset({"exact", "budgets", "warm_start"}),
                        description="HiGHS: budgets, shared lines, rotation choice"),
    "cpsat": Formulation("cpsat", "gatesopt.gating.cpsat", backends=("ortools",),
                         capabilities=frozenset({"exact", "budgets", "warm_start"}),
                         description="OR-Tools CP-SAT: the same model"),
}


def is_installed(formulation: str) -> bool:
    return lookup(FORMULATIONS, formulation, "gating").is_installed()


def solve(problem: GatingProblem, formulation: str = "dp", *, time_limit_s: float | None = None,
          hint: GatingSolution | None = None) -> GatingSolution:
    """Solve ``problem`` with the named formulation (``greedy``, ``dp``, ``milp``, ``cpsat``)."""
    entry = lookup(FORMULATIONS, formulation, "gating")
    module = entry.load()
    if time_limit_s is not None and not time_limit_s > 0:
        raise GatesoptError(f"time limit must be > 0 s, not {time_limit_s!r}")
    return module.solve(problem, time_limit_s=time_limit_s, hint=hint)
