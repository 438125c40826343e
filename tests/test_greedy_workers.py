"""Greedy's answer does not depend on the number of workers (issue 36: an exact run is never
slower than ``--formulation greedy`` because its greedy pass is that run's answer): with two
workers the second process makes link matrices only (``ordering.matrix_helper``), the main
process chains every group in print order as one process does. Checked on answers, never on
timings: the same paths with one worker and two, the exact run's greedy pass the same as the
greedy run's, the matrices handed over the same numbers as those made in place."""
from __future__ import annotations

import numpy as np
import pytest

import gatesopt
from gatesopt.ordering import helper, layers, matrix_helper
from gatesopt.ordering.groups import build
from gatesopt.ordering.polylines import from_polylines
from gatesopt.ordering.problem import OrderingOptions

from conftest import (PROJECT_INSTANCES, SHARED_INSTANCES, matrix_helper_first, needs_shared,
                      random_line_layers)


def _same_answer(a, b) -> None:
    """Two solutions print the same file: the same curves in the same order, each the same way
    round from the same seam, from the same per-group paths."""
    assert np.array_equal(a.curve_order, b.curve_order)
    assert np.array_equal(a.curve_reversed, b.curve_reversed)
    assert np.array_equal(a.curve_seam, b.curve_seam)
    assert [gs.formulation for gs in a.groups] == [gs.formulation for gs in b.groups]
    assert [gs.objective for gs in a.groups] == [gs.objective for gs in b.groups]


def _real(path, mode: str):
    return build(gatesopt.parse(str(path)), OrderingOptions(mode=mode))


def _chain_helper_first(monkeypatch) -> None:
    """Where a chain helper (``helper.Helper``, the exact formulations' second process) is
    started, it answers every group, from the back, before the chain's first group."""
    start = helper.Helper.start.__func__

    def start_and_wait(cls, *args, **kwargs):
        h = start(cls, *args, **kwargs)
        if h is not None:
            h.wait()
        return h

    monkeypatch.setattr(helper.Helper, "start", classmethod(start_and_wait))


@pytest.mark.parametrize("seed", range(2))
def test_greedy_on_random_layers_is_the_same_with_two_workers(monkeypatch, seed):
    """The travel objective (no matrix worth a helper): two workers chain in one process. Before,
    a chain helper solved groups from the back, each from another start than one worker's:
    other paths, here in every group (the helper answering them all first)."""
    _chain_helper_first(monkeypatch)
    sizes = [int(n) for n in np.random.default_rng(seed).integers(8, 30, 24)]
    prob = from_polylines(random_line_layers(sizes, seed=seed), options=OrderingOptions(mode="free"))
    assert len(helper.groups_to_solve(prob)) >= helper.HELPER_MIN_GROUPS
    one = layers.solve(prob, "greedy", workers=1)
    two = layers.solve(prob, "greedy", workers=2)
    _same_answer(one, two)


@pytest.fixture
def small_helper(monkeypatch):
    """A matrix helper even for a file of 9 groups (the project's instances are small)."""
    monkeypatch.setattr(matrix_helper, "MATRIX_HELPER_MIN_GROUPS", 2)
    monkeypatch.setattr(matrix_helper, "MATRIX_HELPER_MIN_S", 0.0)


def _check_greedy_pass(prob, one, monkeypatch) -> None:
    """Two workers, as timing goes and with every matrix handed over: one worker's answer; the
    exact run's greedy pass (``solve_greedy``) is the greedy run's, with every group's bound,
    and a matrix for every group (the helper's, where it made one, equal to one worker's)."""
    _same_answer(one.solution, layers.solve(prob, "greedy", workers=2))
    matrix_helper_first(monkeypatch)
    two = layers.solve(prob, "greedy", workers=2)
    _same_answer(one.solution, two)
    gp = layers.solve_greedy(prob, workers=2)
    _same_answer(gp.solution, two)
    todo = matrix_helper.matrix_groups(prob)
    assert gp.handed == frozenset(todo)
    for g in todo:
        assert np.array_equal(gp.matrices[g], one.matrices[g])
        assert gp.answers[g] is not None
        assert gp.answers[g].bound == one.answers[g].bound


@pytest.mark.parametrize("mode", ["free", "safe"])
def test_greedy_on_a_real_file_is_the_same_with_two_workers(small_helper, monkeypatch, mode):
    """The time objective: the helper makes link matrices, the paths stay one worker's."""
    prob = _real(PROJECT_INSTANCES / "star_lines_m82.gcode", mode)
    _check_greedy_pass(prob, layers.solve_greedy(prob, workers=1), monkeypatch)


@needs_shared
def test_greedy_on_a_corpus_file_is_the_same_with_two_workers(small_helper, monkeypatch):
    """As above on a corpus file (54 groups)."""
    prob = _real(SHARED_INSTANCES / "real_ideamaker420.gcode", "free")
    _check_greedy_pass(prob, layers.solve_greedy(prob, workers=1), monkeypatch)


def test_the_matrices_handed_over_are_those_made_here(small_helper):
    """Every matrix the helper sends is, bit for bit, the one the main process makes for the same
    group from any start (here: the origin, and the slicer's start of the group)."""
    prob = _real(PROJECT_INSTANCES / "cyl_grid.gcode", "free")
    maker = matrix_helper.MatrixHelper.start(prob)
    assert maker is not None
    try:
        maker.wait()
        todo = matrix_helper.matrix_groups(prob)
        got = {g: maker.take(g) for g in todo}
    finally:
        maker.stop()
    assert all(arc is not None for arc in got.values())     # the main process never came
    for g, arc in got.items():
        here = prob.group(g, prob.origin_xy).costs.matrix()
        assert arc.dtype == here.dtype and np.array_equal(arc, here)
        c = int(prob.group_curve_start[g])
        there = prob.group(g, prob.curve_start_xy[c])
        assert np.array_equal(matrix_helper.with_arc(there, arc).arc_cost(), there.arc_cost())


def test_no_helper_without_a_time_objective_or_matrices_worth_one(monkeypatch):
    prob = from_polylines(random_line_layers([10] * 20), options=OrderingOptions(mode="free"))
    assert matrix_helper.matrix_groups(prob) == []
    assert matrix_helper.MatrixHelper.start(prob) is None
    # a real file whose matrices are planned at well under MATRIX_HELPER_MIN_S (enough groups)
    monkeypatch.setattr(matrix_helper, "MATRIX_HELPER_MIN_GROUPS", 2)
    prob = _real(PROJECT_INSTANCES / "cyl_grid.gcode", "free")
    todo = matrix_helper.matrix_groups(prob)
    assert 0 < matrix_helper.planned_matrix_s(prob, todo) < matrix_helper.MATRIX_HELPER_MIN_S
    assert matrix_helper.MatrixHelper.start(prob) is None
