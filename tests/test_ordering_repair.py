"""The time guard's repair pass (``rewrite.order.repair_pass``, ``ordering.repair``;
formulations/ordering.md, "Time guard", "Repair"): a layer the guard puts back although a group
in it was proven optimal is solved again on link costs that agree with the planner, measured
again, and kept re-ordered where it then prints no slower; each group's status is its status on
those costs; the repair never makes a layer slower than the file printed without it."""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

import gatesopt
from gatesopt.ordering import OrderingOptions, build, solve
from gatesopt.ordering.emitter import emit
from gatesopt.ordering.chain import KEPT, anchor_before, end_of, entry_positions
from gatesopt.ordering.formulations import group_solver
from gatesopt.ordering.problem import GroupSolution
from gatesopt.ordering.repair import REPAIRED, can_repair, planner_priced, resolve_layers
from gatesopt.rewrite import guard
from gatesopt.rewrite import order as order_mod
from gatesopt.rewrite.order import repair_pass
from gatesopt.solvers import Status
from gatesopt.verify.proofs import audit_proofs

from test_ordering_cost_planner import _corpus


def _proven_in(prob, sol, layers) -> int:
    """Re-orderable groups ``sol`` proves optimal in ``layers``."""
    layers = set(np.asarray(layers).tolist())
    return sum(1 for g, gs in enumerate(sol.groups)
               if prob.group_reorderable[g] and gs.status == Status.OPTIMAL
               and int(prob.group_layer[g]) in layers)


@pytest.fixture
def cubic(plan_as):
    # classic jerk (Marlin): the default links are not joined to the curves' moves, and the
    # auto answer of layer 13 (its group proven optimal on those costs) prints slower. The file
    # is Cura's for a Klipper printer (PRINT_START: planned by Klipper's rules by default); no
    # Marlin file of the corpus shows such a layer (11 classic-jerk files searched): Marlin's
    # rules are passed explicitly
    plan_as("marlin")
    prog = _corpus("real_cura410_cubic")
    prob = build(prog, OrderingOptions(mode="safe"))
    return prog, prob, solve(prob, "auto")


def test_planner_priced_joins_classic_jerk_links_only_where_they_were_not(cubic):
    prog, prob, _ = cubic
    assert can_repair(prob) and not prob.program_problem.pricer.joined
    joined = planner_priced(prog, prob)
    assert joined is not None and joined.program_problem.pricer.joined
    assert joined.options.joined_links == "all" and joined.n_groups == prob.n_groups
    # already joined: nothing to repair with
    assert planner_priced(prog, joined) is None and not can_repair(joined)


def test_a_put_back_layer_reports_the_path_it_prints_not_the_proof_it_reverted(cubic):
    prog, prob, sol = cubic
    old = guard.emit_guarded(prog, prob, sol)
    # without the repair pass a layer with a proven group is put back ...
    assert _proven_in(prob, sol, old.kept) >= 1
    first = entry_positions(prob, old.solution)
    demoted = 0
    for g, gs in enumerate(old.solution.groups):
        if not prob.group_reorderable[g] or int(prob.group_layer[g]) not in set(old.kept.tolist()):
            continue
        # ... and each of its groups reports the slicer's path it prints, priced where printed
        grp = prob.group(g, anchor_before(prob, old.solution, int(first[g])), end_of(prob, g))
        path = guard.printed_path(prob, old.solution, g, grp, first)
        assert path is not None and np.array_equal(gs.order, path)
        assert abs(gs.objective - grp.path_cost(path)) <= 1e-9 * max(1.0, gs.objective)
        if sol.groups[g].status == Status.OPTIMAL and not np.array_equal(sol.groups[g].order, path):
            # the model's proof the planner disagreed with: not reported as proven
            assert gs.status == Status.FEASIBLE and gs.formulation.endswith(KEPT)
            assert gs.bound <= gs.objective
            demoted += 1
    assert demoted >= 1 and _proven_in(prob, old.solution, old.kept) == 0
    # every proof reported is the subset DP's optimum where printed
    assert audit_proofs(prob, old.solution)[1] == 0


def test_the_repair_pass_runs_past_the_budgets_end(cubic):
    prog, prob, sol = cubic
    old = guard.emit_guarded(prog, prob, sol)
    late = repair_pass(prog, prob, "auto", deadline_s=time.perf_counter() - 100.0)
    new = guard.emit_guarded(prog, prob, sol, repair=late)
    assert len(old.kept) and set(old.kept.tolist()) <= set(new.repaired.tolist())
    assert not set(old.kept.tolist()) & set(new.kept.tolist())


def test_greedys_answer_taken_for_want_of_time_gets_the_repair_pass_too(monkeypatch):
    prog = _corpus("real_cura410_cubic")
    seen = []
    real = order_mod.emit_guarded

    def spy(*args, **kwargs):
        seen.append(kwargs.get("repair"))
        return real(*args, **kwargs)
    # no time left after greedy: its answer is printed (``guard.GREEDY_TAKEN``), repaired alike
    monkeypatch.setattr(order_mod, "solve_budget_s", lambda *a, **k: 1e-9)
    monkeypatch.setattr(order_mod, "emit_guarded", spy)
    _, _, got = order_mod.reorder(prog, OrderingOptions(mode="safe"), budget_s=10.0)
    assert len(seen) == 1 and callable(seen[0])
    assert np.all(got.source != guard.FROM_SOLVER)       # (greedy's answer, not an exact one)


def test_a_reverted_proven_layer_is_solved_again_and_kept_reordered(cubic):
    prog, prob, sol = cubic
    old = guard.emit_guarded(prog, prob, sol)
    assert _proven_in(prob, sol, old.kept) >= 1
    new = guard.emit_guarded(prog, prob, sol, repair=repair_pass(prog, prob, "auto"))
    assert set(old.kept.tolist()) <= set(new.repaired.tolist())
    assert _proven_in(prob, new.solution, new.kept) == 0
    # re-solved on the joined costs: the layer prints re-ordered, its groups say so honestly
    lay = int(new.repaired[0])
    assert new.source[lay] == guard.FROM_SOLVER
    assert guard.changed_layers(prob, new.solution)[lay]
    groups = [gs for g, gs in enumerate(new.solution.groups)
              if prob.group_layer[g] == lay and prob.group_reorderable[g]]
    assert groups and all(gs.formulation.endswith(REPAIRED) for gs in groups)
    assert all(gs.status == Status.OPTIMAL for gs in groups)
    # and the file is faster than without the repair, that layer no slower than the slicer's
    t_old = guard.step_times_s(old.output).sum()
    t_new = guard.step_times_s(new.output).sum()
    assert t_new < t_old - guard.GUARD_TOL_S
    slicer = guard.layer_times_s(prog)
    assert guard.layer_times_s(new.output)[lay] <= slicer[lay] + guard.GUARD_TOL_S


def test_a_repair_that_prints_slower_is_not_taken_and_its_status_is_reported(cubic):
    prog, prob, sol = cubic
    old = guard.emit_guarded(prog, prob, sol)
    joined = planner_priced(prog, prob)
    pp = prob.program_problem
    seen = {}

    def bad(printed, layers):
        # the joined answer with every open curve of those layers printed backwards, its
        # groups' answers unproven: a repair that prints slower
        out = resolve_layers(joined, printed, layers, group_solver("auto"))
        at = np.isin(pp.curve_layer, layers) & ~pp.curve_closed
        rev = np.where(at, ~out.curve_reversed, out.curve_reversed)
        groups = tuple(GroupSolution.make(gs.order, gs.objective, 0.0, Status.FEASIBLE, 0.0,
                                          "backwards") if prob.group_layer[g] in layers else gs
                       for g, gs in enumerate(out.groups))
        seen["cand"] = dataclasses.replace(out, curve_reversed=rev, groups=groups)
        return seen["cand"]
    new = guard.emit_guarded(prog, prob, sol, repair=bad)
    assert len(new.repaired) >= 1
    t_old = guard.layer_times_s(old.output)
    t_new = guard.layer_times_s(new.output)
    # never slower than the file the repair started from, layer by layer and in all
    assert np.all(t_new <= t_old + guard.GUARD_TOL_S)
    assert t_new.sum() <= t_old.sum() + guard.GUARD_TOL_S
    # the candidate itself prints slower in a repaired layer: that layer is put back
    states = np.isin(np.arange(prog.n_layers), new.repaired).astype(np.int64)
    text = emit(prog, prob, guard.mix_layers(prob, old.solution, seen["cand"], states,
                                             with_cost=False))
    t_cand = guard.layer_times_s(gatesopt.parse(text, source="cand"))
    slower = [lay for lay in new.repaired.tolist() if t_cand[lay] > t_old[lay] + guard.GUARD_TOL_S]
    assert slower
    assert all(new.source[lay] != guard.FROM_SOLVER for lay in slower)
    # the repaired layers' answers are the repair's (unproven): no proven group reverted
    for lay in new.repaired.tolist():
        gss = [gs for g, gs in enumerate(new.solution.groups)
               if prob.group_layer[g] == lay and prob.group_reorderable[g]]
        assert gss and all(gs.status == Status.FEASIBLE for gs in gss)
    assert _proven_in(prob, new.solution, new.kept) == 0


def test_resolve_layers_keeps_every_other_layer_and_the_layers_contiguous(cubic):
    prog, prob, sol = cubic
    printed = guard.mix_layers(prob, None, sol, np.zeros(prog.n_layers, np.int64), with_cost=False)
    joined = planner_priced(prog, prob)
    out = resolve_layers(joined, printed, [13], group_solver("auto"))
    pp = prob.program_problem
    assert np.array_equal(pp.curve_layer[out.curve_order], pp.curve_layer)
    other = pp.curve_layer[out.curve_order] != 13
    assert np.array_equal(out.curve_order[other], printed.curve_order[other])
    assert sorted(out.curve_order.tolist()) == list(range(pp.n_curves))
    # a deadline already past: the layer keeps what was printed, its groups' answers too
    late = resolve_layers(joined, printed, [13], group_solver("auto"), deadline_s=0.0)
    assert np.array_equal(late.curve_order, printed.curve_order)
    assert all(a is b for a, b in zip(late.groups, printed.groups))


def test_the_file_end_is_the_last_groups_end_and_its_layer_is_not_put_back():
    # KISSlicer ends with a lift back over the last curve's end at 5 mm/s (G1 X Y Z E0 F300),
    # copied verbatim after whichever curve is printed last: priced as the last group's end
    # (``problem.FILE_END``), the last layer is no longer ordered to end elsewhere and put back
    from gatesopt.ordering.chain import end_of
    from gatesopt.ordering.problem import FILE_END
    prog = _corpus("real_kisslicer163")
    for mode in ("safe", "free"):
        prob = build(prog, OrderingOptions(mode=mode))
        pricer = prob.program_problem.pricer
        assert pricer.file_end is not None and pricer.file_end.feed_mm_s == 5.0
        end = end_of(prob, prob.n_groups - 1)
        assert end is not None and end.curve == FILE_END
        # one move at 5 mm/s: 1 mm further costs ~200 ms
        far = pricer.file_end.ms(pricer.file_end.xy + np.array([[0.0, 0.0], [10.0, 0.0]]))
        assert 1900.0 < far[1] - far[0] < 2100.0
        sol = solve(prob, "auto")
        g = guard.emit_guarded(prog, prob, sol)
        last = int(prob.group_layer[-1])
        assert last not in g.kept.tolist()
        assert _proven_in(prob, g.solution, g.kept) == 0


def _end_of(tail: str):
    from gatesopt.limits import machine_limits
    from gatesopt.ordering.file_end import FileEnd
    from gatesopt.ordering.layout import layout
    from gatesopt.ordering.move_times import MoveTimes
    text = ("G90\nM82\nG92 E0\nG1 Z0.2 F600\nG1 X5 Y5 F3000\nG1 X10 Y5 E1 F1200\nG1 X10 Y10 E2\n"
            "G1 X20 Y10 F3000\nG1 X20 Y20 E3 F1200\n" + tail)
    prog = gatesopt.parse(text, source="end.gcode")
    return FileEnd.of(prog, layout(prog), MoveTimes.from_limits(machine_limits(prog)))


def test_the_file_end_move_is_the_first_xy_word_after_the_last_curve():
    # Cura: retract, then park at the retraction's feed (no F on the park line)
    end = _end_of("G1 E2.2 F2100\nM107\nG1 X0 Y210 ; park\nM84\n")
    assert end is not None and np.allclose(end.xy, [0.0, 210.0]) and end.feed_mm_s == 35.0
    # KISSlicer: back over the last point while lifting, at 5 mm/s (its own Z change kept)
    end = _end_of("G1 E2.2 F1875\nG1 X20 Y20 Z5.2 E2.2 F300\n")
    assert end is not None and np.allclose(end.xy, [20.0, 20.0]) and abs(end.dz_mm - 5.0) < 1e-9
    ms = end.ms(np.array([[20.0, 20.0], [20.0, 30.0]]))
    assert ms[1] - ms[0] > 800.0                  # 10 mm further: hypot(10, 5) vs 5 at 5 mm/s
    # a home or a relative move first: the head's position does not carry over
    assert _end_of("G1 E2.2 F2100\nG28 X\nG1 X0 Y210\n") is None
    assert _end_of("G1 E2.2 F2100\nG91\nG1 X5 Y5\nG90\n") is None
    # no XY move after the last curve (a Klipper END_PRINT macro): no end
    assert _end_of("G1 E2.2 F2100\nG1 Z10 F600\nM84\n") is None
