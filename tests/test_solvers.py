"""The one solver vocabulary (gatesopt.solvers): statuses, the gap, the registries."""
import json
import math

import pytest

from gatesopt import solvers
from gatesopt.errors import GatesoptError
from gatesopt.gating.solve import FORMULATIONS as GATING, is_installed


def test_status_reads_and_writes_as_its_value():
    assert solvers.Status.OPTIMAL == "optimal"
    assert f"{solvers.Status.FEASIBLE}" == "feasible" and str(solvers.Status.FALLBACK) == "fallback"
    assert json.dumps({"s": solvers.Status.INFEASIBLE}) == '{"s": "infeasible"}'
    assert solvers.STATUSES == ("optimal", "feasible", "fallback", "infeasible")


def test_relative_gap():
    assert solvers.relative_gap(10.0, 9.0) == pytest.approx(0.1)
    assert solvers.relative_gap(10.0, 10.0 - 1e-9, abs_tol=1e-6) == 0.0
    assert solvers.relative_gap(10.0, 10.0 - 1e-3, abs_tol=1e-6) == pytest.approx(1e-4)
    assert math.isnan(solvers.relative_gap(10.0, -math.inf))
    assert solvers.relative_gap(10.0, 11.0) == 0.0        # a bound above the objective is no gap
    assert solvers.relative_gap(-10.0, -12.0) == pytest.approx(0.2)   # |objective| in the denominator


def test_registry_errors_name_the_choices():
    with pytest.raises(GatesoptError, match="unknown gating formulation 'nope': choose one of greedy, dp"):
        is_installed("nope")
    missing = solvers.Formulation("x", "gatesopt.nowhere", backends=("no_such_package_gatesopt",))
    assert not missing.is_installed()
    with pytest.raises(GatesoptError, match="needs the Python package 'no_such_package_gatesopt'"):
        missing.load()
    assert GATING["milp"].is_installed()
