"""The whole job (gatesopt.rewrite): nothing is swallowed around the curve ordering.

Before issue 35 the whole-job call caught (ImportError, AttributeError, NotImplementedError) around
the ordering and wrote a gating-only file with the note "curve ordering skipped: gatesopt.ordering
not available": a bug in the ordering looked like a missing package, and the user got a file they
had not asked for."""
from __future__ import annotations

import pytest

from gatesopt import GatesoptError, parse
from gatesopt.gating import GatingOptions
from gatesopt.rewrite import order, order_program, run

from conftest import PROJECT_INSTANCES


def _program():
    return parse(PROJECT_INSTANCES / "square_lines.gcode")


def test_a_bug_in_the_ordering_propagates(monkeypatch):
    def broken(*a, **k):
        raise AttributeError("'OrderingProblem' object has no attribute 'made_up'")
    monkeypatch.setattr(order, "solve", broken)
    with pytest.raises(AttributeError, match="made_up"):
        run(_program(), GatingOptions(rotate="none"), order=True)
    with pytest.raises(AttributeError, match="made_up"):
        order_program(_program())


def test_an_error_of_the_ordering_is_not_turned_into_a_note(monkeypatch):
    # what a formulation whose backend is missing raises (``solvers.Formulation.load``)
    msg = "formulation 'cpsat' needs the Python package 'ortools', which is not installed"

    def missing(*a, **k):
        raise GatesoptError(msg)
    monkeypatch.setattr(order, "solve", missing)
    with pytest.raises(GatesoptError, match="ortools"):
        run(_program(), GatingOptions(rotate="none"), order=True)


def test_without_ordering_the_ordering_is_not_run(monkeypatch):
    def never(*a, **k):
        raise AssertionError("the ordering ran with order=False")
    monkeypatch.setattr(order, "solve", never)
    res = run(_program(), GatingOptions(rotate="none"), order=False)
    assert res.report.ok and not res.ordered and res.order_summary is None
