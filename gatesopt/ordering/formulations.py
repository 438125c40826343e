"""The curve ordering's formulations by name (formulations/ordering.md): ``solvers.Formulation``
records, as ``gating.solve`` and cvxpy's solver registry keep them. Each module is imported on
first use, so ``import gatesopt.ordering`` loads neither OR-Tools nor HiGHS; every module has
``solve(group, *, time_limit_s, hint=None, **kwargs) -> GroupSolution``.

Capabilities (``Formulation.capabilities``), what the solve driver (``layers.solve``) asks:

    exact       proves a group optimal given time (the bound meets the path)
    look_ahead  its paths are chained with look-ahead re-solves across group boundaries
                (``chain.look_ahead``). Without it (greedy and tsp, the paper's baselines) groups
                chain as Fleming et al.'s Algorithm 1 chains layers: each from where the last ended
    warm_up     calls compiled kernels (numba caches, HiGHS) that ``auto.warm_up`` loads before
                the first group, outside any group's limit
    one_chain   its answer must not depend on the number of workers: every group is chained in
                the main process, from the previous group's end; a second worker only makes link
                matrices (``matrix_helper``). Greedy: ``--formulation greedy`` and the exact
                run's greedy pass are one answer with one process or two
    any_size    takes groups of any size (``dp``, exact up to ``dp.fits``, raises above: library
                only, not a CLI choice)
"""
from __future__ import annotations

from .. import solvers
from ..errors import GatesoptError
from ..solvers import Formulation
from .problem import OrderingOptionsError

FORMULATIONS: dict[str, Formulation] = {
    "greedy": Formulation("greedy", "gatesopt.ordering.greedy_pass",
                          capabilities=frozenset({"any_size", "one_chain"}),
                          description="nearest neighbour, 2-opt, Or-opt, orientation DP; subset DP on small "
                                      "groups, matching where cheap"),
    "tsp": Formulation("tsp", "gatesopt.ordering.tsp", backends=("ortools",),
                       capabilities=frozenset({"any_size"}),
                       description="Fleming et al. Algorithm 1: a shortest closed tour, cut open"),
    "cpsat": Formulation("cpsat", "gatesopt.ordering.cpsat", backends=("ortools",),
                         capabilities=frozenset({"exact", "look_ahead", "any_size"}),
                         description="OR-Tools CP-SAT circuit model"),
    "milp": Formulation("milp", "gatesopt.ordering.milp", backends=("highspy",),
                        capabilities=frozenset({"exact", "look_ahead", "warm_up", "any_size"}),
                        description="HiGHS: the symmetric model (branch-and-cut), else the directed"),
    "auto": Formulation("auto", "gatesopt.ordering.auto", backends=("highspy",),
                        capabilities=frozenset({"exact", "look_ahead", "warm_up", "any_size"}),
                        description="exact where it pays (DP, bounds, matching, milp), else ILS"),
    "dp": Formulation("dp", "gatesopt.ordering.dp",
                      capabilities=frozenset({"exact", "look_ahead"}),
                      description="subset DP, exact for small groups (library only)"),
}


def lookup(name: str) -> Formulation:
    """``FORMULATIONS[name]``, or an ``OrderingOptionsError`` naming the choices."""
    try:
        return solvers.lookup(FORMULATIONS, name, "ordering")
    except GatesoptError as exc:
        raise OrderingOptionsError(str(exc)) from None


def group_solver(name: str):
    """The named formulation's ``solve`` (its module imported now)."""
    return lookup(name).load().solve


def warm_up() -> None:
    """Load the compiled kernels the ``warm_up`` formulations call (``auto.warm_up``)."""
    FORMULATIONS["auto"].load().warm_up()
