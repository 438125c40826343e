"""Re-emitted travels of a combing slicer: no retraction where the slicer would not have made
one (gatesopt/ordering/emit.py, WallCrossing)."""
from __future__ import annotations

import numpy as np
import pytest

import gatesopt
from gatesopt.ordering import OrderingOptions, build
from gatesopt.ordering.layout import layout
from gatesopt.ordering.travel import WallCrossing, travel_style
from gatesopt.rewrite.order import order_program

from conftest import SHARED_INSTANCES, needs_shared


def _square_part_gcode() -> str:
    """One layer: a closed 20 mm square wall, then four infill lines inside it."""
    out = ["G21", "G90", "M82", "G92 E0", ";LAYER:0", "G0 X10 Y10 Z0.2 F6000", ";TYPE:WALL-OUTER"]
    e = 0.0
    for x, y in [(30, 10), (30, 30), (10, 30), (10, 10)]:
        e += 0.6
        out.append(f"G1 X{x} Y{y} E{e:.4f} F1800")
    out.append(";TYPE:FILL")
    for k, y in enumerate([12, 16, 20, 24]):
        x0, x1 = (12, 28) if k % 2 == 0 else (28, 12)
        out.append(f"G0 X{x0} Y{y} F6000")
        e += 0.5
        out.append(f"G1 X{x1} Y{y} E{e:.4f} F1800")
    out.append("G0 X50 Y50")
    return "\n".join(out) + "\n"


def test_wall_crossing_sees_the_square_wall():
    prog = gatesopt.parse(_square_part_gcode().encode())
    prob = build(prog, OrderingOptions(mode="free"))
    walls = WallCrossing(prog, prob, layout(prog))
    assert walls.crosses(0, (20, 20), (40, 20))            # out through the wall
    assert not walls.crosses(0, (12, 12), (28, 24))         # over the infill
    assert not walls.crosses(0, (12, 12), (12.4, 12))       # too short to tell: ends touch walls
    assert walls.crosses(0, (5, 20), (35, 20))              # through both sides


@needs_shared
def test_non_combing_slicer_is_not_taken_for_one():
    prog = gatesopt.parse(SHARED_INSTANCES / "real_prusa261_benchy.gcode.gz")
    assert travel_style(prog, layout(prog)).comb_max_mm == 0.0


@needs_shared
@pytest.mark.parametrize("name", ["real_cura591.gcode.gz", "real_ideamaker514.gcode.gz"])
def test_reordered_combing_file_keeps_retractions_near_the_slicers(name):
    """Before combing was honoured, re-ordering these files multiplied their retractions by
    2.5-4 (real_cura591: 137 -> 560, ideaMaker 5.1.4: 450 -> 1140). Now: 137 -> 275 and
    450 -> 380; the rest on real_cura591 are straight travels that cross a wall, where the slicer
    would have combed around it (not reproduced: such travels retract)."""
    prog = gatesopt.parse(SHARED_INSTANCES / name)
    assert travel_style(prog, layout(prog)).comb_max_mm > 0
    res = order_program(prog, OrderingOptions(mode="safe"), formulation="greedy")
    assert res.ok
    s = res.summary
    assert s["travel_after_mm"] < s["travel_before_mm"]
    assert s["retractions_after"] <= 2.5 * s["retractions_before"]


# ------------------------------------------------------------------------------------------------
# firmware retraction (bare G10 / G11: PrusaSlicer/Slic3r "use firmware retraction", Klipper's
# [firmware_retraction], Cura's machine_firmware_retract)

def _firmware_retract_gcode(rrf_temperature_in_layer: bool = False) -> str:
    """Two layers of eight 10 mm lines in a scrambled order; the slicer retracts with G10 / G11
    around every travel. Optionally a RepRapFirmware ``G10 P0 S205`` (tool temperature) after the
    fourth line of layer 1: a heater command, not a retraction."""
    out = ["G21", "G90", "M83", "G28", "G10 P0 S200 ; set temperature"]
    ys = [0, 40, 10, 50, 20, 60, 30, 70]
    for layer in range(2):
        out += [f";LAYER:{layer}", f"G1 Z{0.2 + 0.2 * layer:.1f} F600"]
        for k, y in enumerate(ys):
            x0, x1 = (20, 30) if k % 2 == 0 else (30, 20)
            out += ["G10", f"G0 X{x0} Y{y + 20} F6000", "G11", f"G1 X{x1} Y{y + 20} E0.4 F1800"]
            if rrf_temperature_in_layer and layer == 1 and k == 3:
                out.append("G10 P0 S205")
    out += ["G10", "G0 X0 Y150 F6000", "M84"]
    return "\n".join(out) + "\n"


def _travels_and_retraction(text: str):
    """(XY length, retracted by G10?) of every travel between extrusions, and whether every
    extrusion starts unretracted (each G10 undone by a G11 before the next extrusion)."""
    x = y = 0.0
    retracted = False
    runs, run, run_retracted = [], None, False
    extrudes_unretracted = True
    for line in text.splitlines():
        words = line.split(";")[0].split()
        if words == ["G10"]:
            assert not retracted, "G10 while already retracted"
            retracted = True
        elif words == ["G11"]:
            assert retracted, "G11 without a G10"
            retracted = False
        elif words and words[0] in ("G0", "G1"):
            w = {t[0]: float(t[1:]) for t in words[1:]}
            nx, ny = w.get("X", x), w.get("Y", y)
            length = float(np.hypot(nx - x, ny - y))
            if "E" in w and length > 0:
                extrudes_unretracted &= not retracted
                if run is not None:
                    runs.append((run, run_retracted))
                run = None
            elif length > 0:
                if run is None:
                    run, run_retracted = 0.0, False
                run += length
                run_retracted |= retracted
            x, y = nx, ny
    return runs, extrudes_unretracted


def test_firmware_retraction_is_rebuilt_with_the_travel():
    """A file that retracts with G10 / G11 is re-ordered (they were barriers before), and every
    rebuilt travel the slicer would have retracted for is retracted by one G10 and one G11 (never
    two G10 in a row, every extrusion unretracted). The report counts G10 as a retraction; a
    RepRapFirmware ``G10 P0 S205`` is a heater command and stays a barrier."""
    from gatesopt.ordering.travel_stats import travel_stats
    prog = gatesopt.parse(_firmware_retract_gcode())
    assert travel_stats(prog)["retractions"] == 17        # 16 travels and the final one
    res = order_program(prog, OrderingOptions(mode="free"))
    assert res.ok and res.summary["groups_reordered"] == 1      # layer 0 keeps its order
    assert res.summary["travel_after_mm"] < 0.75 * res.summary["travel_before_mm"]
    runs_in, ok_in = _travels_and_retraction(prog.to_gcode())
    runs_out, ok_out = _travels_and_retraction(res.text)
    assert ok_in and ok_out
    shortest_retracted = min(d for d, r in runs_in if r)          # 30 mm here
    assert all(r for d, r in runs_out if d >= shortest_retracted)
    assert any(not r for d, r in runs_out)                         # the new 10 mm hops go dry
    # + the layer change's (no XY travel) and the last one's (no extrusion after it)
    assert res.summary["retractions_after"] == sum(r for _, r in runs_out) + 2 == 10
    # the heater line: layer 1 splits there into two groups of four lines each
    rrf = gatesopt.parse(_firmware_retract_gcode(rrf_temperature_in_layer=True))
    prob = build(rrf, OrderingOptions(mode="free"))
    assert sorted(np.diff(prob.group_curve_start).tolist()) == [4, 4, 8]
    assert travel_stats(rrf)["retractions"] == 17
    res = order_program(rrf, OrderingOptions(mode="free"))
    assert res.ok


def test_progress_and_messages_do_not_split_a_layer_and_are_kept():
    """M73 (progress: Bambu, Orca, PrusaSlicer, Creality Print) and M117 (Kiri:Moto writes one every
    1 % of the print, mid-curve) are not barriers: the layer stays one group, and every such line
    is in the output, also those inside a curve that is printed reversed."""
    out = ["G21", "G90", "M83", ";LAYER:0", "G1 Z0.2 F600", "G1 X10 Y0 E1 F1800", ";LAYER:1",
           "G1 Z0.4 F600"]
    ys = [0, 40, 10, 50, 20, 60, 30, 70]
    for k, y in enumerate(ys):
        out += [f"G0 X20 Y{y + 20} F6000", f"M73 P{10 + k} R{30 - k}",
                f"G1 X25 Y{y + 20} E0.2 F1800", f"M117 {k}% layer 1 / 2", f"G1 X30 Y{y + 20} E0.2"]
    out += ["G0 X0 Y150 F6000", "M84"]
    prog = gatesopt.parse("\n".join(out) + "\n")
    prob = build(prog, OrderingOptions(mode="free"))
    assert np.diff(prob.group_curve_start).max() == 8              # layer 1: one group of eight
    res = order_program(prog, OrderingOptions(mode="free"))
    assert res.ok and res.summary["travel_after_mm"] < 0.8 * res.summary["travel_before_mm"]
    assert any(t.startswith("G1 X20") and " E" in t for t in res.text.splitlines())   # reversed
    kept = [t for t in res.text.splitlines() if t.startswith(("M73", "M117"))]
    assert sorted(kept) == sorted(t for t in out if t.startswith(("M73", "M117")))


def _bridge_fan_gcode() -> str:
    """Layer 1: eight infill lines; the fan is at S100 for most and at S255 for two of them (a
    bridge, as PrusaSlicer and KISSlicer write it: M106 before the curve, M106 back after it).
    Layer 0 sets the fan first (the first M106 of the file, a barrier)."""
    out = ["G21", "G90", "M83", ";LAYER:0", "G1 Z0.2 F600", "M106 S100", "G1 X10 Y0 E1 F1800",
           ";LAYER:1", "G1 Z0.4 F600"]
    ys = [0, 40, 10, 50, 20, 60, 30, 70]
    for k, y in enumerate(ys):
        out.append(f"G0 X20 Y{y + 20} F6000")
        if k in (1, 5):
            out.append("M106 S255")
        out.append(f"G1 X30 Y{y + 20} E0.4 F1800")
        if k in (1, 5):
            out.append("M106 S100")
    out += ["G0 X0 Y150 F6000", "M107", "M84"]
    return "\n".join(out) + "\n"


def test_part_fan_is_state_reissued_where_a_curve_needs_it():
    """The part-cooling fan (M106 / M107, no P) is state, not a barrier: layer 1 stays one group,
    and the output re-issues M106 so that every extrusion sees the duty it saw in the slicer's
    order (the bridge lines at S255, the rest at S100)."""
    prog = gatesopt.parse(_bridge_fan_gcode())
    prob = build(prog, OrderingOptions(mode="free"))
    assert np.diff(prob.group_curve_start).max() == 8              # layer 1: one group of eight
    res = order_program(prog, OrderingOptions(mode="free"))
    assert res.ok and res.summary["travel_after_mm"] < 0.8 * res.summary["travel_before_mm"]
    out = gatesopt.parse(res.text)
    assert out.to_gcode() != prog.to_gcode()
    # every extruding move, found by its end points, has the fan duty it had

    def duty(p):
        rows = np.flatnonzero(p.extruding & (p.layer == 1))
        ends = [tuple(sorted((tuple(p.start_mm[r, :2]), tuple(p.end_mm[r, :2])))) for r in rows]
        return dict(zip(ends, np.round(p.fan[rows] * 255).astype(int).tolist()))
    assert duty(out) == duty(prog)
    assert sorted(set(duty(prog).values())) == [100, 255]
    # the order changed around the bridge lines: the fan lines are not where the slicer had them
    fan_lines = [t for t in res.text.splitlines() if t.startswith("M106")]
    assert fan_lines != [t for t in prog.to_gcode().splitlines() if t.startswith("M106")]


def test_verify_catches_a_missing_fan_reissue():
    """Drop one re-issued M106 from a re-ordered output: a curve now prints at the wrong fan duty,
    and the verifier says which line."""
    prog = gatesopt.parse(_bridge_fan_gcode())
    res = order_program(prog, OrderingOptions(mode="free"))
    lines = res.text.splitlines()
    fan_at = [i for i, t in enumerate(lines) if t == "M106 S255"]
    assert fan_at
    broken = "\n".join(lines[:fan_at[0]] + lines[fan_at[0] + 1:]) + "\n"
    from gatesopt.verify.ordering import check
    found = check(prog, gatesopt.parse(broken))
    fan = [f for f in found if "part fan" in f.message]
    # said once, by the move-by-move check (not again by the per-layer filament-by-duty one)
    assert fan and all(f.check == "fan" for f in fan)
    assert any("part fan at S100" in f.message and "S255 in the original" in f.message for f in fan)


def test_other_fans_stay_barriers():
    """``M106 P2`` (Bambu's auxiliary fan) is not the fan the parser models: it stays a barrier,
    its lines keep their order, and the layer splits there."""
    text = _bridge_fan_gcode().replace("M106 S255", "M106 P2 S255").replace("M106 S100\nG0", "M106 P2 S0\nG0")
    prog = gatesopt.parse(text)
    prob = build(prog, OrderingOptions(mode="free"))
    assert np.diff(prob.group_curve_start).max() < 8
    res = order_program(prog, OrderingOptions(mode="free"))
    assert res.ok
    aux = [t for t in res.text.splitlines() if t.startswith("M106 P2")]
    assert aux == [t for t in text.splitlines() if t.startswith("M106 P2")]


def test_first_value_of_a_state_is_a_barrier():
    """Before a file's first ``M204`` the acceleration is the firmware's, which the output cannot
    re-issue: a curve printed before that line must not move after it. The second M204 is state."""
    text = _bridge_fan_gcode().replace("M106 S255", "M204 S1000").replace("M106 S100\nG0", "M204 S500\nG0")
    prog = gatesopt.parse(text)
    lay = layout(prog)
    first, second = [i for i in range(prog.n_lines) if prog.line_text(i).startswith("M204")][:2]
    assert first in lay.state_key and second in lay.state_key
    prob = build(prog, OrderingOptions(mode="free"))
    starts = prob.group_curve_start.tolist()
    layer1 = [c for c in range(prob.n_curves) if prob.curve_layer[c] == 1]
    # layer 1 splits once, at the first M204 (before its 2nd curve): groups of 1 and 7 curves
    assert [b - a for a, b in zip(starts, starts[1:]) if a in layer1] == [1, 7]


def test_solve_output_keeps_the_fan_each_extrusion_saw():
    """Re-ordered and gated (``gatesopt solve``): the verifier's fan check holds for the output and
    catches a missing re-issue, once: per layer, filament by fan duty (``commands``) where gating
    split moves, move by move (``fan``) where the output has no gating line, as here."""
    from gatesopt.rewrite import run
    from gatesopt.verify import verify
    prog = gatesopt.parse(_bridge_fan_gcode())
    res = run(prog, order_options=OrderingOptions(mode="free"), formulation="milp")
    assert res.ordered and res.report.ok, res.report.findings
    assert res.summary()["travel_after_mm"] < res.summary()["travel_before_mm"]
    lines = res.text.splitlines()
    k = lines.index("M106 S255")
    broken = gatesopt.parse("\n".join(lines[:k] + lines[k + 1:]) + "\n")
    found = verify(prog, broken).findings
    fan = [f for f in found if (f.check == "commands" and "part fan at S100" in f.message)
           or (f.check == "fan" and "part fan at S100" in f.message)]
    assert fan, [str(f) for f in found]
    assert len({f.check for f in fan}) == 1, [str(f) for f in found]      # one check, not both


def test_the_part_fan_is_one_state_however_its_p_word_is_written():
    """``M106 S..``, ``M106 P0 S..``, ``M106 P0.0 S..`` and ``M107`` set the same fan: one state
    key, so emit re-issues one value (two keys would write both, the wrong one last)."""
    text = (_bridge_fan_gcode().replace("M106 S255", "M106 P0.0 S255", 1)
            .replace("M106 S100\nG0", "M106 P0 S100\nG0", 1))
    prog = gatesopt.parse(text)
    lay = layout(prog)
    fan = [i for i in range(prog.n_lines) if prog.line_text(i).startswith(("M106", "M107"))]
    assert len(fan) == 6 and {lay.state_key[i] for i in fan} == {("fan",)}
    res = order_program(prog, OrderingOptions(mode="free"))
    assert res.ok


def _progress_gcode() -> str:
    """Layer 1: eight infill lines in a scrambled order, an ``M73 P.. R..`` progress line before
    each (as Bambu, Orca, PrusaSlicer and Creality Print write them mid-layer, by print time)."""
    out = ["G21", "G90", "M83", ";LAYER:0", "G1 Z0.2 F600", "G1 X10 Y0 E1 F1800",
           ";LAYER:1", "G1 Z0.4 F600"]
    for k, y in enumerate([0, 40, 10, 50, 20, 60, 30, 70]):
        out += [f"M73 P{10 + 10 * k} R{80 - 10 * k}", f"G0 X20 Y{y + 20} F6000",
                f"G1 X30 Y{y + 20} E0.4 F1800"]
    out += ["M117 done", "G0 X0 Y150 F6000", "M84"]
    return "\n".join(out) + "\n"


def test_progress_lines_keep_their_order_when_curves_move():
    """M73 lines travel with the curve after them, but a re-ordered layer still writes them in
    the slicer's sequence: the printer's progress never steps back (it did before the fix: the
    output had P40 after P60 here)."""
    prog = gatesopt.parse(_progress_gcode())
    res = order_program(prog, OrderingOptions(mode="free"))
    assert res.ok and res.summary["travel_after_mm"] < 0.8 * res.summary["travel_before_mm"]

    def progress(text):
        return [t for t in text.splitlines() if t.startswith(("M73", "M117"))]
    assert progress(res.text) == progress(prog.to_gcode())
    # the curves did move (the lines are printed bottom to top now), so the M73 lines went with them

    def lines_y(text):
        return [t.split()[2] for t in text.splitlines() if t.startswith(("G1 X30", "G1 X20"))]
    assert lines_y(res.text) != lines_y(prog.to_gcode())


def test_verify_catches_progress_stepping_back():
    """Swap two M73 lines of a re-ordered output: the verifier reports the first out of order."""
    prog = gatesopt.parse(_progress_gcode())
    res = order_program(prog, OrderingOptions(mode="free"))
    lines = res.text.splitlines()
    at = [i for i, t in enumerate(lines) if t.startswith("M73")]
    lines[at[2]], lines[at[3]] = lines[at[3]], lines[at[2]]
    from gatesopt.verify.ordering import check
    found = check(prog, gatesopt.parse("\n".join(lines) + "\n"))
    assert [f.line for f in found if f.check == "commands"][:1] == [at[2] + 1]
    assert any("M73 P40" in f.message and "M73 P30" in f.message for f in found)
