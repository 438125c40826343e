"""One solver vocabulary for both problem families (power gating, curve ordering).

As cvxpy does it: every formulation answers with one of four statuses, a bound where it has one,
and one definition of the optimality gap; formulations are registered by name with the Python
packages they need and what they can do, and are imported on first use (``is_installed`` looks
for the backend with ``importlib.util.find_spec`` without importing it).

Status
    ``optimal``    proven optimal: the objective meets the bound (within the formulation's
                   tolerance: ``mip_rel_gap`` for HiGHS, an absolute 1e-6 mm for travel);
    ``feasible``   a valid answer without a proof, with its gap to the bound;
    ``fallback``   a valid answer from a simpler method after the named one could not give one
                   (a time limit hit before the first solution, an interrupted solve);
    ``infeasible`` no valid answer exists under the constraints (budgets that cannot be met).

Gap
    ``relative_gap(objective, bound) = (objective - bound) / |objective|``, a unitless fraction
    (0.02 is 2 %), >= 0; NaN where the formulation has no finite bound. Objective and bound are in
    the problem's own unit (J for gating, mm or s of travel for ordering). "Gap" means only this;
    a motor's idle time between two steps is an *idle interval*.
"""
from __future__ import annotations

import enum
import importlib
import importlib.util
import math
from dataclasses import dataclass

from .errors import GatesoptError


class Status(str, enum.Enum):
    """What a formulation's answer is (module docstring)."""

    OPTIMAL = "optimal"
    FEASIBLE = "feasible"
    FALLBACK = "fallback"
    INFEASIBLE = "infeasible"

    def __str__(self) -> str:           # "optimal", as the reports have always written it
        return self.value

    def __format__(self, spec: str) -> str:
        return format(self.value, spec)


STATUSES = tuple(s.value for s in Status)


def relative_gap(objective: float, bound: float, *, abs_tol: float = 0.0) -> float:
    """(objective - bound) / |objective|, >= 0; 0 where they differ by at most ``abs_tol`` (float
    noise in the objective's unit); NaN where ``bound`` is not finite (no bound)."""
    if not math.isfinite(bound):
        return math.nan
    if objective - bound <= abs_tol:
        return 0.0
    return max(0.0, (objective - bound) / max(abs(objective), 1e-12))


@dataclass(frozen=True)
class Formulation:
    """A registered formulation: where its ``solve`` lives, what it needs, what it can do."""

    name: str
    module: str                         # dotted module path holding ``solve``
    backends: tuple = ()                # Python packages it needs beyond the core dependencies
    capabilities: frozenset = frozenset()   # e.g. {"exact", "budgets", "warm_start"}
    description: str = ""

    def is_installed(self) -> bool:
        return all(importlib.util.find_spec(b) is not None for b in self.backends)

    def load(self):
        """The module, imported on first use; a clear error where a backend is missing."""
        if not self.is_installed():
            missing = [b for b in self.backends if importlib.util.find_spec(b) is None]
            raise GatesoptError(f"formulation {self.name!r} needs the Python package "
                                f"{missing[0]!r}, which is not installed")
        return importlib.import_module(self.module)


def lookup(registry: dict, name: str, family: str) -> Formulation:
    """``registry[name]``, or a ``GatesoptError`` naming the choices."""
    try:
        return registry[name]
    except KeyError:
        raise GatesoptError(f"unknown {family} formulation {name!r}: choose one of "
                            f"{', '.join(registry)}") from None
