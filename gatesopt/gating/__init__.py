"""Motor power gating (3DGates, Chen et al., ASPLOS'17, Section 4).

``build(program, options) -> GatingProblem``; ``solve(problem, formulation=...) -> GatingSolution``.
Formulations: ``greedy`` (the paper's Algorithm 1), ``dp``, ``milp``, ``cpsat``; the math is in
``formulations/gating.md``.
"""
from .problem import (GatingOptions, GatingOptionsError, GatingProblem, GatingSolution, Instructions,
                      Pieces, build, check_feasible, from_moves, score, steps_motor_at)
from .solve import FORMULATIONS, solve

__all__ = ["GatingOptions", "GatingOptionsError", "GatingProblem", "GatingSolution", "Instructions",
           "Pieces", "build", "check_feasible", "from_moves", "score", "steps_motor_at", "solve",
           "FORMULATIONS"]

try:  # emit lives in gatesopt/gating/emit.py (written alongside)
    from .emit import emit  # noqa: F401
    __all__.append("emit")
except ModuleNotFoundError as exc:  # pragma: no cover - only while emit.py does not exist
    if exc.name != f"{__name__}.emit":
        raise
