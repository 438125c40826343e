"""Motor power gating (3DGates, Chen et al., ASPLOS'17, Section 4).

``build(program, options) -> GatingProblem``; ``solve(problem, formulation=...) -> GatingSolution``;
``emit(program, solution, firmware=...) -> str``. The whole rewrite (order, gate, rotate, emit,
verify) in one call is ``gatesopt.rewrite.run``.
Formulations: ``greedy`` (the paper's Algorithm 1), ``dp``, ``milp``, ``cpsat``; the math is in
``formulations/gating.md``. ``gating.cvxpy_model.to_cvxpy`` writes the coupled model as a cvxpy
problem for planners that add constraints of their own.

Modules: ``options`` (GatingOptions), ``problem`` (GatingProblem, build), ``rotation`` (angles,
bed fit, which rows rotate), ``timeline`` (moments among steps), ``scoring`` (the one energy
function over off intervals), ``solution`` (GatingSolution), ``moves`` (from another planner's
arrays), ``coupled`` (the solver-neutral model and its share bound), the formulations, ``solve``
(registry), ``emit`` / ``emit_line`` / ``emit_plain`` / ``placement`` (G-code out).
"""
from .emit import emit
from .moves import from_moves
from .options import GatingOptions, GatingOptionsError
from .problem import GatingProblem, build, steps_motor_at
from .scoring import Instructions, Pieces, check_feasible, score
from .solution import GatingSolution
from .solve import FORMULATIONS, solve

__all__ = ["GatingOptions", "GatingOptionsError", "GatingProblem", "GatingSolution", "Instructions",
           "Pieces", "build", "check_feasible", "from_moves", "score", "steps_motor_at", "solve",
           "FORMULATIONS", "emit"]
