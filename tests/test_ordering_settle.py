"""The chain made right where it is printed (``ordering.settle``, issue 36): a group whose picked
path is not proven for the start and end the chain gives it is solved again there by the subset
DP; the chain never gets dearer, and every group reported optimal prints the DP's optimum from the
start it prints from to where it travels on."""
from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from gatesopt.ordering import OrderingOptions, dp, from_polylines, layers, settle
from gatesopt.ordering.chain import BACKWARDS, KEPT, LOOKAHEAD_FROM, end_of, reprove
from gatesopt.ordering.problem import OPTIMAL_ABS_TOL, Anchor
from gatesopt.solvers import Status
from gatesopt.verify.proofs import audit_proofs


def strokes_problem(seed: int, n_groups: int = 8):
    """Layers of 3-8 random strokes (and a loop now and then), far enough apart that where a
    group ends matters to the next one: the chain DP takes the slicer's order for the next
    group's sake."""
    rng = np.random.default_rng(seed)
    layers_ = []
    for g in range(n_groups):
        polys = []
        off = rng.uniform(0, 60, 2)
        for _ in range(int(rng.integers(3, 9))):
            if rng.random() < 0.2:
                c = off + rng.uniform(0, 30, 2)
                polys.append(np.array([c, c + [2, 0], c + [2, 2], c + [0, 2], c]))
            else:
                polys.append(off + rng.uniform(0, 30, (2, 2)))
        layers_.append(polys)
    return from_polylines(layers_, options=OrderingOptions(mode="free"))


def _chain_cost(prob, sol) -> float:
    return prob.order_cost(sol.curve_order, sol.curve_reversed, sol.curve_seam)


def reproved_only(problem, plans, picked, priced=None):
    """The chain as picked, each group not proven where it prints only proven again there
    (``chain.reprove``: the rule before ``settle``)."""
    picked = list(picked)
    entry = Anchor.of(problem.origin_xy)
    for g, (grp, _, _, _) in enumerate(plans):
        gs = picked[g]
        if problem.group_reorderable[g] and (gs.status != Status.OPTIMAL
                                             or gs.formulation.endswith(KEPT)
                                             or not settle.proof_holds(problem, plans, picked,
                                                                       g, entry)):
            gs = picked[g] = reprove(problem, g, entry,
                                     settle.printed_end(problem, plans, picked, g), gs)
        if grp.n_curves:
            entry = problem.exit_anchor(g, grp, gs.order)
    return picked


@pytest.mark.parametrize("seed", range(8))
def test_dp_from_a_first_candidate_is_the_cheapest_path_from_it(seed):
    prob = strokes_problem(seed, 1)
    grp = prob.group(0, Anchor.of(prob.origin_xy))
    per_curve = [np.flatnonzero(grp.cand_curve == c) for c in range(grp.n_curves)]
    for first in range(grp.n_cands):
        got = dp.solve(grp, first=first)
        assert got.order[0] == first and got.status == Status.FEASIBLE
        best = np.inf
        rest = [c for c in range(grp.n_curves) if c != grp.cand_curve[first]]
        for perm in itertools.permutations(rest):
            for choice in itertools.product(*(per_curve[c] for c in perm)):
                best = min(best, grp.path_cost(np.array((first,) + choice)))
        assert got.objective == pytest.approx(best)


@pytest.mark.parametrize("seed", range(10))
def test_settling_never_makes_the_chain_dearer_and_proves_where_it_prints(seed, monkeypatch):
    prob = strokes_problem(seed)
    settled = layers.solve(prob, "auto")
    monkeypatch.setattr(layers, "settle_chain", reproved_only)
    picked = layers.solve(prob, "auto")
    assert _chain_cost(prob, settled) <= _chain_cost(prob, picked) + 1e-6
    n_opt = [sum(gs.status == Status.OPTIMAL for gs in s.groups) for s in (settled, picked)]
    assert n_opt[0] >= n_opt[1]
    # every group reported optimal prints the DP's optimum from where it is entered, to where
    # it travels on: free, the problem's end, or the next group's entry as printed (but the
    # second half of a split proof, proven from the point the first half travels to:
    # formulations/ordering.md, "Across groups and layers")
    pos = Anchor.of(prob.origin_xy)
    for g, gs in enumerate(settled.groups):
        free = prob.group(g, pos, end_of(prob, g))
        split = LOOKAHEAD_FROM in gs.formulation or BACKWARDS in gs.formulation
        if gs.status == Status.OPTIMAL and prob.group_reorderable[g] and not split:
            ends = [end_of(prob, g)]
            if g + 1 < prob.n_groups and len(settled.groups[g + 1].order):
                nxt = prob.group(g + 1, pos)
                ends.append(prob.cand_anchor(g + 1, nxt, int(settled.groups[g + 1].order[0])))
            assert any(prob.group(g, pos, e).path_cost(gs.order)
                       <= dp.solve(prob.group(g, pos, e)).objective + OPTIMAL_ABS_TOL
                       for e in ends), g
        pos = prob.exit_anchor(g, free, gs.order)


def test_settling_proves_more_and_prints_cheaper_than_proving_again_alone(monkeypatch):
    # on these layers the chain DP takes paths not proven where they print (the slicer's order
    # for the next group's sake, a path entered from another start): proven again alone, some
    # stay unproven; settled, the chain is cheaper and more groups are proven
    probs = [strokes_problem(seed, 12) for seed in range(12)]
    sols = [layers.solve(p, "auto") for p in probs]
    monkeypatch.setattr(layers, "settle_chain", reproved_only)
    olds = [layers.solve(p, "auto") for p in probs]
    for p, s, o in zip(probs, sols, olds):
        assert _chain_cost(p, s) <= _chain_cost(p, o) + 1e-6
    proven = [sum(gs.status == Status.OPTIMAL for x in xs for gs in x.groups)
              for xs in (sols, olds)]
    assert proven[0] > proven[1]
    assert sum(_chain_cost(p, s) for p, s in zip(probs, sols)) < sum(
        _chain_cost(p, o) for p, o in zip(probs, olds)) - 1e-6


def test_a_proof_for_the_next_groups_entry_holds_only_where_the_file_enters_that_group_so():
    # the time guard may print the layer after a group in another order (the slicer's here):
    # a group proven for the next group's entry as its end (``settle``) is then proven again
    # where the file prints it (``guard.printed_answer`` with ``same_next_entries``); every group
    # the guard's answer reports optimal holds for the file's own start and next entry
    from gatesopt.rewrite.guard import (entry_positions, keep_layers, printed_answer,
                                        same_entry_groups, same_next_entries)
    exits_moved = 0
    for seed in range(6):
        prob = strokes_problem(seed, 10)
        sol = layers.solve(prob, "auto")
        for lay in range(1, prob.n_groups):
            final = keep_layers(prob, sol, [lay])
            entered = same_entry_groups(prob, final, sol)
            exited = same_next_entries(prob, final, sol)
            exits_moved += int(np.count_nonzero(~exited))
            first = entry_positions(prob, final)
            groups = [printed_answer(prob, final, g, gs, a, first, x) if g != lay else
                      dataclasses.replace(gs, status=Status.FEASIBLE)
                      for g, (gs, a, x) in enumerate(zip(sol.groups, entered, exited))]
            checked, bad = audit_proofs(prob, dataclasses.replace(final, groups=tuple(groups)))
            assert checked > 0 and bad == 0, (seed, lay)
    assert exits_moved > 0


def test_each_settled_answer_says_the_start_and_end_its_bound_is_for():
    # (``settle_chain(priced=...)``: the greedy pass hands each answer on with the costs its
    # bound was proven with; a bound taken for another end once made a group "optimal" 0.33 %
    # above the optimum) -- the answer's cost is its path's cost there, its bound at most the
    # DP's optimum there
    changed = 0
    for seed in range(12):
        prob = strokes_problem(seed, 12)
        built = []
        sol = layers.solve(prob, "greedy", built_groups=built)
        for g, (grp, _, priced_on, gs) in enumerate(built):
            assert gs is sol.groups[g]
            if not prob.group_reorderable[g] or prob.group_fixed[g]:
                continue
            assert priced_on.path_cost(gs.order) == pytest.approx(gs.objective, abs=1e-6), g
            assert gs.bound <= dp.solve(priced_on).objective + OPTIMAL_ABS_TOL, g
            changed += priced_on is not grp
    assert changed >= 1      # some answers here are settled for another start or end
