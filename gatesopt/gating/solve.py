"""Formulation registry: name -> module with ``solve(problem, *, time_limit_s, hint) -> GatingSolution``.

As cvxpy's solver registry: a dict of names to modules, imported on first use, and
``is_installed`` checks the backend with ``importlib.util.find_spec`` without importing it.
"""
from __future__ import annotations

import importlib
import importlib.util

from ..errors import GatesoptError
from .problem import GatingProblem, GatingSolution

# name -> (module, backend package needed)
FORMULATIONS: dict[str, tuple[str, str | None]] = {
    "greedy": ("gatesopt.gating.greedy", None),
    "dp": ("gatesopt.gating.dp", None),
    "milp": ("gatesopt.gating.milp", "highspy"),
    "cpsat": ("gatesopt.gating.cpsat", "ortools"),
}


def is_installed(formulation: str) -> bool:
    _, backend = FORMULATIONS[formulation]
    return backend is None or importlib.util.find_spec(backend) is not None


def solve(problem: GatingProblem, formulation: str = "dp", *, time_limit_s: float | None = None,
          hint: GatingSolution | None = None) -> GatingSolution:
    """Solve ``problem`` with the named formulation (``greedy``, ``dp``, ``milp``, ``cpsat``)."""
    if formulation not in FORMULATIONS:
        raise GatesoptError(f"unknown gating formulation {formulation!r}: choose one of {', '.join(FORMULATIONS)}")
    if not is_installed(formulation):
        raise GatesoptError(f"formulation {formulation!r} needs the Python package "
                            f"{FORMULATIONS[formulation][1]!r}, which is not installed")
    if time_limit_s is not None and not time_limit_s > 0:
        raise GatesoptError(f"time limit must be > 0 s, not {time_limit_s!r}")
    module = importlib.import_module(FORMULATIONS[formulation][0])
    return module.solve(problem, time_limit_s=time_limit_s, hint=hint)
