"""Planner time model (gatesopt.planner) and machine limits (gatesopt.limits).

Programs for the math tests are built by hand (``make_program``) so each test controls every
length, feed and limit; the closed forms are written next to each assertion.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from gatesopt import planner
from gatesopt.limits import machine_limits
from gatesopt.program import Kind, Program

INSTANCES = Path(__file__).resolve().parents[2] / "shared" / "instances"


# ------------------------------------------------------------------------------------------------
# a Program from points, by hand
def make_program(start, steps, header=(), footer=()) -> Program:
    """``steps``: ("move", (x, y, z, e), feed_mm_s), ("dwell", seconds) or ("motor", "M18 X").
    G-code text is written
    too (``header`` lines first, then one line per step, then ``footer``) so that limits can be
    read from it."""
    lines = [*header]
    pos = np.asarray(start, dtype=float)
    rows = []
    for st in steps:
        if st[0] == "move":
            end = np.asarray(st[1], dtype=float)
            feed = float(st[2])
            lines.append("G1 X%r Y%r Z%r E%r F%r" % (*end.tolist(), feed * 60))
            d = end - pos
            lxyz = float(np.linalg.norm(d[:3]))
            if lxyz > 0:
                kind = Kind.EXTRUDE if d[3] > 0 else (Kind.RETRACT if d[3] < 0 else
                                                     (Kind.Z_ONLY if d[0] == d[1] == 0 else Kind.TRAVEL))
                length = lxyz
            else:
                kind = Kind.RETRACT if d[3] < 0 else Kind.UNRETRACT
                length = abs(d[3])
            rows.append(dict(line=len(lines) - 1, kind=kind, start=pos.copy(), end=end, feed=feed,
                             length=length, dur=length / feed))
            pos = end
        elif st[0] == "motor":
            lines.append(st[1])
            rows.append(dict(line=len(lines) - 1, kind=Kind.MOTOR, start=pos.copy(), end=pos.copy(),
                             feed=rows[-1]["feed"] if rows else 25.0, length=0.0, dur=0.0))
        elif st[0] == "dwell":
            lines.append(f"G4 S{st[1]}")
            rows.append(dict(line=len(lines) - 1, kind=Kind.DWELL, start=pos.copy(), end=pos.copy(),
                             feed=rows[-1]["feed"] if rows else 25.0, length=0.0, dur=float(st[1])))
        else:
            raise ValueError(st[0])
    lines += list(footer)
    text = "".join(line + "\n" for line in lines)
    data = text.encode()
    starts = np.zeros(len(lines) + 1, dtype=np.int64)
    starts[1:] = np.cumsum([len(line) + 1 for line in lines])
    n = len(rows)
    col = lambda key, dtype=float: np.array([r[key] for r in rows], dtype=dtype)  # noqa: E731
    values = dict(
        source="<test>", data=data, line_start=starts,
        line=col("line", np.int64), kind=col("kind", np.int8),
        start_mm=np.array([r["start"] for r in rows]).reshape(n, 4),
        end_mm=np.array([r["end"] for r in rows]).reshape(n, 4),
        feed_mm_s=col("feed"), length_mm=col("length"), duration_s=col("dur"),
        layer=np.zeros(n, np.int32), feature=np.full(n, -1, np.int16), fan=np.zeros(n, np.float32),
        hotend_c=np.zeros(n, np.float32), bed_c=np.zeros(n, np.float32),
        arc_center_mm=np.full((n, 2), np.nan), arc_ccw=np.zeros(n, bool),
        offset_mm=np.zeros((n, 4)), relative_xyz=np.zeros(n, bool), relative_e=np.zeros(n, bool),
        inch=np.zeros(n, bool), enabled=np.ones((n, 4), bool),
    )
    # per-line command columns if the Program has them (the parser fills them; here: the text)
    letters = np.array([ord(t[0]) if t[:1].isalpha() and t[:1].isupper() else 0 for t in lines], np.uint8)
    numbers = np.array([float(t[1:].split()[0]) if t[:1] in "GM" and t[1:].split() else np.nan
                        for t in lines], np.float32)
    letters[[i for i, t in enumerate(lines) if t.startswith("SET_")]] = 64
    for f in dataclasses.fields(Program):
        if f.name in values:
            continue
        if f.name == "line_letter":
            values[f.name] = letters
        elif f.name == "line_number":
            values[f.name] = numbers
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            values[f.name] = np.zeros(len(lines))
    return Program(**values)


KLIPPER = ("SET_VELOCITY_LIMIT VELOCITY=500 ACCEL=1000 SQUARE_CORNER_VELOCITY=5",)


def marlin_jerk(accel=1000.0, jerk=10.0):
    """Marlin header lines with classic jerk (PrusaSlicer-style config block for the rule)."""
    return (f"M201 X{accel * 10:g} Y{accel * 10:g} Z1000 E10000", "M203 X500 Y500 Z50 E100",
            f"M204 P{accel:g} R{accel:g} T{accel:g}", f"M205 X{jerk:g} Y{jerk:g} Z1 E5"), \
        ("; machine_max_jerk_x = %g" % jerk, "; gcode_flavor = marlin2")


def jerk_program(steps, start=(0, 0, 0, 0), accel=1000.0, jerk=10.0):
    header, footer = marlin_jerk(accel, jerk)
    return make_program(start, steps, header, footer)


# ------------------------------------------------------------------------------------------------
# hand-computed trapezoids
def test_single_move_accelerate_cruise_decelerate_klipper():
    # Klipper: starts and ends at rest. L = 100, v = 50, a = 1000:
    # d_acc = d_dec = v^2 / 2a = 1.25 mm, t = 2 v/a + (L - 2.5) / v = 0.1 + 1.95 = 2.05 s
    p = make_program((0, 0, 0, 0), [("move", (100, 0, 0, 0), 50)], KLIPPER)
    pl = planner.plan(p)
    assert pl.limits.firmware == "klipper" and pl.limits.junction == "scv"
    assert pl.duration_s[0] == pytest.approx(2.05, rel=1e-12)
    assert pl.accel_s[0] == pytest.approx(0.05) and pl.decel_s[0] == pytest.approx(0.05)
    assert pl.cruise_s[0] == pytest.approx(1.95)
    assert pl.entry_mm_s[0] == 0 and pl.exit_mm_s[0] == 0 and pl.cruise_mm_s[0] == pytest.approx(50)


def test_single_move_classic_jerk_starts_at_safe_speed():
    # classic jerk: starts from rest at the jerk speed j = 10 and stops from it:
    # t = 2 (v - j)/a + (L - 2 (v^2 - j^2)/2a) / v = 0.08 + (100 - 2.4)/50 = 2.032 s
    p = jerk_program([("move", (100, 0, 0, 0), 50)])
    pl = planner.plan(p)
    assert pl.limits.junction == "jerk"
    assert pl.entry_mm_s[0] == pytest.approx(10) and pl.exit_mm_s[0] == pytest.approx(10)
    assert pl.duration_s[0] == pytest.approx(0.08 + 97.6 / 50, rel=1e-12)


def test_triangle_profile():
    # too short to reach F = 100: peak^2 = a L (from and to rest), t = 2 sqrt(a L) / a
    p = make_program((0, 0, 0, 0), [("move", (1, 0, 0, 0), 100)], KLIPPER)
    pl = planner.plan(p)
    peak = math.sqrt(1000 * 1.0)
    assert pl.cruise_mm_s[0] == pytest.approx(peak)
    assert pl.cruise_s[0] == 0
    assert pl.duration_s[0] == pytest.approx(2 * peak / 1000, rel=1e-12)


def test_junction_limited_klipper_square_corner():
    # a 90 degree corner on Klipper is taken at exactly square_corner_velocity (5 mm/s):
    # JD = scv^2 (sqrt2 - 1)/a and v^2 = a JD sin(45)/(1 - sin(45)) = scv^2
    p = make_program((0, 0, 0, 0), [("move", (50, 0, 0, 0), 50), ("move", (50, 50, 0, 0), 50)], KLIPPER)
    pl = planner.plan(p)
    assert pl.exit_mm_s[0] == pytest.approx(5.0) and pl.entry_mm_s[1] == pytest.approx(5.0)
    t1 = 50 / 1000 + 45 / 1000 + (50 - 1.25 - (2500 - 25) / 2000) / 50
    assert pl.duration_s[0] == pytest.approx(t1, rel=1e-12)
    assert pl.duration_s[1] == pytest.approx(t1, rel=1e-12)    # mirror image


def test_junction_limited_classic_jerk_corner():
    # Marlin classic jerk, X move then Y move at 50 mm/s, jerk 10: X stops from 50 (a reversal
    # of 50 > 10: factor 0.2), Y then starts at 10 <= 10: the junction speed is 10 mm/s
    p = jerk_program([("move", (50, 0, 0, 0), 50), ("move", (50, 50, 0, 0), 50)])
    pl = planner.plan(p)
    assert pl.exit_mm_s[0] == pytest.approx(10.0) and pl.entry_mm_s[1] == pytest.approx(10.0)


def test_collinear_moves_keep_speed():
    # two collinear moves at the same feed: no slowdown at their junction under any rule
    for header in (KLIPPER, marlin_jerk()[0]):
        p = make_program((0, 0, 0, 0), [("move", (50, 0, 0, 0), 50), ("move", (100, 0, 0, 0), 50)],
                         header, marlin_jerk()[1] if header != KLIPPER else ())
        pl = planner.plan(p)
        assert pl.exit_mm_s[0] == pytest.approx(50.0)
        one = planner.plan(make_program((0, 0, 0, 0), [("move", (100, 0, 0, 0), 50)], header,
                                        marlin_jerk()[1] if header != KLIPPER else ()))
        assert pl.duration_s.sum() == pytest.approx(one.duration_s.sum(), rel=1e-12)


@pytest.mark.parametrize("rule", ["deviation", "scv", "jerk"])
def test_square_path_corner_speeds_closed_form(rule):
    # a 20 mm square at 100 mm/s, a = 1000: every corner speed from the rule's closed form
    side, v, a = 20.0, 100.0, 1000.0
    pts = [(side, 0), (side, side), (0, side), (0, 0)]
    steps = [("move", (x, y, 0, 0), v) for x, y in pts]
    if rule == "deviation":
        jd = 0.05
        p = make_program((0, 0, 0, 0), steps, (f"M204 P{a:g} T{a:g}", f"M205 J{jd}", "M201 X9000 Y9000",
                                                "M203 X500 Y500"))
        expect = math.sqrt(a * jd * math.sqrt(0.5) / (1 - math.sqrt(0.5)))
    elif rule == "scv":
        p = make_program((0, 0, 0, 0), steps, KLIPPER)
        expect = 5.0
    else:
        p = jerk_program(steps, accel=a, jerk=8.0)
        expect = 8.0
    pl = planner.plan(p)
    assert pl.limits.junction == rule
    np.testing.assert_allclose(pl.entry_mm_s[1:], expect, rtol=1e-9)
    np.testing.assert_allclose(pl.exit_mm_s[:-1], expect, rtol=1e-9)
    # and each side's time is its trapezoid between those speeds
    v0 = pl.entry_mm_s[1]
    d_ramp = (v * v - v0 * v0) / (2 * a)
    t_side = 2 * (v - v0) / a + (side - 2 * d_ramp) / v
    assert pl.duration_s[1] == pytest.approx(t_side, rel=1e-9)


def test_reversal_stops_under_klipper_and_deviation():
    steps = [("move", (10, 0, 0, 0), 50), ("move", (0, 0, 0, 0), 50)]
    assert planner.plan(make_program((0, 0, 0, 0), steps, KLIPPER)).exit_mm_s[0] == pytest.approx(0, abs=1e-9)
    pl = planner.plan(make_program((0, 0, 0, 0), steps, ("M205 J0.02", "M204 P1000 T1000")))
    assert pl.exit_mm_s[0] < 0.1


def test_extruder_only_moves_and_dwell_force_stops():
    steps = [("move", (20, 0, 0, 1), 40), ("move", (20, 0, 0, 0.2), 35), ("move", (40, 0, 0, 0.2), 100),
             ("dwell", 0.5), ("move", (60, 0, 0, 0.2), 100)]
    pl = planner.plan(make_program((0, 0, 0, 0), steps, KLIPPER))
    assert pl.exit_mm_s[0] == 0 and pl.entry_mm_s[1] == 0 and pl.exit_mm_s[1] == 0
    assert pl.exit_mm_s[2] == 0 and pl.entry_mm_s[4] == 0
    assert pl.duration_s[3] == 0.5         # the dwell keeps its own time
    # retract move: E-only; on Klipper its accel is the extruder's max_extrude_only_accel, not the
    # toolhead's ACCEL (kinematics/extruder.py check_move): by default 3000 mm/s^2 (the stock
    # max_accel) * 4 * 0.4^2 / (pi 0.875^2) = 798.24
    assert pl.accel_mm_s2[1] == pytest.approx(3000 * 0.64 / (np.pi * 0.875 ** 2))
    assert pl.accel_mm_s2[1] == pytest.approx(798.2432, abs=1e-4)


# ------------------------------------------------------------------------------------------------
# model-level properties
def random_path(rng, n=60):
    steps, pos = [], np.zeros(4)
    for _ in range(n):
        r = rng.random()
        if r < 0.1:
            pos = pos + [0, 0, 0, -rng.uniform(0.2, 2)]
            steps.append(("move", tuple(pos), rng.uniform(20, 60)))
        elif r < 0.15:
            steps.append(("dwell", 0.1))
        else:
            d = rng.normal(size=2) * rng.choice([0.3, 3, 30])
            pos = pos + [d[0], d[1], 0, abs(d[0]) * 0.03 * (rng.random() < 0.7)]
            steps.append(("move", tuple(pos), rng.uniform(10, 200)))
    return steps


@pytest.mark.parametrize("header,footer", [(KLIPPER, ()), marlin_jerk(), (("M205 J0.02", "M204 P1000 T1000 R1000"), ())])
def test_monotone_in_acceleration(header, footer):
    # a higher acceleration never makes a print slower, under every junction rule
    rng = np.random.default_rng(5)
    for _ in range(5):
        p = make_program((0, 0, 0, 0), random_path(rng), header, footer)
        base = machine_limits(p)
        totals = [planner.plan(p, base.with_values(accel_print=acc, accel_travel=acc, accel_retract=acc)).total_s
                  for acc in (200, 500, 1000, 2000, 5000, 20000)]
        assert all(b <= a + 1e-9 for a, b in zip(totals, totals[1:])), totals
        # and the planner never beats the paper's L/F, which has infinite acceleration
        assert totals[-1] >= p.duration_s.sum() - 1e-9


def test_paper_model_reproduced_exactly():
    p = make_program((0, 0, 0, 0), random_path(np.random.default_rng(1)), KLIPPER)
    d = planner.durations(p, "paper")
    assert d is p.duration_s
    assert not np.array_equal(planner.durations(p, "planner"), d)
    with pytest.raises(planner.TimeModelError):
        planner.durations(p, "quantum")


def test_time_positions_inverse_and_consistent():
    p = make_program((0, 0, 0, 0), random_path(np.random.default_rng(2), 40), KLIPPER)
    pl = planner.plan(p)
    steps = np.repeat(np.arange(p.n_steps), 11)
    f = np.tile(np.linspace(0, 1, 11), p.n_steps)
    t = pl.time_at_fraction(steps, f)
    np.testing.assert_allclose(pl.time_at_fraction(np.arange(p.n_steps), 1.0), pl.duration_s, rtol=1e-9, atol=1e-12)
    assert np.all(np.diff(t.reshape(p.n_steps, 11), axis=1) >= -1e-12)      # monotone inside a step
    moving = pl.length_mm[steps] > 0
    np.testing.assert_allclose(pl.fraction_at_time(steps, t)[moving], f[moving], atol=1e-7)
    # one accelerating move from rest: the first half of the distance takes sqrt(2 (L/2) / a)
    one = planner.plan(make_program((0, 0, 0, 0), [("move", (1, 0, 0, 0), 100)], KLIPPER))
    assert one.time_at_fraction(0, 0.5) == pytest.approx(math.sqrt(2 * 0.5 / 1000))
    assert one.fraction_at_time(0, math.sqrt(2 * 0.25 / 1000)) == pytest.approx(0.25)


def _with_stop(steps, k):
    return steps[:k] + [("dwell", 0.0)] + steps[k:]


@pytest.mark.parametrize("header,footer", [(KLIPPER, ()), marlin_jerk(), (("M205 J0.02", "M204 P1000 T1000 R1000"), ())])
def test_stop_cost_matches_full_replan(header, footer):
    # the windowed stop cost equals re-planning the whole program with a stop (a zero dwell)
    rng = np.random.default_rng(11)
    steps = [s for s in random_path(rng, 80) if s[0] == "move"]
    p = make_program((0, 0, 0, 0), steps, header, footer)
    pl = planner.plan(p)
    fw = "marlin"
    for k in (1, 5, 17, 40, 63, len(steps) - 1):
        q = make_program((0, 0, 0, 0), _with_stop(steps, k), header, footer)
        extra = planner.plan(q).total_s - pl.total_s
        # (classic jerk can make a stop look faster than a shared junction: never credited)
        assert pl.stop_cost_s(k, firmware=fw) == pytest.approx(max(extra, 0.0), abs=1e-9)
    many = pl.stop_cost_s(np.array([1, 5, 17]), firmware=fw)
    assert many.shape == (3,)
    assert np.all(many >= 0)


@pytest.mark.parametrize("header,footer", [(KLIPPER, ()), marlin_jerk(), (("M205 J0.02", "M204 P1000 T1000 R1000"), ())])
def test_stop_cost_of_a_motor_line_in_the_file(header, footer):
    # the cost of an M18 already in the file = plan with it - plan without it; S0/S1 (the paper's
    # patch) and M17 do not drain the queue, so they cost nothing and change no speed
    rng = np.random.default_rng(3)
    steps = [s for s in random_path(rng, 40) if s[0] == "move"]
    k = 20
    base = make_program((0, 0, 0, 0), steps, header, footer)
    without = planner.plan(base)
    # every variant planned by the header's rules: a SET_STEPPER_ENABLE line is a Klipper command,
    # which would make the file's own default family Klipper's (limits.default_family)
    family = without.limits.firmware

    def planned(prog):
        return planner.plan(prog, machine_limits(prog, family=family))

    for text, drains in (("M18 X", True), ("SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=0", True),
                         ("S0 X", False), ("M17 X", False)):
        p = make_program((0, 0, 0, 0), steps[:k] + [("motor", text)] + steps[k:], header, footer)
        pl = planned(p)
        assert bool(planner.drains_queue(p)[k]) == drains
        extra = pl.total_s - without.total_s
        if not drains:
            assert extra == pytest.approx(0.0, abs=1e-12)
        assert pl.stop_cost_s(k, firmware="marlin") == pytest.approx(max(extra, 0.0), abs=1e-9)
        # a dwell right beside it also stops the head: then the motor line adds nothing
        q = make_program((0, 0, 0, 0), steps[:k] + [("motor", text), ("dwell", 0.0)] + steps[k:], header, footer)
        assert planned(q).stop_cost_s(k, firmware="marlin") == 0.0


def test_stop_cost_closed_form_and_klipper_dwell():
    # a straight 200 mm line cut in two at 50 mm/s, a = 1000, Klipper (from rest to rest): a stop
    # in the middle adds v/(2a) braking + v/(2a) accelerating = v/a = 0.05 s, plus 2 x 0.1 s dwell
    p = make_program((0, 0, 0, 0), [("move", (100, 0, 0, 0), 50), ("move", (200, 0, 0, 0), 50)], KLIPPER)
    pl = planner.plan(p)
    assert pl.stop_cost_s(1, firmware="marlin") == pytest.approx(0.05, rel=1e-9)
    assert pl.stop_cost_s(1) == pytest.approx(0.25, rel=1e-9)          # the file's firmware: Klipper
    assert pl.stop_cost_s(1, firmware="3dgates") == 0.0
    assert pl.stop_cost_s(0, firmware="marlin") == 0.0                   # already at rest there


# ------------------------------------------------------------------------------------------------
# machine limits
def test_limits_from_marlin_lines():
    header = ("M201 X1500 Y1400 Z300 E9000", "M203 X250 Y240 Z11 E90", "M204 P700 R1300 T2100",
              "M205 X9 Y7 Z0.3 E4 S1 T2 B20000")
    steps = [("move", (50, 0, 0, 1), 30), ("move", (100, 0, 0, 2), 30)]
    p = make_program((0, 0, 0, 0), steps, header)
    lim = machine_limits(p)
    np.testing.assert_allclose(lim.max_accel_mm_s2, [1500, 1400, 300, 9000])
    np.testing.assert_allclose(lim.max_feed_mm_s, [250, 240, 11, 90])
    np.testing.assert_allclose(lim.jerk_mm_s, [9, 7, 0.3, 4])
    assert (lim.accel_print_mm_s2, lim.accel_retract_mm_s2, lim.accel_travel_mm_s2) == (700, 1300, 2100)
    assert lim.min_feed_mm_s == 1 and lim.min_travel_feed_mm_s == 2
    assert lim.min_segment_time_s == pytest.approx(0.02)
    assert lim.source["accel_print"].startswith("line 3: M204")
    assert lim.firmware == "marlin"
    assert lim.changes == ()


def test_limit_change_applies_from_its_line():
    steps = [("move", (50, 0, 0, 1), 200), ("move", (100, 0, 0, 2), 200)]
    base = make_program((0, 0, 0, 0), steps, ("M204 P1000 T1000", "M205 J0.01"))
    # insert "M204 P300" between the two moves: build the text and patch the line numbers
    lines = base.data.decode().splitlines()
    lines.insert(3, "M204 P300")
    data = ("\n".join(lines) + "\n").encode()
    starts = np.zeros(len(lines) + 1, np.int64)
    starts[1:] = np.cumsum([len(x) + 1 for x in lines])
    p = dataclasses.replace(base, data=data, line_start=starts, line=np.array([2, 4]),
                            **({"line_letter": np.array([77, 77, 71, 77, 71], np.uint8),
                                "line_number": np.array([204, 205, 1, 204, 1], np.float32)}
                               if hasattr(base, "line_letter") else {}))
    lim = machine_limits(p)
    assert lim.accel_print_mm_s2 == 1000
    assert lim.changes == ((3, "accel_print", 300.0),)
    pl = planner.plan(p, lim)
    assert pl.accel_mm_s2[0] == 1000 and pl.accel_mm_s2[1] == 300


def test_limits_from_klipper_lines():
    header = ("SET_VELOCITY_LIMIT VELOCITY=250 ACCEL=4000 ACCEL_TO_DECEL=2000 SQUARE_CORNER_VELOCITY=8",)
    p = make_program((0, 0, 0, 0), [("move", (100, 0, 0, 1), 400)], header)
    lim = machine_limits(p)
    assert lim.firmware == "klipper" and lim.junction == "scv"
    assert lim.accel_print_mm_s2 == lim.accel_travel_mm_s2 == 4000
    assert lim.accel_to_decel_mm_s2 == 2000
    assert lim.square_corner_velocity_mm_s == 8 and lim.max_velocity_mm_s == 250
    pl = planner.plan(p, lim)
    assert pl.nominal_mm_s[0] == 250      # F400 capped by max_velocity


def test_limits_from_prusaslicer_config_block():
    footer = ("; prusaslicer_config = begin", "; gcode_flavor = marlin2",
              "; machine_limits_usage = emit_to_gcode",
              "; machine_max_acceleration_e = 10000,5000", "; machine_max_acceleration_extruding = 1250,1250",
              "; machine_max_acceleration_retracting = 1250,1250", "; machine_max_acceleration_travel = 1500,1250",
              "; machine_max_acceleration_x = 1000,960", "; machine_max_acceleration_y = 1000,960",
              "; machine_max_acceleration_z = 200,200", "; machine_max_feedrate_e = 120,120",
              "; machine_max_feedrate_x = 200,100", "; machine_max_feedrate_y = 200,100",
              "; machine_max_feedrate_z = 12,12", "; machine_max_jerk_e = 4.5,4.5",
              "; machine_max_jerk_x = 8,8", "; machine_max_jerk_y = 8,8", "; machine_max_jerk_z = 0.4,0.4",
              "; machine_min_extruding_rate = 0,0", "; machine_min_travel_rate = 0,0",
              "; prusaslicer_config = end")
    p = make_program((0, 0, 0, 0), [("move", (10, 0, 0, 1), 30), ("move", (20, 0, 0, 2), 30)],
                     ("M204 P2000",), footer)
    lim = machine_limits(p)
    assert lim.junction == "jerk"
    np.testing.assert_allclose(lim.max_accel_mm_s2, [1000, 1000, 200, 10000])   # normal mode (first) values
    np.testing.assert_allclose(lim.max_feed_mm_s, [200, 200, 12, 120])
    np.testing.assert_allclose(lim.jerk_mm_s, [8, 8, 0.4, 4.5])
    assert lim.accel_travel_mm_s2 == 1500 and lim.accel_retract_mm_s2 == 1250
    assert lim.source["max_accel_x"] == "config: machine_max_acceleration_x"
    # the file's M204 P2000 is capped by the declared machine maximum (PrusaSlicer's estimator)
    assert lim.accel_print_mm_s2 == 1250
    assert "line 1" in lim.source["accel_print"]


def test_limits_default_profile_recorded():
    p = make_program((0, 0, 0, 0), [("move", (10, 0, 0, 1), 30)])
    lim = machine_limits(p)
    assert lim.profile == "marlin" and lim.junction == "deviation"
    assert lim.source["accel_print"].startswith("default: marlin")
    with pytest.raises(Exception, match="unknown printer profile"):
        machine_limits(p, profile="nope")


def test_slicer_estimate_formats():
    cases = {
        "; estimated printing time (normal mode) = 1d 2h 3m 4s": 93784.0,
        ";TIME:3723": 3723.0,
        ";Print Time: 744": 744.0,
        ";   Build time: 1 hours 2 minutes": 3720.0,
        "; Calculated-during-export Build Time: 10.5 minutes": 630.0,
    }
    for line, want in cases.items():
        p = make_program((0, 0, 0, 0), [("move", (10, 0, 0, 0), 30)], (line,))
        assert planner.slicer_estimate_s(p) == pytest.approx(want)
    assert planner.slicer_estimate_s(make_program((0, 0, 0, 0), [("move", (1, 0, 0, 0), 3)])) is None


def test_curaengine_command_line_placeholder_is_not_taken_for_an_estimate():
    # CuraEngine run from the command line writes ;TIME:6666 (the Cura front end fills it in);
    # its estimate is then the last ;TIME_ELAPSED: marker (found on CuraEngine 4.13 output)
    moves = [("move", (10, 0, 0, 0), 30)]
    elapsed = (";TIME:6666", ";LAYER:0", ";TIME_ELAPSED:12.5", ";LAYER:1", ";TIME_ELAPSED:1028.153066")
    assert planner.slicer_estimate_s(make_program((0, 0, 0, 0), moves, elapsed)) == pytest.approx(1028.153066)
    # no header at all: the markers still say it
    assert planner.slicer_estimate_s(make_program((0, 0, 0, 0), moves, elapsed[1:])) == pytest.approx(1028.153066)
    # the placeholder alone is no estimate
    assert planner.slicer_estimate_s(make_program((0, 0, 0, 0), moves, (";TIME:6666",))) is None


# ------------------------------------------------------------------------------------------------
# real files: PrusaSlicer's estimator simulates Marlin's planner; we must agree closely
@pytest.mark.skipif(not INSTANCES.is_dir(), reason="../shared/instances not present")
@pytest.mark.parametrize("name", ["prusa25_cyl_vase.gcode.gz", "prusa25_star_rect15_m82.gcode.gz",
                                  "real_superslicer2356_arcwelder.gcode"])
def test_agrees_with_slicer_estimate(name):
    from gatesopt import parse
    p = parse(INSTANCES / name)
    est = planner.slicer_estimate_s(p)
    ours = planner.estimated_total_s(p, "planner")
    assert abs(ours / est - 1) < 0.02, (ours, est)
    # the paper model is far off on the same file (no acceleration): the planner is the better model
    assert abs(ours / est - 1) <= abs(planner.estimated_total_s(p, "paper") / est - 1)


def test_arc_close_to_its_polyline():
    # a G3 half circle (R = 20) and the same arc as 1-degree chords take nearly the same time, and
    # at most the paper's L/F plus a start and a stop (v/a)
    from gatesopt import parse
    head = "SET_VELOCITY_LIMIT VELOCITY=500 ACCEL=1000 SQUARE_CORNER_VELOCITY=5\nG90\nM83\nG1 X20 Y0 F3000\n"
    arc = parse(head + "G3 X-20 Y0 I-20 J0 E2 F3000\n")
    chords = "".join(f"G1 X{20 * math.cos(math.radians(a)):.5f} Y{20 * math.sin(math.radians(a)):.5f} E{2 / 180:.6f}\n"
                     for a in range(1, 181))
    poly = parse(head + chords)
    t_arc = planner.plan(arc).duration_s[-1]
    t_poly = planner.plan(poly).duration_s[1:].sum()
    L = math.pi * 20
    assert L / 50 <= t_arc <= L / 50 + 50 / 1000 + 1e-9
    assert t_arc == pytest.approx(t_poly, rel=0.02)


def test_kernel_columns_match_limit_keys():
    from gatesopt import _planner_kernel as k
    from gatesopt.limits import K
    assert (k.C_MAX_ACCEL, k.C_MAX_FEED, k.C_JERK) == (K["max_accel_x"], K["max_feed_x"], K["jerk_x"])
    assert (k.C_ACCEL_PRINT, k.C_ACCEL_TRAVEL, k.C_ACCEL_RETRACT, k.C_ACCEL_TO_DECEL) == (
        K["accel_print"], K["accel_travel"], K["accel_retract"], K["accel_to_decel"])
    assert (k.C_JD, k.C_SCV, k.C_MAX_VELOCITY, k.C_MIN_SEGMENT_TIME, k.C_MIN_FEED, k.C_MIN_TRAVEL_FEED) == (
        K["junction_deviation"], K["square_corner_velocity"], K["max_velocity"], K["min_segment_time"],
        K["min_feed"], K["min_travel_feed"])


def test_klipper_accel_to_decel_smoothing():
    # one 1 mm move from rest to rest, a = 1000, ACCEL_TO_DECEL = 500 (toolhead.py flush): the peak
    # v^2 is capped at (0 + 2 L a_smooth) / 2 = 500 instead of the triangle's a L = 1000
    head = ("SET_VELOCITY_LIMIT VELOCITY=500 ACCEL=1000 ACCEL_TO_DECEL=500 SQUARE_CORNER_VELOCITY=5",)
    pl = planner.plan(make_program((0, 0, 0, 0), [("move", (1, 0, 0, 0), 100)], head))
    vp = math.sqrt(500)
    assert pl.cruise_mm_s[0] == pytest.approx(vp)
    assert pl.duration_s[0] == pytest.approx(2 * vp / 1000 + 0.5 / vp, rel=1e-12)
    # smoothing never speeds a print up, and a long move is not affected
    rng = np.random.default_rng(9)
    steps = random_path(rng, 80)
    smooth = planner.plan(make_program((0, 0, 0, 0), steps, head)).total_s
    plain = planner.plan(make_program((0, 0, 0, 0), steps, KLIPPER[:1])).total_s
    assert smooth >= plain
    long_move = planner.plan(make_program((0, 0, 0, 0), [("move", (100, 0, 0, 0), 50)], head))
    assert long_move.duration_s[0] == pytest.approx(2.05, rel=1e-12)


def test_limits_reprapfirmware_units():
    # RepRapFirmware: M203 and M566 in mm/min
    p = make_program((0, 0, 0, 0), [("move", (10, 0, 0, 1), 30)],
                     ("M203 X12000 Y9000 Z600 E3000", "M566 X600 Y480 Z12 E300", "M201 X800 Y700"),
                     ("; gcode_flavor = reprapfirmware",))
    lim = machine_limits(p)
    assert lim.firmware == "reprap" and lim.junction == "jerk"
    np.testing.assert_allclose(lim.max_feed_mm_s, [200, 150, 10, 50])
    np.testing.assert_allclose(lim.jerk_mm_s, [10, 8, 0.2, 5])
    assert lim.source["jerk_x"].startswith("line 2: M566")


def test_time_positions_with_klipper_smoothing():
    head = ("SET_VELOCITY_LIMIT VELOCITY=500 ACCEL=3000 ACCEL_TO_DECEL=700 SQUARE_CORNER_VELOCITY=5",)
    p = make_program((0, 0, 0, 0), random_path(np.random.default_rng(4), 60), head)
    pl = planner.plan(p)
    ms = pl.move_step
    assert np.all(pl.entry_mm_s[ms] <= pl.cruise_mm_s[ms] + 1e-9)
    assert np.all(pl.exit_mm_s[ms] <= pl.cruise_mm_s[ms] + 1e-9)
    np.testing.assert_allclose(pl.time_at_fraction(ms, 1.0), pl.duration_s[ms], rtol=1e-9, atol=1e-12)
    f = np.full(len(ms), 0.37)
    np.testing.assert_allclose(pl.fraction_at_time(ms, pl.time_at_fraction(ms, f)), f, atol=1e-7)
