"""Deadlines passed down, not fresh limits (issue 37: the 10 s default solve): each phase gets what
is left of the budget, a phase that finds nothing left answers at once with what it has, and says
so by its status. Proven by construction with fake clocks and stand-ins, never by timing a run."""
from __future__ import annotations

import time
import types

import highspy
import numpy as np
import pytest

from gatesopt._native import run_highs, run_lp
from gatesopt.ordering import auto, budget, formulations, layers, milp, runner, symmetric, symmetric_graph
from gatesopt.ordering.polylines import from_polylines
from gatesopt.ordering.problem import GroupSolution, OrderingOptions
from gatesopt.ordering.runner import OUT_OF_TIME, GroupRunner
from gatesopt.solvers import Formulation, Status

from test_ordering import random_problem
from conftest import never_solve, random_line_layers, slicer_order


class FakeClock:
    """``time.perf_counter`` of one module, moved on by the test (or by ``step`` per reading)."""

    def __init__(self, now: float = 1000.0, step: float = 0.0):
        self.now, self.step = now, step

    def perf_counter(self) -> float:
        self.now += self.step
        return self.now

    def module(self):
        return types.SimpleNamespace(perf_counter=self.perf_counter)


def test_a_group_after_the_budget_is_not_searched(monkeypatch):
    """A runner whose budget has ended answers with the slicer's order at once, status fallback
    (nothing proven: bound 0), and counts it; the solver is never called."""
    # numba compiling in the last 10 s (a fresh worker's first kernels) is not charged to the
    # budget (runner._jit.compile_s_since): none here, so the budget has surely ended
    monkeypatch.setattr(runner._jit, "compile_s_since", lambda t: 0.0)
    prob = from_polylines(random_line_layers([30], seed=1), options=OrderingOptions(mode="free"))
    grp = prob.group(0, prob.origin_xy)
    r = GroupRunner(prob, never_solve, 2.0, 0.5, time.perf_counter() - 10.0, {})
    gs = r.run(0, grp)
    assert gs.status == Status.FALLBACK and gs.formulation == OUT_OF_TIME
    assert np.array_equal(gs.order, slicer_order(grp))
    assert gs.bound == 0.0 and gs.objective == pytest.approx(grp.path_cost(slicer_order(grp)))
    assert r.out_of_time == 1


def test_limits_come_out_of_what_is_left_and_stop_at_the_budget(monkeypatch):
    """On a fake clock where each solve uses its whole limit and 10 ms more (the greedy path runs
    whatever the limit), the limits given add up to at most the budget, and once the expected
    overrun no longer fits no group is given to the solver: the rest keep the slicer's order
    (fallback), and the solve ends at most one group's overrun after the budget. Without this
    the groups after the budget ran the greedy path at limit 0, seconds past it on a large file."""
    clock = FakeClock()
    monkeypatch.setattr(runner, "time", clock.module())
    # (compiling spans are real-clock readings: none on the fake one)
    monkeypatch.setattr(runner._jit, "compile_s_since", lambda t: 0.0)
    prob = from_polylines(random_line_layers([40] * 12, seed=2), options=OrderingOptions(mode="free"))
    given = []

    def uses_its_limit(grp, *, time_limit_s, **kw):
        given.append(time_limit_s)
        clock.now += time_limit_s + 0.01
        order = slicer_order(grp)
        return GroupSolution.make(order, grp.path_cost(order), 0.0, Status.FALLBACK, time_limit_s, "stand-in")

    budget_s, t0 = 0.2, clock.now
    r = GroupRunner(prob, uses_its_limit, 2.0, budget_s, t0, {})
    answers = []
    for g in range(prob.n_groups):
        answers.append(r.run(g, prob.group(g, prob.origin_xy)))
        r.passed(g)
    assert sum(given) <= budget_s + 1e-12
    assert clock.now <= t0 + budget_s + 0.01 + 1e-12
    assert r.out_of_time >= 1 and len(given) + r.out_of_time == prob.n_groups, given
    late = [a for a in answers if a.formulation == OUT_OF_TIME]
    assert late and all(a.status == Status.FALLBACK for a in late)


def test_the_time_between_groups_is_measured_and_reserved(monkeypatch):
    """What the caller spends between groups (building them: the time objective's link costs) is
    measured per curve and reserved for the groups still to come, from the prior on."""
    clock = FakeClock()
    monkeypatch.setattr(runner, "time", clock.module())
    monkeypatch.setattr(runner._jit, "compile_s_since", lambda t: 0.0)
    prob = from_polylines(random_line_layers([20, 20, 20], seed=3), options=OrderingOptions(mode="free"))
    r = GroupRunner(prob, never_solve, 2.0, 100.0, clock.now, {})
    prior = r.rest_s(0)
    assert r.pass_rate() == pytest.approx(budget.OVERHEAD_S_PER_CURVE)
    clock.now += 1.0                    # the caller took 1 s to pass group 0 (20 curves)
    r.passed(0)
    rate = (budget.OVERHEAD_S_PER_CURVE * budget.OVERRUN_PRIOR_CURVES + 1.0) / (budget.OVERRUN_PRIOR_CURVES + 20)
    assert r.pass_rate() == pytest.approx(rate)
    assert r.rest_s(0) > prior
    scale = rate / budget.OVERHEAD_S_PER_CURVE
    assert r.rest_s(0) == pytest.approx(rate * 40 + scale * budget.TAIL_S_PER_CURVE * 60)


def test_layers_solve_with_no_budget_left_calls_no_solver(monkeypatch):
    """A whole solve given no time: every re-orderable group keeps the slicer's order, marked out
    of time, and the solution is the slicer's print order."""
    import sys
    this = sys.modules[__name__]
    monkeypatch.setattr(this, "solve", never_solve, raising=False)
    monkeypatch.setitem(formulations.FORMULATIONS, "auto",
                        Formulation("auto", __name__, capabilities=frozenset({"look_ahead"})))
    prob = from_polylines(random_line_layers([25, 30, 18], seed=4), options=OrderingOptions(mode="free"))
    sol = layers.solve(prob, "auto", time_limit_s=2.0, budget_s=0.0)
    assert all(gs.formulation.startswith(OUT_OF_TIME) for gs in sol.groups)
    assert all(gs.status == Status.FALLBACK for gs in sol.groups)
    assert np.array_equal(sol.curve_order, np.arange(prob.n_curves))
    assert not sol.curve_reversed.any()


def test_auto_runs_no_exact_step_once_its_limit_is_spent(monkeypatch):
    """auto's exact step gets what is left of the group's limit; where the heuristics used it up
    it is not started (it once got 50 ms whatever was left) and the group is a fallback."""
    auto.warm_up()
    called = []
    monkeypatch.setattr(milp, "solve", lambda *a, **k: called.append(k) or never_solve(None, time_limit_s=0))
    reached = 0
    for seed in range(12):
        grp = random_problem(900 + seed, 40, closed_share=0.0).group(0, np.zeros(2))
        if not symmetric_graph.applies(grp):
            continue
        clock = FakeClock(step=0.0)
        monkeypatch.setattr(auto, "time", clock.module())
        # each clock reading one second later: greedy, matching and ILS take "1 s" each
        clock.step = 1.0
        gs = auto.solve(grp, time_limit_s=0.5)
        monkeypatch.setattr(auto, "time", time)
        if gs.status != Status.OPTIMAL:
            reached += 1
            assert gs.status == Status.FALLBACK, gs
    assert reached >= 1 and not called


def _symmetric_group():
    for seed in range(40):
        grp = random_problem(3100 + seed, 40, closed_share=0.0, clustered=True).group(0, np.zeros(2))
        if symmetric_graph.applies(grp):
            return grp
    raise AssertionError("no group for the symmetric model")


def test_symmetric_model_gives_every_highs_run_the_same_deadline(monkeypatch):
    """The root's and the branch-and-cut's LPs all run to the one deadline of the group (each run
    gets the time left to it, ``run_lp``), never a fresh time limit per round."""
    symmetric.load_kernels()
    seen = []

    def recording(h, deadline=None):
        seen.append(deadline)
        return run_lp(h, deadline)

    monkeypatch.setattr(symmetric, "run_lp", recording)
    grp = _symmetric_group()
    deadline = time.perf_counter() + 30.0
    start = np.asarray(auto.greedy.solve(grp).order)
    symmetric.solve(grp, start, deadline)
    assert seen and all(d == deadline for d in seen)


def test_symmetric_model_with_its_deadline_passed_runs_no_lp(monkeypatch):
    """Given a deadline already passed, the model starts no LP and claims no proof beyond its
    seed bound: the incumbent comes back."""
    symmetric.load_kernels()
    ran = []

    def recording(h, deadline=None):
        r = run_lp(h, deadline)
        ran.append(bool(r))
        return r

    monkeypatch.setattr(symmetric, "run_lp", recording)
    grp = _symmetric_group()
    start = np.asarray(auto.greedy.solve(grp).order)
    order, obj, bound, proven = symmetric.solve(grp, start, time.perf_counter() - 1.0)
    assert not any(ran)
    assert np.array_equal(order, start) and obj == pytest.approx(grp.path_cost(start))
    assert bound <= obj


class _FakeHighs:
    """What ``run_highs`` asks of a Highs instance, recording the time limit it is given."""

    def __init__(self, run_time_s: float):
        self.run_time_s, self.options, self.runs = run_time_s, {}, 0
        self.cbSimplexInterrupt = self.cbMipInterrupt = types.SimpleNamespace(
            subscribe=lambda f: None, unsubscribe=lambda f: None)

    def getRunTime(self):
        return self.run_time_s

    def setOptionValue(self, name, value):
        self.options[name] = value

    def run(self):
        self.runs += 1
        return highspy.HighsStatus.kOk


def test_run_highs_gives_highs_the_time_left_to_the_deadline():
    """HiGHS counts its time limit against all the runs of an instance: run_highs sets it to the
    run time so far plus the time left to the deadline (not a fresh limit), and does not run at
    all once the deadline has passed."""
    h = _FakeHighs(run_time_s=100.0)
    before = time.perf_counter()
    assert run_highs(h, before + 2.0)
    assert h.runs == 1 and 100.0 < h.options["time_limit"] <= 102.0
    h2 = _FakeHighs(run_time_s=5.0)
    assert not run_highs(h2, time.perf_counter() - 0.1)
    assert h2.runs == 0 and "time_limit" not in h2.options


def test_run_lp_gives_highs_the_time_left_and_runs_nothing_after_a_stop_request():
    """``run_lp`` (the ordering's small LPs, no interrupt callbacks) sets the time limit as
    ``run_highs`` does, runs nothing past the deadline, and, a stop requested (Ctrl-C inside a
    ``stop_scope``), runs nothing and says it was stopped: the cutting-plane loop then ends with
    what it has."""
    from gatesopt.solvers import Stopped, request_stop, stop_scope
    h = _FakeHighs(run_time_s=100.0)
    assert run_lp(h, time.perf_counter() + 2.0)
    assert h.runs == 1 and 100.0 < h.options["time_limit"] <= 102.0
    assert not run_lp(h, time.perf_counter() - 0.1) and h.runs == 1
    with stop_scope():
        request_stop()
        r = run_lp(h, time.perf_counter() + 2.0)
    assert not r and r.stopped == Stopped.INTERRUPTED and h.runs == 1
    assert run_lp(h, None) and h.runs == 2      # (the scope's end clears the request)


def test_a_budget_below_the_ordering_floor_skips_the_ordering(monkeypatch):
    """A budget that leaves the ordering some time, but less than its build, group pass and emit
    take with no search at all (``stage_floor_s``), keeps the slicer's order without building
    anything, and says why: running it would end the run late by the difference."""
    import gatesopt
    from gatesopt.gating import GatingOptions
    from gatesopt.rewrite import order as rorder, pipeline

    from conftest import PROJECT_INSTANCES
    program = gatesopt.parse(PROJECT_INSTANCES / "star_lines_m82.gcode")
    floor = rorder.stage_floor_s(program)
    assert floor > 0 and rorder.stage_floor_s(program, 3.0) > floor     # slower machine, more
    monkeypatch.setattr(pipeline, "ordering_budget_s", lambda *a, **k: 0.9 * floor)
    monkeypatch.setattr(pipeline, "_order_curves", lambda *a, **k: never_solve(None, time_limit_s=0))
    res = pipeline.run(program, GatingOptions(rotate="none"), budget_s=10.0)
    assert res.report.ok and not res.ordered and "ordering_s" not in res.times
    assert any("curve ordering skipped" in n and f"{floor:.1f} s its build" in n for n in res.notes)


def test_a_solve_budget_below_the_group_pass_skips_the_solve_after_the_build(monkeypatch):
    """Once the problem is built its size is known: where the solve's budget would not pay for
    passing its groups (every group out of time, the run late by the pass and the emit), the
    ordering stops there and keeps the slicer's order, said so; ``gatesopt order`` (no ``slow``)
    still solves."""
    import gatesopt
    from gatesopt.gating import GatingOptions
    from gatesopt.rewrite import order as rorder, pipeline

    from conftest import PROJECT_INSTANCES
    program = gatesopt.parse(PROJECT_INSTANCES / "star_lines_m82.gcode")
    monkeypatch.setattr(pipeline, "stage_floor_s", lambda program, slow=1.0: 0.0)
    monkeypatch.setattr(rorder, "OVERHEAD_S_PER_CURVE", 1e3)       # passing a group: "1000 s"
    monkeypatch.setattr(rorder, "solve", lambda *a, **k: never_solve(None, time_limit_s=0))
    # (the greedy pass before the exact solve: neither is called)
    monkeypatch.setattr(rorder, "solve_greedy", lambda *a, **k: never_solve(None, time_limit_s=0))
    res = pipeline.run(program, GatingOptions(rotate="none"), budget_s=10.0)
    assert res.report.ok and not res.ordered
    assert any("curve ordering skipped after its build" in n for n in res.notes), res.notes
    with pytest.raises(AssertionError, match="after the budget ended"):     # no slow: it solves
        rorder.reorder(program, budget_s=10.0)


def _gating_problem():
    import gatesopt
    from gatesopt import gating
    from gatesopt.gating import GatingOptions

    from conftest import PROJECT_INSTANCES
    program = gatesopt.parse(PROJECT_INSTANCES / "star_lines_m82.gcode")
    return gating.build(program, GatingOptions.for_firmware("marlin", rotate="none", max_added_time_pct=2.0))


def test_cpsat_model_build_stops_on_ctrl_c(monkeypatch):
    """CP-SAT's model is built in Python (~2 s on a 217k-line file, which a Ctrl-C used to wait
    for): a stop request that arrives during the build ends it, and the warm start comes back
    marked interrupted, never "optimal" by a search that did not run."""
    from gatesopt.gating import cpsat
    from gatesopt.solvers import Stopped, request_stop, stop_scope
    problem = _gating_problem()
    real = cpsat._add_share_cuts
    monkeypatch.setattr(cpsat, "_add_share_cuts", lambda *a: (request_stop(), real(*a)))
    with stop_scope():
        sol = cpsat.solve(problem, time_limit_s=60.0)
    assert sol.stopped == Stopped.INTERRUPTED or sol.status == Status.OPTIMAL
    assert "not searched" in sol.message


def test_cpsat_past_its_deadline_after_the_build_does_not_search(monkeypatch):
    """The time limit is for the whole call: where the warm start and the build used it up,
    CP-SAT is not started (it once got a fresh 10 ms), and the answer says time limit."""
    from gatesopt.gating import cpsat
    from gatesopt.solvers import Stopped
    problem = _gating_problem()
    clock = FakeClock()
    monkeypatch.setattr(cpsat, "time", clock.module())
    real = cpsat._add_share_cuts

    def slow_cuts(*a):                  # the build "takes" 100 s
        clock.now += 100.0
        return real(*a)
    monkeypatch.setattr(cpsat, "_add_share_cuts", slow_cuts)
    monkeypatch.setattr(cpsat, "run_native", lambda *a, **k: never_solve(None, time_limit_s=0))
    sol = cpsat.solve(problem, time_limit_s=5.0)
    assert "not searched" in sol.message
    assert sol.status == Status.OPTIMAL or sol.stopped == Stopped.TIME_LIMIT


def test_a_helper_out_of_time_leaves_its_groups_to_the_main_process():
    """A helper process whose budget has ended answers no group: walked backwards, greedy's
    answer loses the proof greedy made for its own start, so each group is left to the main
    process, which keeps greedy's answer (proven by greedy's subset DP here). Before, a helper out
    of time claimed every group from the back in milliseconds while the main process was busy:
    864 of prusa25_bunny_triangles15_lh01's groups in one run."""
    prob = from_polylines(random_line_layers([9] * 20, seed=6), options=OrderingOptions(mode="free"))
    greedy = layers.solve_greedy(prob, workers=1)
    assert all(a is not None for a in greedy.answers)
    assert all(gs.status == Status.OPTIMAL for gs in greedy.solution.groups)
    slept = []

    def busy(done, n, proven):
        # the main process busy for 4 s after its first group (the helper boots in ~1.5 s)
        if not slept:
            slept.append(True)
            time.sleep(4.0)
    sol = layers.solve(prob, "auto", budget_s=0.05, workers=2, greedy=greedy, progress=busy)
    assert slept and not any("+back" in gs.formulation for gs in sol.groups)
    assert all(gs.status == Status.OPTIMAL for gs in sol.groups)

