"""The slicer's wipes on rebuilt travels (formulations/ordering.md, "Wipes"): a rebuilt travel
that retracts wipes first, as the slicer does -- its own wipe, verbatim, out of a curve printed
as it printed it, else its usual wipe back over the last extrusion -- and the solver prices what
is written. Before, a re-ordered Bambu Studio cube lost 252 of its 255 wipes, and the report's
print time counted the dropped wipe moves as a saving."""
from __future__ import annotations

import re

import numpy as np
import pytest

import gatesopt
from gatesopt.ordering import OrderingOptions, build, emit, solve
from gatesopt.ordering.cost import gap_times_ms
from gatesopt.ordering.layout import layout
from gatesopt.ordering.travel_stats import travel_stats
from gatesopt.ordering.wipes import SlicerWipes

from conftest import SHARED_INSTANCES, needs_shared

HEAD = "G90\nM83\nG28\n"


def _island(x0: float, y0: float, z: float, arc: bool = False) -> str:
    """A 6 mm square printed counter-clockwise from (x0, y0), then the slicer's wipe back along
    its last side while retracting 0.6 of 0.8 mm (``arc``: a quarter circle of 1 mm radius
    into the square, as Bambu Studio wipes), the rest in place, a lifted travel."""
    wipe = (f"G2 X{x0 + 1:g} Y{y0 + 2:g} I1 J0 E-0.6" if arc else f"G1 X{x0:g} Y{y0 + 3:g} E-0.6")
    return (f"G1 X{x0:g} Y{y0:g} F9000\nG1 Z{z:g} F600\nG1 E0.8 F2100\n;TYPE:Perimeter\n"
            f"G1 X{x0 + 6:g} Y{y0:g} E0.3 F1800\nG1 X{x0 + 6:g} Y{y0 + 6:g} E0.3\n"
            f"G1 X{x0:g} Y{y0 + 6:g} E0.3\nG1 X{x0:g} Y{y0 + 1:g} E0.25\n"
            f";WIPE_START\nG1 F7200\n{wipe}\n;WIPE_END\n"
            f"G1 E-0.2 F2100\nG1 Z{z + 0.4:g} F600\n")


def _plate(order, arc: bool = False) -> str:
    """Islands on a line, two layers: the first in line (a first layer keeps its order) and one
    more island 8 mm on (the shortest travel the slicer retracted for: 14.3 mm), the second
    printed by the slicer in ``order`` (a zigzag the ordering undoes)."""
    spots = [(10.0 + 20.0 * k, 10.0) for k in range(len(order))]
    first = "".join(_island(*spots[k], 0.2, arc) for k in range(len(order)))
    first += _island(spots[-1][0] + 14.0, 10.0, 0.2, arc)
    second = "".join(_island(*spots[k], 0.4, arc) for k in order)
    return (HEAD + ";LAYER_CHANGE\n;Z:0.2\n" + first + ";LAYER_CHANGE\n;Z:0.4\n" + second
            + "G1 X0 Y0 F9000\nM84\n")


def _unwiped_retractions(program) -> int:
    """Retractions (runs of -E, more than float noise) with no XY move among them."""
    d = program.delta_mm
    neg = (program.layer >= 0) & (d[:, 3] < -1e-4)
    count, run, wiped = 0, False, False
    for k in range(len(neg)):
        if neg[k]:
            wiped = wiped or bool(np.hypot(d[k, 0], d[k, 1]) > 0)
            run = True
        elif run and (abs(d[k, 0]) + abs(d[k, 1]) + abs(d[k, 2]) > 0 or d[k, 3] > 0):
            count += not wiped
            run, wiped = False, False
    return count + (run and not wiped)


@pytest.mark.parametrize("arc", [False, True])
def test_the_slicers_own_wipe_is_written_again_on_a_rebuilt_travel(arc):
    src = _plate([0, 3, 1, 4, 2, 5], arc)
    prog = gatesopt.parse(src)
    # (copied gaps priced move by move, as ``gap_times_ms`` measures: tests/test_ordering_cost.py)
    prob = build(prog, OrderingOptions(mode="free", copied_gaps="moves"))
    sol = solve(prob, "auto", time_limit_s=5.0)
    out = gatesopt.parse(emit(prog, prob, sol))
    before, after = travel_stats(prog), travel_stats(out)
    assert after["travel_mm"] < before["travel_mm"]                  # re-ordered
    assert before["wipes"] == before["retractions"] == 13
    assert after["wipes"] == after["retractions"] and _unwiped_retractions(out) == 0
    # the wipe's moves are the slicer's (from a square's last corner back 2 mm, -0.6 mm of
    # filament, then -0.2 in place), written by a rebuilt travel (``Writer.move_xy_e``'s
    # numbers: the slicer wrote "E-0.6")
    text = emit(prog, prob, sol)
    if arc:
        # the quarter circle as 3 chords (sagitta <= 0.04 mm at 1 mm radius), 0.2 mm each
        assert re.search(r"(G1 X[\d.]+ Y[\d.]+ E-\.2\b.*\n){3}G1 E-\.2 ", text)
    else:
        assert re.search(r"G1 X\d+ Y13 E-\.6\b.*\nG1 E-\.2 ", text)
    # what the solver priced is what was written (the wipe's moves included)
    measured = gap_times_ms(out, prob.pricer.move)
    assert sol.cost_after == pytest.approx(measured.sum(), rel=1e-6, abs=1e-3)
    assert sol.cost_after <= sol.cost_before + 1e-6


def test_without_wipes_the_rebuilt_travels_retract_in_place():
    # the mutation: the same solve with no wipe to write drops them -- the check above sees it
    src = _plate([0, 3, 1, 4, 2, 5])
    prog = gatesopt.parse(src)
    prob = build(prog, OrderingOptions(mode="free"))
    prob.pricer.wipes = SlicerWipes.none(prob.n_curves)
    prob.pricer._ends = prob.pricer.ends_args()
    sol = solve(prob, "auto", time_limit_s=5.0)
    out = gatesopt.parse(emit(prog, prob, sol))
    assert _unwiped_retractions(out) > 0


def test_a_curve_printed_backwards_wipes_back_over_its_first_move():
    prog = gatesopt.parse(_plate([0, 1, 2]))
    lay = layout(prog)
    closed = np.zeros(len(lay.curve_s0), bool)
    w = SlicerWipes.of(prog, lay, closed)
    # side 0: the slicer's own (one move, 2 mm up, -0.6); side 1: 2 mm along its first side
    # (+X from its start), the slicer's 0.3 mm of filament per mm
    assert w.n_moves[0, 0] == 1
    np.testing.assert_allclose(w.moves[0, 0, 0], [0.0, 2.0, -0.6, 120.0], atol=1e-12)
    assert w.n_moves[0, 1] == 1
    np.testing.assert_allclose(w.moves[0, 1, 0], [2.0, 0.0, -0.6, 120.0], atol=1e-12)
    np.testing.assert_allclose(w.shift_xy[0, 1], [2.0, 0.0], atol=1e-12)
    # a loop gets none backwards
    assert SlicerWipes.of(prog, lay, ~closed).n_moves[:, 1].sum() == 0
    # a file that does not wipe gets none anywhere
    plain = gatesopt.parse(re.sub(r"G1 X\d+ Y13 E-0.6", "G1 E-0.6", _plate([0, 1, 2])))
    assert SlicerWipes.of(plain, layout(plain), closed).n_moves.sum() == 0


@needs_shared
@pytest.mark.parametrize("name,mode", [("real_prusa274_screw_arcs.gcode.gz", "free"),
                                       ("real_crealityprint514.gcode.gz", "safe")])
def test_rebuilt_travels_wipe_on_real_files(name, mode):
    prog = gatesopt.parse(SHARED_INSTANCES / name)
    prob = build(prog, OrderingOptions(mode=mode))
    sol = solve(prob, "greedy", time_limit_s=1.0)
    out = gatesopt.parse(emit(prog, prob, sol))
    assert sol.cost_after < sol.cost_before                         # something was rebuilt
    # no more retractions without a wipe than the slicer made
    assert _unwiped_retractions(out) <= _unwiped_retractions(prog)
    # (fewer retractions in free mode, where travels got short: each of those left wipes)
    before, after = travel_stats(prog), travel_stats(out)
    assert after["retractions"] - after["wipes"] <= before["retractions"] - before["wipes"]


def test_float_noise_of_e_is_no_retraction():
    # a rebuilt dry travel keeps its gaps' net E exactly, the slicer's rounding included
    # (``G1 E-.00001``): not a retraction the report counts (a free-mode PrusaSlicer output
    # showed 245 retractions more than it made)
    text = ("G90\nM83\n;LAYER_CHANGE\n;Z:0.2\nG1 Z0.2 F600\nG1 X0 Y0 F6000\nG1 X10 Y0 E0.5 F1200\n"
            "G1 X12 Y0 F9000\nG1 E-.00001 F2100\nG1 X20 Y0 E0.5 F1200\nG1 E-0.8 F2100\n"
            "G1 X40 Y0 F9000\nG1 E0.8\nG1 X50 Y0 E0.5\n")
    stats = travel_stats(gatesopt.parse(text))
    assert stats["retractions"] == 1 and stats["travels"] == 2


@pytest.mark.parametrize("r_mm, sweep_deg, ccw", [(5.0, 90.0, True), (5.0, 270.0, False),
                                                  (0.5, 360.0, True), (0.02, 360.0, False)])
def test_arc_chords_stay_on_the_arc_and_close_it(r_mm, sweep_deg, ccw):
    # one rule (``arc_span``) for the slicer's own arc wipes (``arc_chords``) and the usual wipe
    # along an arc (``_walk``): chords within ARC_SAGITTA_MM of the arc, a tiny circle as four
    # quarter turns, never a chord of no length (a full circle once came out as one move of 0 mm)
    from gatesopt.ordering.wipes import ARC_SAGITTA_MM, arc_chords, arc_span
    sweep = np.radians(sweep_deg) * (1 if ccw else -1)
    start = np.array([10.0 + r_mm, 20.0])
    end = np.array([10.0 + r_mm * np.cos(sweep), 20.0 + r_mm * np.sin(sweep)])
    chords = arc_chords(start, (10.0, 20.0), ccw, end - start)
    r, span, per = arc_span(r_mm, 0.0, end[0] - 10.0, end[1] - 20.0, ccw)
    assert r == pytest.approx(r_mm) and span == pytest.approx(np.radians(sweep_deg))
    assert len(chords) == max(1, int(np.ceil(span / per - 1e-12)))
    p = start.copy()
    for dx, dy, share in chords:
        q = p + (dx, dy)
        mid = (p + q) / 2 - (10.0, 20.0)
        assert np.hypot(dx, dy) > 1e-6                                   # a move, not a point
        assert r_mm - np.hypot(*mid) <= max(ARC_SAGITTA_MM, r_mm) + 1e-9  # on the arc
        if r_mm > ARC_SAGITTA_MM:
            assert r_mm - np.hypot(*mid) <= ARC_SAGITTA_MM + 1e-9
        assert share == pytest.approx(1 / len(chords))
        p = q
    assert np.allclose(p, end, atol=1e-9)
    if r_mm < ARC_SAGITTA_MM:
        assert len(chords) == 4
