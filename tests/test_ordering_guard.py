"""The time guard (``rewrite.guard``): which re-ordered layers keep the slicer's order, decided on
the planner's time of the emitted file split at extrusions, the layer change belonging to both
layers around it (formulations/ordering.md, "Time guard")."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import gatesopt
from gatesopt.ordering import OrderingOptions, build, solve
from gatesopt.rewrite import guard
from conftest import PROJECT_INSTANCES


def _in_slicer_order(prob, solution, layer) -> bool:
    """Layer ``layer``'s curves are in the slicer's order and direction in ``solution``."""
    at = prob.curve_layer[solution.curve_order] == layer
    return (np.array_equal(solution.curve_order[at], np.flatnonzero(prob.curve_layer == layer))
            and not solution.curve_reversed[solution.curve_order[at]].any())


def _layer_xy(p, layer):
    """The extruding moves of one layer, in print order."""
    m = (p.layer == layer) & p.extruding
    return np.round(np.concatenate([p.start_mm[m, :2], p.end_mm[m, :2]], axis=1), 4)


def _stand_in(monkeypatch, prog, prob, times):
    """A stand-in emit and parse: per layer L one extruding step (the layer's own time,
    ``inner[L]``) and one travel (the layer change after it, ``after[L]``, counted by the
    parse in layer L + 1 as a layer marker before the travel would put it), from
    ``times(solution) -> (inner, after)``. Returns the slicer's file as the stand-in reads it."""
    L = prog.n_layers

    def fake_emit(program, problem, solution, memo=None):
        inner, after = times(solution)
        return np.ravel(np.column_stack([inner, after])).tobytes()

    def fake_parse(text, source=None):
        d = np.frombuffer(text, float)
        layer = np.minimum(np.arange(2 * L) // 2 + np.arange(2 * L) % 2, L - 1)
        return SimpleNamespace(n_layers=L, layer=layer, duration_s=d, source="stand-in",
                               extruding=np.arange(2 * L) % 2 == 0)
    monkeypatch.setattr(guard, "emit", fake_emit)
    monkeypatch.setattr(guard, "parse", fake_parse)
    monkeypatch.setattr(guard, "step_times_s", lambda program: program.duration_s)
    # the slicer's file: 1 s per layer and per layer change
    return fake_parse(np.ones(2 * L).tobytes())


@pytest.fixture
def star():
    prog = gatesopt.parse(str(PROJECT_INSTANCES / "star_lines_m82.gcode"))
    prob = build(prog, OrderingOptions(mode="free"))
    sol = solve(prob, "greedy")
    moved = [L for L in range(1, prog.n_layers - 1) if not _in_slicer_order(prob, sol, L)]
    assert len(moved) >= 4
    return prog, prob, sol, moved


def test_a_layer_whose_layer_change_pays_for_it_stays_re_ordered(monkeypatch, star):
    # prusa25_star_rect15_m82 (safe): a curve printed from its other end made its layer 44 ms
    # slower and the travel into the next layer 71 ms shorter; that travel is counted in the next
    # layer, so the guard that compared layer by layer put 46 such layers back (the whole gain)
    prog, prob, sol, moved = star
    a = moved[0]
    def times(s):
        inner, after = np.ones(prog.n_layers), np.ones(prog.n_layers)
        if not _in_slicer_order(prob, s, a):
            inner[a] += 0.044
            after[a] -= 0.071
        return inner, after
    orig = _stand_in(monkeypatch, prog, prob, times)
    # as the file is read (a layer's time: the steps after its marker), layer a is slower
    assert guard.layer_times_s(guard.parse(guard.emit(prog, prob, sol)))[a] > 1.04
    final, _, out, kept = guard.emit_guarded(orig, prob, sol)
    assert a not in kept and not _in_slicer_order(prob, final, a)
    assert out.duration_s.sum() == pytest.approx(orig.duration_s.sum() - 0.027)


@pytest.mark.parametrize("g_a, g_b, want", [(0.1, 0.1, (0, 1)), (0.7, 0.5, (1, 1)),
                                            (1.0, -0.2, (1, 0)), (0.1, -0.2, (0, 0))])
def test_two_neighbours_sharing_a_layer_change_take_the_best_of_the_four_states(monkeypatch, star,
                                                                                g_a, g_b, want):
    # Layers a and b = a + 1 both re-ordered: each gains inside itself (g_a, g_b), and the layer
    # change between them takes 0.6 s longer when a is re-ordered and b is not, 0.55 s when both
    # are (a rebuilt travel that retracts where the slicer's went straight on). The guard
    # measures the four combinations (the re-ordered file, the slicer's, every other layer put
    # back) and returns the fastest, ``want`` (1: re-ordered)
    prog, prob, sol, moved = star
    a = next(L for L in moved if L + 1 in moved)
    b = a + 1

    def times(s):
        inner, after = np.ones(prog.n_layers), np.ones(prog.n_layers)
        ra, rb = not _in_slicer_order(prob, s, a), not _in_slicer_order(prob, s, b)
        inner[a] -= g_a * ra
        inner[b] -= g_b * rb
        after[a] += 0.6 * (ra and not rb) + 0.55 * (ra and rb)
        return inner, after
    orig = _stand_in(monkeypatch, prog, prob, times)
    final, _, out, kept = guard.emit_guarded(orig, prob, sol)
    total = {(ra, rb): -g_a * ra - g_b * rb + 0.6 * (ra and not rb) + 0.55 * (ra and rb)
             for ra in (0, 1) for rb in (0, 1)}
    assert min(total, key=total.get) == want
    assert (int(a not in kept), int(b not in kept)) == want
    assert out.duration_s.sum() == pytest.approx(orig.duration_s.sum() + total[want])
    assert (not _in_slicer_order(prob, final, a)) == bool(want[0])
    assert (not _in_slicer_order(prob, final, b)) == bool(want[1])


def test_the_guard_never_returns_a_print_slower_than_the_slicers(monkeypatch, star):
    # every state measured is slower (each re-ordered layer 0.1 s, whatever its neighbours):
    # the slicer's order throughout
    prog, prob, sol, moved = star
    def times(s):
        inner, after = np.ones(prog.n_layers), np.ones(prog.n_layers)
        for L in moved:
            inner[L] += 0.1 * (not _in_slicer_order(prob, s, L))
        return inner, after
    orig = _stand_in(monkeypatch, prog, prob, times)
    final, _, out, kept = guard.emit_guarded(orig, prob, sol)
    assert set(moved) <= set(kept.tolist())
    assert all(_in_slicer_order(prob, final, L) for L in moved)
    assert out.duration_s.sum() == pytest.approx(orig.duration_s.sum())


def test_a_layer_slower_re_ordered_keeps_the_slicers_order_the_others_stay(monkeypatch):
    # the real emit and parse: the guarded print is never slower than the slicer's nor than the
    # unguarded one; a layer made to look 1 s slower re-ordered goes back alone
    from gatesopt.rewrite import order as pipeline
    prog = gatesopt.parse(str(PROJECT_INSTANCES / "star_lines_m82.gcode"))
    free = OrderingOptions(mode="free")
    unguarded = pipeline.order_program(prog, free, time_guard=False)
    guarded = pipeline.order_program(prog, free)
    t0 = guard.step_times_s(prog).sum()
    t_guarded = guard.step_times_s(guarded.output).sum()
    assert t_guarded <= t0 + guard.GUARD_TOL_S
    assert t_guarded <= guard.step_times_s(unguarded.output).sum() + guard.GUARD_TOL_S
    still = [L for L in range(1, prog.n_layers)
             if not np.array_equal(_layer_xy(guarded.output, L), _layer_xy(prog, L))]
    assert len(still) >= 2
    slow = still[0]
    real = guard.step_times_s

    def times(p):
        t = real(p).copy()
        if p is not prog and not np.array_equal(_layer_xy(p, slow), _layer_xy(prog, slow)):
            t[np.flatnonzero((p.layer == slow) & p.extruding)[0]] += 1.0
        return t
    monkeypatch.setattr(guard, "step_times_s", times)
    res = pipeline.order_program(prog, free)
    assert res.ok and res.summary["layers_kept_slower"] == guarded.summary["layers_kept_slower"] + 1
    assert np.array_equal(_layer_xy(res.output, slow), _layer_xy(prog, slow))
    for L in still[1:]:
        assert np.array_equal(_layer_xy(res.output, L), _layer_xy(guarded.output, L))
    assert [r for r in res.summary["per_layer"] if r["layer"] == slow][0]["status"] == "kept"
