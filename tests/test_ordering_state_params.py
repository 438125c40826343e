"""State lines that set some of a command's parameters (issue 36): a curve moved by the
re-ordering prints under the limits it had in the slicer's order, parameter by parameter.

Creality Print / Orca write ``SET_VELOCITY_LIMIT ... SQUARE_CORNER_VELOCITY=7`` (or ``=12``)
before most features and ``SET_VELOCITY_LIMIT ACCEL=2500 ACCEL_TO_DECEL=1250`` before bridges,
which keeps the corner velocity of the feature before. With one state key per command the
emitter saw the bridge's own line in force and re-issued nothing, so a bridge moved after a
feature at 7 mm/s printed at 7 instead of 12: real_crealityprint514 free, layer 17, an 899-move
bridge 2.95 s slower than the cost model priced it (the model plans each curve under the limits
in force at its lines in the slicer's file), and the time guard put the proven order back."""
from __future__ import annotations

import numpy as np

import gatesopt
from gatesopt.limits import K, machine_limits
from gatesopt.ordering import OrderingOptions, build
from gatesopt.ordering.emitter import emit
from gatesopt.ordering.problem import OrderingSolution

from conftest import SHARED_INSTANCES, needs_shared

WALL_12 = "SET_VELOCITY_LIMIT ACCEL=5000 ACCEL_TO_DECEL=2500 SQUARE_CORNER_VELOCITY=12"
WALL_7 = "SET_VELOCITY_LIMIT ACCEL=5000 ACCEL_TO_DECEL=2500 SQUARE_CORNER_VELOCITY=7"
BRIDGE = "SET_VELOCITY_LIMIT ACCEL=2500 ACCEL_TO_DECEL=1250"


def _zigzag(x0: float, y0: float, e: float, rows: int = 4) -> tuple[list[str], float]:
    out = []
    for k in range(rows):
        y = y0 + 0.5 * k
        x = x0 + 15 if k % 2 == 0 else x0
        if k:
            e += 0.03
            out.append(f"G1 X{x0 + 15 if k % 2 else x0:.3f} Y{y:.3f} E{e:.5f}")
        e += 0.8
        out.append(f"G1 X{x:.3f} Y{y:.3f} E{e:.5f}")
    return out, e


def _klipper_gcode() -> str:
    """Layer 0 states both SET_VELOCITY_LIMIT forms (the first line of each is a barrier), layer 1
    prints a wall at corner velocity 12, a bridge that keeps it (its line names no corner
    velocity), then a wall at 7."""
    out = ["; FLAVOR: Klipper", "G21", "G90", "M82", "G92 E0", ";LAYER_CHANGE", ";Z:0.2",
           "G1 X10 Y10 Z0.2 F12000", WALL_12, BRIDGE, "G1 F3000"]
    e = 0.0
    lines, e = _zigzag(10, 10, e)
    out += lines
    out += [";LAYER_CHANGE", ";Z:0.4", "G1 Z0.4 F12000"]
    for setting, (x0, y0) in ((WALL_12, (10, 30)), (BRIDGE, (10, 60)), (WALL_7, (10, 90))):
        out += [f"G1 X{x0:.3f} Y{y0:.3f} F12000", setting, "G1 F4500"]
        lines, e = _zigzag(x0, y0, e)
        out += lines
    out += ["G1 X0 Y150 F12000", "M84"]
    return "\n".join(out) + "\n"


def _limits_by_move(p, layer: int) -> dict:
    """Per extruding move of ``layer`` (by its end points): its square corner velocity and
    acceleration under the planner's reading of the file (``limits.machine_limits``)."""
    rows = np.flatnonzero(p.extruding & (p.layer == layer))
    per = machine_limits(p).per_step(p)[rows]
    ends = [tuple(sorted((tuple(np.round(p.start_mm[r, :2], 3)), tuple(np.round(p.end_mm[r, :2], 3)))))
            for r in rows]
    return dict(zip(ends, zip(per[:, K["square_corner_velocity"]].tolist(),
                              per[:, K["accel_print"]].tolist())))


def test_moved_bridge_keeps_the_corner_velocity_it_was_sliced_with():
    prog = gatesopt.parse(_klipper_gcode())
    prob = build(prog, OrderingOptions(mode="free"))
    layer1 = np.flatnonzero(prob.curve_layer == 1)
    assert len(layer1) == 3
    # the bridge (layer 1's second curve) printed last, after the wall at corner velocity 7
    order = np.arange(prob.n_curves)
    order[layer1] = layer1[[0, 2, 1]]
    n = prob.n_curves
    sol = OrderingSolution(order, np.zeros(n, bool), np.zeros(n, np.int64), (), 0.0, 0.0, 0.0,
                           "test")
    text = emit(prog, prob, sol)
    out = gatesopt.parse(text)
    want = _limits_by_move(prog, 1)
    assert sorted(set(want.values())) == [(7.0, 5000.0), (12.0, 2500.0), (12.0, 5000.0)]
    assert _limits_by_move(out, 1) == want
    # the order did change: the bridge's own line now follows the wall at 7
    body = text.splitlines()
    assert body.index(WALL_7) < max(i for i, t in enumerate(body) if t == BRIDGE)


def test_emit_in_the_slicers_order_adds_no_state_line():
    """The slicer's own order is copied as it was: no line re-issued."""
    prog = gatesopt.parse(_klipper_gcode())
    prob = build(prog, OrderingOptions(mode="free"))
    n = prob.n_curves
    sol = OrderingSolution(np.arange(n), np.zeros(n, bool), np.zeros(n, np.int64), (), 0.0, 0.0,
                           0.0, "test")
    assert emit(prog, prob, sol) == prog.to_gcode()


@needs_shared
def test_crealityprint_layer_17_reordered_under_the_sliced_limits():
    """real_crealityprint514 free: every extruding move of the re-ordered file runs under the
    square corner velocity and acceleration it had in the slicer's file."""
    from gatesopt.rewrite.order import order_program
    prog = gatesopt.parse(SHARED_INSTANCES / "real_crealityprint514.gcode.gz")
    res = order_program(prog, OrderingOptions(mode="free"), budget_s=10, workers=1,
                        time_guard=False)
    assert res.ok
    for layer in (17, 18):
        assert _limits_by_move(res.output, layer) == _limits_by_move(prog, layer)


def _features_gcode(order) -> str:
    """Layer 1's three features (wall at corner velocity 12, bridge, wall at 7) printed in
    ``order``, each after its own SET_VELOCITY_LIMIT line as it stands (relative E: a feature's
    moves extrude the same wherever they are printed); nothing re-issued."""
    out = ["; FLAVOR: Klipper", "G21", "G90", "M83", "G92 E0", ";LAYER_CHANGE", ";Z:0.2",
           "G1 X10 Y10 Z0.2 F12000", WALL_12, BRIDGE, "G1 F3000", "G1 X25 Y10 E0.8",
           ";LAYER_CHANGE", ";Z:0.4", "G1 Z0.4 F12000"]
    feats = ((WALL_12, 30), (BRIDGE, 60), (WALL_7, 90))
    for k in order:
        setting, y0 = feats[k]
        out += [f"G1 X10 Y{y0} F12000", setting, "G1 F4500"]
        out += [f"G1 X{10 + 15 * ((i + 1) % 2)} Y{y0 + 0.5 * i} E0.8" for i in range(4)]
    out += ["G1 X0 Y150 F12000", "M84"]
    return "\n".join(out) + "\n"


def test_the_verifier_finds_a_move_printed_under_other_limits():
    # the emitter's fault above, made by hand: the bridge moved after the wall at corner
    # velocity 7 with nothing re-issued prints at 7, not 12: ``verify.ordering.check_limits``
    # says so (the line, the limit, both values); the features in their own order, or re-ordered
    # by the emitter, pass
    from gatesopt.verify.ordering import check, check_limits
    prog = gatesopt.parse(_features_gcode((0, 1, 2)))
    naive = gatesopt.parse(_features_gcode((0, 2, 1)))
    found = check_limits(prog, naive)
    assert len(found) == 1 and found[0].check == "limits"
    assert "square_corner_velocity = 7, 12 in the original" in found[0].message
    assert any(f.check == "limits" for f in check(prog, naive))
    assert check_limits(prog, prog) == []
    prob = build(prog, OrderingOptions(mode="free"))
    layer1 = np.flatnonzero(prob.curve_layer == 1)
    order = np.arange(prob.n_curves)
    order[layer1] = layer1[[0, 2, 1]]
    n = prob.n_curves
    sol = OrderingSolution(order, np.zeros(n, bool), np.zeros(n, np.int64), (), 0.0, 0.0, 0.0,
                           "test")
    out = gatesopt.parse(emit(prog, prob, sol))
    assert check_limits(prog, out) == [] and check(prog, out) == []
