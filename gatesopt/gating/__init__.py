"""Motor power gating (3DGates, Chen et al., ASPLOS'17, Section 4).

``build(program, options) -> GatingProblem``; ``solve(problem, formulation=...) -> GatingSolution``;
``emit(program, solution, firmware=...) -> str``; ``run(program, options, ...)`` does the whole rewrite
(order, gate, emit, verify) in one call.
Formulations: ``greedy`` (the paper's Algorithm 1), ``dp``, ``milp``, ``cpsat``; the math is in
``formulations/gating.md``.
"""
from .emit import emit
from .pipeline import RunResult, run
from .problem import (GatingOptions, GatingOptionsError, GatingProblem, GatingSolution, Instructions,
                      Pieces, build, check_feasible, from_moves, score, steps_motor_at)
from .solve import FORMULATIONS, solve

__all__ = ["GatingOptions", "GatingOptionsError", "GatingProblem", "GatingSolution", "Instructions",
           "Pieces", "build", "check_feasible", "from_moves", "score", "steps_motor_at", "solve",
           "FORMULATIONS", "emit", "run", "RunResult"]
