"""A rebuilt travel keeps the slicer's clearance lift.

A one-at-a-time print (Cura's ``print_sequence = one_at_a_time``) leaves each object by lifting
over it -- ``G0 F9000 X65.8 Y123.284 Z10`` after the last layer at Z5 -- before it travels to the
next object's first layer at Z0.2. Re-ordered so that another curve ends the object's last
layer, the rebuilt travel into the next object consumed that lift and flew at Z5, across the top
of the object just printed (found on a CuraEngine slice of four towers, Ender-3 definition); the
verifier said nothing. The rebuilt travel now flies no lower than the slicer's (``gaps.
rebuilt_gap``), and the verifier reports a layer change that no longer climbs to the slicer's
clearance (``verify.ordering``)."""
from __future__ import annotations

import numpy as np

import gatesopt
from gatesopt.ordering import OrderingOptions, build
from gatesopt.ordering.emitter import emit
from gatesopt.ordering.problem import OrderingSolution
from gatesopt.verify.ordering import check


def _lines(x0: float, y: float, e: float) -> tuple[list[str], float]:
    out = []
    for k in range(3):
        e += 0.5
        out += [f"G0 F6000 X{x0:.3f} Y{y + 3 * k:.3f}", f"G1 F1500 X{x0 + 10:.3f} Y{y + 3 * k:.3f} E{e:.4f}"]
    return out, e


def _one_at_a_time() -> str:
    """Two objects of three layers each, printed one after the other, Cura-like: the first
    object's last layer ends, the head lifts to Z10 over it, travels, and the second object
    starts at Z0.2."""
    out = [";FLAVOR:Marlin", "G21", "G90", "M82", "G92 E0"]
    e, layer = 0.0, 0
    for obj, x0 in enumerate((20.0, 120.0)):
        if obj:
            out += ["G1 F1500 E{:.4f}".format(e - 5.0), "G0 F9000 X35 Y25 Z10", "G0 X110 Y20"]
            e -= 5.0
        for k in range(3):
            z = 0.2 * (k + 1)
            out += [f";LAYER:{layer}", f"G0 F6000 X{x0:.3f} Y20 Z{z:.1f}"]
            if obj and not k:
                e += 5.0
                out.append(f"G1 F1500 E{e:.4f}")
            body, e = _lines(x0, 20.0, e)
            out += body
            layer += 1
    out += ["M107", "M84"]
    return "\n".join(out) + "\n"


def _reversed_last_layer_of_first_object(prog):
    prob = build(prog, OrderingOptions(mode="free"))
    last = np.flatnonzero(prob.curve_layer == 2)
    assert len(last) == 3
    order = np.arange(prob.n_curves)
    order[last] = last[::-1]                # another curve ends the object's last layer
    n = prob.n_curves
    return prob, OrderingSolution(order, np.zeros(n, bool), np.zeros(n, np.int64), (), 0.0, 0.0,
                                  0.0, "test")


def _top_z_between(out, a: int, b: int) -> float:
    """The highest Z of the steps after layer a's last extrusion up to layer b's first."""
    ext = out.extruding & (out.layer >= 0)
    last_a = np.flatnonzero(ext & (out.layer == a))[-1]
    first_b = np.flatnonzero(ext & (out.layer == b))[0]
    return float(out.end_mm[last_a:first_b + 1, 2].max())


def test_the_travel_to_the_next_object_climbs_to_the_slicers_lift():
    prog = gatesopt.parse(_one_at_a_time())
    assert _top_z_between(prog, 2, 3) == 10.0
    prob, sol = _reversed_last_layer_of_first_object(prog)
    out = gatesopt.parse(emit(prog, prob, sol))
    assert _top_z_between(out, 2, 3) >= 10.0 - 1e-9
    assert not [f for f in check(prog, out, prob.layout) if "clearance" in f.message]


def test_the_verifier_reports_a_layer_change_that_lost_its_lift():
    # the same output with the lift cut down to the object's height: "clearance" names the layer
    # change; the original against itself has no finding, and a z-hop (0.4 mm) is not a lift
    prog = gatesopt.parse(_one_at_a_time())
    assert not [f for f in check(prog, prog) if f.check == "clearance"]
    low = gatesopt.parse(_one_at_a_time().replace("G0 F9000 X35 Y25 Z10", "G0 F9000 X35 Y25 Z0.6"))
    hits = [f for f in check(prog, low) if f.check == "clearance"]
    assert len(hits) == 1 and "layer 2 -> 3" in hits[0].message and "Z10" in hits[0].message
    assert hits[0].line is not None
    hop = gatesopt.parse(_one_at_a_time().replace("G0 F9000 X35 Y25 Z10", "G0 F9000 X35 Y25 Z1"))
    assert not [f for f in check(hop, prog) if f.check == "clearance"]
