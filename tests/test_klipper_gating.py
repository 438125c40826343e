"""The klipper-gating dialect (issue 34): the gating model, the emitter, the verifier and the Klipper
module agree on when each pin is off.

- brute force over every subset of idle intervals, under the module's rules A and B (checked by
  ``check_feasible``), equals dp == milp == cpsat, with and without an input shaper;
- the dialect's constants are the module's (its own pure helpers, loaded from
  integrations/klipper/gatesopt_gating.py);
- the shaper windows are Klipper's (klippy/extras/shaper_defs.py from a checkout, when given);
- solve -> emit -> verify: every line the module gates, none it skips; a line the module would
  skip is reported;
- a Klipper printer.cfg is read as Klipper reads it (includes, SAVE_CONFIG).
"""
from __future__ import annotations

import dataclasses
import importlib.util
import itertools
import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO
from gatesopt import firmware as fwmod
from gatesopt.gating import GatingOptions, check_feasible, from_moves, score, solve
from gatesopt.parse import parse
from gatesopt.printer_config import PrinterConfigError, read_printer_config
from gatesopt.rewrite.pipeline import run
from gatesopt.shaper import shaper
from gatesopt.verify import verify
from gatesopt.verify.schedule import scheduled_lines, timeline_s

MODULE_PATH = REPO / "integrations" / "klipper" / "gatesopt_gating.py"
EXACT = ("dp", "milp", "cpsat")

MZV30_CFG = """
[printer]
kinematics: cartesian
max_velocity: 300
max_accel: 3000

[stepper_x]
[stepper_y]

[input_shaper]
shaper_type_x: mzv
shaper_freq_x: 30
shaper_type_y: mzv
shaper_freq_y: 30

[gatesopt_gating]
"""


def _load_module():
    spec = importlib.util.spec_from_file_location("gatesopt_gating_for_dialect", MODULE_PATH)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def mzv30(tmp_path_factory):
    p = tmp_path_factory.mktemp("cfg") / "printer.cfg"
    p.write_text(MZV30_CFG)
    return read_printer_config(p)


def _options(printer=None, slots=None, **kw):
    """The dialect's options; ``slots``: the module's pin_queue_slots instead of the printer's (1:
    rule A's floor is the spacing again, as the module takes it)."""
    o = GatingOptions.for_firmware("klipper-gating", printer=printer, rotate="none", **kw)
    if slots is not None:
        sch = o.schedule
        floor = printer.gating.min_off_time_s if printer is not None and printer.gating else 0.0
        o = o.replace(schedule=dataclasses.replace(
            sch, pin_queue_slots=slots, min_off_s=max(floor, sch.min_spacing_s) if slots == 1 else floor))
    return o


# ------------------------------------------------------------------------------------------------
# the dialect's numbers are the module's
@pytest.mark.parametrize("shaped", [False, True])
def test_the_dialects_margins_and_rule_a_are_the_modules(shaped, mzv30):
    gg = _load_module()
    printer = mzv30 if shaped else None
    o = _options(printer)
    pre, post = printer.window_s("x") if shaped else (0.0, 0.0)
    for m in (0, 1):
        assert math.isclose(o.off_margin_s(m), gg.off_delay_s(post, o.end_late_s), rel_tol=0, abs_tol=1e-15)
        assert math.isclose(o.on_margin_s(m), gg.on_lead_s(pre, o.start_ahead_s), rel_tol=0, abs_tol=1e-15)
        need = o.off_margin_s(m) + o.on_margin_s(m) + o.schedule.min_off_s
        assert math.isclose(need, gg.required_gap_s(pre, post, o.start_ahead_s, o.end_late_s, 0.0, 0.1,
                                                    o.schedule.pin_queue_slots), abs_tol=1e-15)
        o1 = _options(printer, slots=1)
        need1 = o1.off_margin_s(m) + o1.on_margin_s(m) + o1.schedule.min_off_s
        assert math.isclose(need1, gg.required_gap_s(pre, post, o.start_ahead_s, o.end_late_s, 0.0, 0.1, 1),
                            abs_tol=1e-15)
    assert o.schedule.min_spacing_s == pytest.approx(0.1)
    assert o.stall_off_s == o.stall_on_s == 0.0 and not o.on_line


def test_the_pin_spacing_default_and_range_are_the_modules(tmp_path):
    """One number for the least time between two changes of a pin: the module's default and range,
    the dialect's default, the printer.cfg reader's default and range."""
    from gatesopt.firmware import klipper_gating
    from gatesopt.printer_config import GatingSection
    gg = _load_module()
    assert gg.DEFAULT_PIN_SPACING_S == klipper_gating.PIN_SPACING_S == GatingSection().min_pin_spacing_s == 0.1
    assert _options().schedule.min_spacing_s == gg.DEFAULT_PIN_SPACING_S
    for value, ok in ((gg.MIN_PIN_SPACING_S, True), (gg.MAX_PIN_SPACING_S, True),
                      (gg.MIN_PIN_SPACING_S * 0.99, False), (gg.MAX_PIN_SPACING_S * 1.01, False)):
        cfg = tmp_path / "p.cfg"
        cfg.write_text(MZV30_CFG + f"min_pin_spacing: {value!r}\n")
        if ok:
            assert read_printer_config(cfg).gating.min_pin_spacing_s == value
        else:
            with pytest.raises(PrinterConfigError, match="min_pin_spacing"):
                read_printer_config(cfg)
    # the pin queue: two changes of a pin queued by default, 1 or 2, an integer as Klipper's getint
    assert gg.DEFAULT_PIN_QUEUE_SLOTS == klipper_gating.PIN_QUEUE_SLOTS == GatingSection().pin_queue_slots == 2
    assert _options().schedule.pin_queue_slots == 2 and _options().schedule.min_off_s == 0.0
    for value, ok in (("1", True), ("2", True), ("0", False), ("3", False), ("2.0", False), ("two", False)):
        cfg = tmp_path / "p.cfg"
        cfg.write_text(MZV30_CFG + f"pin_queue_slots: {value}\n")
        if ok:
            assert read_printer_config(cfg).gating.pin_queue_slots == int(value)
            assert _options(read_printer_config(cfg)).schedule.min_off_s == (0.1 if value == "1" else 0.0)
        else:
            with pytest.raises(PrinterConfigError, match="pin_queue_slots"):
                read_printer_config(cfg)


def test_min_pin_spacing_in_printer_cfg_sets_rules_a_and_b(tmp_path):
    """``min_pin_spacing: 0.05`` in [gatesopt_gating] with one change in flight: rule A's floor and
    rule B's spacing are 0.05 s in the gating problem (a 0.09 s idle stretch becomes an idle
    interval, two offs 0.06 s apart are both allowed), as the module applies them."""
    cfg = tmp_path / "p.cfg"
    cfg.write_text("[printer]\nkinematics: cartesian\nmax_velocity: 300\nmax_accel: 3000\n"
                   "[gatesopt_gating]\nmin_pin_spacing: 0.05\npin_queue_slots: 1\n")
    fast = read_printer_config(cfg)
    o = _options(fast)
    assert (o.schedule.min_off_s, o.schedule.min_spacing_s) == (0.05, 0.05)
    s = np.array([(0, 0, .2, 0), (1, 0, .2, 0), (1, 5, .2, 0)])
    e = np.array([(1, 0, .2, 0), (1, 5, .2, 0), (2, 5, .2, 0)])
    short = lambda opts: from_moves(s, e, np.array([0.05, 0.09, 0.05]), opts).n_idle_intervals
    assert short(_options(motors=("X",), slots=1)) == 0 and short(_options(fast, motors=("X",))) == 1
    # rule B: X idle 0.2 s, steps 0.06 s, idle 0.2 s: both off only with the smaller spacing
    s = np.array([(0, 0, .2, 0), (1, 0, .2, 0), (1, 5, .2, 0), (2, 5, .2, 0), (2, 10, .2, 0), (3, 10, .2, 0)])
    e = np.array([(1, 0, .2, 0), (1, 5, .2, 0), (2, 5, .2, 0), (2, 10, .2, 0), (3, 10, .2, 0), (4, 10, .2, 0)])
    d = np.array([0.05, 0.2, 0.06, 0.3, 0.02, 0.05])
    for opts, both in ((_options(slots=1), 1), (o, 2)):
        sol = solve(from_moves(s, e, d, opts), "dp")
        assert int(np.sum(sol.off_motor == 0)) == both


def test_the_pin_spacing_of_printer_cfg_is_what_solve_and_verify_use(tmp_path):
    """A file solved for ``min_pin_spacing: 0.025`` gates more than one for the default, the
    verifier derives exactly the report's off time with that printer.cfg, and without it (the
    module's default 0.1 s) finds lines the module would skip (one change in flight, where the
    spacing is rule A's floor too)."""
    from gatesopt.cli import main
    import json
    src, cfg = tmp_path / "in.gcode", tmp_path / "printer.cfg"
    src.write_text(GCODE)
    base = ("[printer]\nkinematics: cartesian\nmax_velocity: 300\nmax_accel: 3000\n[gatesopt_gating]\n"
            "pin_queue_slots: 1\n")
    off = {}
    for name, extra in (("default", ""), ("fast", "min_pin_spacing: 0.025\n")):
        cfg.write_text(base + extra)
        out, rep = tmp_path / f"{name}.gcode", tmp_path / f"{name}.json"
        assert main(["solve", str(src), "-o", str(out), "--firmware", "klipper-gating", "--printer-config",
                     str(cfg), "--no-order", "--rotate", "none", "--json", str(rep)]) == 0
        report = json.loads(rep.read_text())
        lines = scheduled_lines(parse(out.read_text().encode()), firmware="klipper-gating",
                                start_ahead_s=0.0018, end_late_s=0.001, printer=read_printer_config(cfg),
                                original=parse(GCODE.encode()))
        assert lines and all(s.gated for s in lines)
        off[name] = sum(report["off_time_s"].values())
        assert sum(s.on_s - s.off_s for s in lines) == pytest.approx(off[name], abs=1e-9)
        assert main(["verify", str(src), str(out), "--claimed", str(rep), "--printer-config", str(cfg)]) == 0
    assert off["fast"] > off["default"]
    cfg.write_text(base)
    rep = verify(parse(GCODE.encode()), parse((tmp_path / "fast.gcode").read_text().encode()),
                 firmware="klipper-gating", printer=read_printer_config(cfg))
    assert not rep.ok and any("skips this line" in str(f) for f in rep.findings)


# ------------------------------------------------------------------------------------------------
# brute force == dp == milp == cpsat under rules A and B
def _random_moves(rng, n):
    """A polyline of n axis-parallel or diagonal moves with durations around rule A's 0.1 s floor,
    and a few extrude-only moves (they count towards an idle interval's length)."""
    pts, durs = [(0.0, 0.0)], []
    starts, ends = [], []
    e = 0.0
    x, y = 0.0, 0.0
    for _ in range(n):
        kind = rng.integers(4)
        d = float(rng.choice([0.02, 0.04, 0.06, 0.09, 0.12, 0.2, 0.35]))
        if kind == 3:           # extrude-only
            starts.append((x, y, 0.2, e))
            e -= 0.5
            ends.append((x, y, 0.2, e))
        else:
            dx = float(rng.uniform(1, 5)) if kind in (0, 2) else 0.0
            dy = float(rng.uniform(1, 5)) if kind in (1, 2) else 0.0
            starts.append((x, y, 0.2, e))
            x, y, e = x + dx, y + dy, e + 0.05
            ends.append((x, y, 0.2, e))
        durs.append(d)
    return np.array(starts), np.array(ends), np.array(durs)


def _brute_force(problem):
    best = None
    for k in range(problem.n_angles):
        g = problem.idle_intervals_of(k)
        assert len(g) <= 13, "instance too big for brute force"
        for r in range(len(g) + 1):
            for sub in itertools.combinations(g, r):
                sub = np.array(sub, np.int64)
                m, a, b = problem.idle_motor[sub], problem.idle_start_s[sub], problem.idle_end_s[sub]
                if check_feasible(problem, k, m, a, b):
                    continue
                e = score(problem, m, a, b).energy_j
                if best is None or e < best - 1e-9:
                    best = e
    return best


def _module_rule_b(problem, chosen) -> bool:
    """Rule B as the module's protocol states it, from first principles on the lower-bound clock:
    consecutive gated intervals i, j of a motor; one change in flight: i's on to j's off at least
    the spacing (margins counted); two queued: i's off to j's off and i's on to j's on."""
    o = problem.options
    sp, k = o.schedule.min_spacing_s, o.schedule.pin_queue_slots
    for m in set(problem.idle_motor[chosen].tolist()):
        g = sorted(chosen[problem.idle_motor[chosen] == m], key=lambda i: problem.idle_lb_off_s[i])
        for i, j in zip(g, g[1:]):
            off_i, on_i = problem.idle_lb_off_s[i], problem.idle_lb_on_s[i]
            off_j, on_j = problem.idle_lb_off_s[j], problem.idle_lb_on_s[j]
            if k == 1 and o.on_margin_s(m) + (off_j - on_i) + o.off_margin_s(m) < sp:
                return False
            if k == 2 and (off_j - off_i < sp or on_j - on_i < sp):
                return False
    return True


def _brute_force_rules(problem):
    """The best energy over every subset of idle intervals that keeps ``_module_rule_b``."""
    best = None
    for k in range(problem.n_angles):
        g = problem.idle_intervals_of(k)
        for r in range(len(g) + 1):
            for sub in itertools.combinations(g, r):
                sub = np.array(sub, np.int64)
                if not _module_rule_b(problem, sub):
                    continue
                e = score(problem, problem.idle_motor[sub], problem.idle_start_s[sub], problem.idle_end_s[sub]).energy_j
                if best is None or e < best - 1e-9:
                    best = e
    return best


@pytest.mark.parametrize("slots", [1, 2])
@pytest.mark.parametrize("shaped", [False, True])
@pytest.mark.parametrize("seed", range(8))
def test_exact_solvers_equal_brute_force_under_the_modules_rules(seed, shaped, slots, mzv30):
    """dp (the chain with one monotone predecessor), milp, cpsat == brute force over every subset,
    with one change of a pin in flight and with two queued; the brute force by check_feasible and by
    rule B written here from the protocol give the same optimum."""
    rng = np.random.default_rng(seed)
    s, e, d = _random_moves(rng, 14)
    p = from_moves(s, e, d, _options(mzv30 if shaped else None, slots=slots))
    assert p.n_idle_intervals <= 13
    best = _brute_force(p)
    assert best == pytest.approx(_brute_force_rules(p), rel=1e-12, abs=1e-9)
    for f in EXACT:
        sol = solve(p, f, time_limit_s=30)
        assert sol.status == "optimal", (f, sol.status, sol.message)
        assert check_feasible(p, sol.angle_index, sol.off_motor, sol.off_start_s, sol.off_end_s) == []
        assert sol.energy_j == pytest.approx(best, rel=1e-9, abs=1e-9), f
    g = solve(p, "greedy")
    assert check_feasible(p, g.angle_index, g.off_motor, g.off_start_s, g.off_end_s) == []
    assert g.energy_j >= best - 1e-9


X_IDLE_STEP_IDLE = (
    np.array([(0, 0, .2, 0), (1, 0, .2, 0), (1, 5, .2, 0), (2, 5, .2, 0), (2, 10, .2, 0), (3, 10, .2, 0)]),
    np.array([(1, 0, .2, 0), (1, 5, .2, 0), (2, 5, .2, 0), (2, 10, .2, 0), (3, 10, .2, 0), (4, 10, .2, 0)]))


def _x_offs(durations, slots, formulations=EXACT + ("greedy",)):
    """X steps, idles (Y) ``durations[1]``, steps ``durations[2]``, idles ``durations[3]``, steps:
    (idle intervals of X, {formulation: X intervals off}, check_feasible of both off)."""
    s, e = X_IDLE_STEP_IDLE
    p = from_moves(s, e, np.array(durations), _options(slots=slots))
    x = np.flatnonzero(p.idle_motor == 0)
    both = check_feasible(p, 0, p.idle_motor[x], p.idle_start_s[x], p.idle_end_s[x])
    return len(x), {f: int(np.sum(solve(p, f).off_motor == 0)) for f in formulations}, both


def test_rule_b_makes_the_optimum_skip_an_interval():
    """One change in flight: X idle for 0.2 s, steps 0.02 s, idle 0.2 s again: the first on and the
    second off are 0.02 s + margins apart, less than 0.1 s: only one of them may be off, and every
    solver keeps exactly one. Two queued: the offs and the ons are 0.22 s apart, both are off."""
    n, off, both = _x_offs([0.05, 0.2, 0.02, 0.3, 0.02, 0.05], slots=1)
    assert n == 2 and any("rule B" in v for v in both) and set(off.values()) == {1}, off
    n, off, both = _x_offs([0.05, 0.2, 0.02, 0.3, 0.02, 0.05], slots=2)
    assert n == 2 and both == [] and set(off.values()) == {2}, off


@pytest.mark.parametrize("durations,why", [
    ([0.05, 0.2, 0.02, 0.05, 0.02, 0.05], "on after on"),     # ons 0.02 + 0.05 s apart
    ([0.05, 0.05, 0.02, 0.2, 0.02, 0.05], "off after off"),   # offs 0.05 + 0.02 s apart
])
def test_rule_b_with_two_queued_changes(durations, why):
    """Two changes of a pin queued: each change waits for the change two back, so i's off and j's
    off, and i's on and j's on, must each be 0.1 s apart; here one pair is 0.07 s apart (the other
    0.22 s): only one interval may be off, and every solver keeps exactly one of them."""
    n, off, both = _x_offs(durations, slots=2)
    assert n == 2 and any("rule B" in v for v in both) and set(off.values()) == {1}, (why, off)


def test_rule_a_leaves_short_intervals_out():
    """One change in flight: an X idle interval of 0.09 s of moves is shorter than 0.1 s + margins:
    not an idle interval of the problem; 0.11 s is. Two queued: rule A is the margins (2.827 ms)
    and min_off_time alone."""
    def problem(gap_s, slots):
        s = np.array([(0, 0, .2, 0), (1, 0, .2, 0), (1, 5, .2, 0)])
        e = np.array([(1, 0, .2, 0), (1, 5, .2, 0), (2, 5, .2, 0)])
        return from_moves(s, e, np.array([0.05, gap_s, 0.05]), _options(motors=("X",), slots=slots))
    assert problem(0.09, 1).n_idle_intervals == 0
    assert problem(0.11, 1).n_idle_intervals == 1
    assert problem(0.09, 2).n_idle_intervals == 1
    assert problem(0.0028, 2).n_idle_intervals == 0 and problem(0.0029, 2).n_idle_intervals == 1


# ------------------------------------------------------------------------------------------------
# solve -> emit -> verify, on G-code
GCODE = """; tiny print for klipper-gating
G28
G1 Z0.2 F600
G1 X10 Y10 F6000
G1 X20 E1 F1200
G1 Y30 E2 F1200
G1 X21 E2.05 F1200
G1 Y31 E2.1 F1200
G1 X40 E3 F1200
G1 E2 F2400
G1 Y50 F1200
G1 E3 F2400
G1 X50 E4 F1200
G1 Y50.5 E4.1 F600
G1 X60 E5 F1200
M84
"""


@pytest.mark.parametrize("formulation", ("greedy",) + EXACT)
@pytest.mark.parametrize("shaped", [False, True])
def test_every_emitted_line_is_gated_by_the_protocol(formulation, shaped, mzv30):
    prog = parse(GCODE.encode(), source="tiny.gcode")
    o = _options(mzv30 if shaped else None)
    res = run(prog, o, formulation=formulation, order=False)
    assert res.report.ok, res.report.findings
    out = parse(res.text.encode(), source="out.gcode")
    lines = scheduled_lines(out, firmware="klipper-gating", start_ahead_s=o.start_ahead_s,
                            end_late_s=o.end_late_s, printer=o.printer, original=prog)
    assert lines and all(s.gated for s in lines)
    # the off time the verifier derives is the solution's, motor by motor
    sol = res.solution
    for m in (0, 1):
        got = sum(s.on_s - s.off_s for s in lines if s.motor == m)
        want = float(np.sum((sol.off_end_s - sol.off_start_s)[sol.off_motor == m]))
        assert got == pytest.approx(want, abs=1e-9)
    assert "GATESOPT_GATE" in res.text and "SET_STEPPER_ENABLE" not in res.text


def test_a_line_the_module_would_skip_is_reported(tmp_path):
    prog = parse(GCODE.encode(), source="tiny.gcode")
    # after the X move of line 7 (1 mm at 20 mm/s = 0.05 s) X idles 1 mm of Y (0.05 s): too short
    # with one change of the pin in flight (rule A's floor is then the 0.1 s spacing)
    cfg = tmp_path / "printer.cfg"
    cfg.write_text("[printer]\nkinematics: cartesian\nmax_velocity: 300\nmax_accel: 3000\n"
                   "[gatesopt_gating]\npin_queue_slots: 1\n")
    one = read_printer_config(cfg)
    text = GCODE.replace("G1 X21 E2.05 F1200\n", "G1 X21 E2.05 F1200\nGATESOPT_GATE STEPPERS=stepper_x\n")
    out = parse(text.encode(), source="bad.gcode")
    rep = verify(prog, out, firmware="klipper-gating", printer=one)
    assert not rep.ok
    assert any("skips this line for motor X (short)" in str(f) for f in rep.findings)
    assert verify(prog, out, firmware="klipper-gating").ok      # two queued: rule A is the margins
    # two queued: a second X line whose on comes 0.075 s after the first line's on (X21 0.05 s,
    # Y30.5 0.025 s at 20 mm/s): the module skips it for the spacing, as the verifier says
    text = GCODE.replace("G1 X20 E1 F1200\n", "G1 X20 E1 F1200\nGATESOPT_GATE STEPPERS=stepper_x\n")
    text = text.replace("G1 X21 E2.05 F1200\nG1 Y31 E2.1 F1200\n",
                        "G1 X21 E2.05 F1200\nGATESOPT_GATE STEPPERS=stepper_x\nG1 Y30.5 E2.1 F1200\n")
    orig = parse(GCODE.replace("G1 Y31 E2.1 F1200\n", "G1 Y30.5 E2.1 F1200\n").encode(), source="tiny.gcode")
    rep = verify(orig, parse(text.encode(), source="bad.gcode"), firmware="klipper-gating")
    assert [str(f) for f in rep.findings if f.check == "timing"] and all(
        "motor X (spacing)" in str(f) for f in rep.findings if f.check == "timing"), rep.findings
    # a line for the extruder: the module refuses it
    text = GCODE.replace("G1 X40 E3 F1200\n", "G1 X40 E3 F1200\nGATESOPT_GATE STEPPERS=extruder\n")
    rep = verify(prog, parse(text.encode(), source="bad.gcode"), firmware="klipper-gating")
    assert any(f.check == "firmware" for f in rep.findings)


def test_the_claim_with_a_shaper_fails_without_the_printer_config(mzv30):
    prog = parse(GCODE.encode(), source="tiny.gcode")
    o = _options(mzv30)
    res = run(prog, o, formulation="dp", order=False)
    assert res.report.ok
    out = parse(res.text.encode(), source="out.gcode")
    claimed = (res.solution.energy_j, res.solution.time_after_s)
    assert verify(prog, out, firmware="klipper-gating", claimed=claimed, printer=mzv30).ok
    assert not verify(prog, out, firmware="klipper-gating", claimed=claimed).ok


# ------------------------------------------------------------------------------------------------
# printer.cfg and shaper windows
def test_printer_config_reads_includes_and_save_config(tmp_path):
    (tmp_path / "shaper.cfg").write_text("[input_shaper]\nshaper_freq_x: 40 ; a comment\nshaper_type: zv\n")
    (tmp_path / "printer.cfg").write_text(
        "[include shaper.cfg]\n[printer]\nkinematics: cartesian\nmax_velocity: 250\nmax_accel: 2000\n"
        "[gatesopt_gating]\nsteppers: stepper_x\nstart_ahead: 0.002\n"
        "#*# <---------------------- SAVE_CONFIG ---------------------->\n"
        "#*# DO NOT EDIT THIS BLOCK OR BELOW. The contents are auto-generated.\n#*#\n"
        "#*# [input_shaper]\n#*# shaper_freq_y = 50.0\n#*# shaper_type_y = mzv\n")
    c = read_printer_config(tmp_path / "printer.cfg")
    shaped = dict(c.shapers)
    assert shaped["x"].name == "zv" and shaped["y"].name == "mzv"
    assert c.window_s("y") == shaper("mzv", 50).window_s()
    assert c.gating.steppers == ("stepper_x",) and c.gating.start_ahead_s == 0.002
    o = GatingOptions.for_firmware("klipper-gating", printer=c, motors=("X",))
    assert o.start_ahead_s == 0.002
    with pytest.raises(fwmod.FirmwareError, match="gate X only"):
        GatingOptions.for_firmware("klipper-gating", printer=c, motors=("X", "Y"))
    (tmp_path / "bad.cfg").write_text("[printer]\nmax_velocity: fast\n")
    with pytest.raises(PrinterConfigError, match="bad.cfg.*max_velocity"):
        read_printer_config(tmp_path / "bad.cfg")


def test_a_corexy_printer_is_refused(tmp_path):
    (tmp_path / "p.cfg").write_text("[printer]\nkinematics: corexy\n")
    with pytest.raises(fwmod.FirmwareError, match=r"cartesian printers only: both stepper_x \(A\) and "
                       r"stepper_y \(B\) step for every X or Y move.*per axis \(X, Y\), not per motor A/B"):
        GatingOptions.for_firmware("klipper-gating", printer=read_printer_config(tmp_path / "p.cfg"))
    (tmp_path / "d.cfg").write_text("[printer]\nkinematics: delta\n")
    with pytest.raises(fwmod.FirmwareError, match="'delta'.*do not each move one axis alone"):
        GatingOptions.for_firmware("klipper-gating", printer=read_printer_config(tmp_path / "d.cfg"))


KLIPPER = os.environ.get("GATESOPT_KLIPPER")


@pytest.mark.skipif(not KLIPPER or not (Path(KLIPPER or ".") / "klippy/extras/shaper_defs.py").exists(),
                    reason="needs a Klipper checkout in $GATESOPT_KLIPPER (klippy/extras/shaper_defs.py)")
@pytest.mark.parametrize("name", ["zv", "mzv", "zvd", "ei", "2hump_ei", "3hump_ei"])
@pytest.mark.parametrize("freq, zeta", [(30.0, 0.1), (47.5, 0.05), (80.0, 0.15)])
def test_shaper_windows_are_klippers(name, freq, zeta, monkeypatch):
    monkeypatch.syspath_prepend(str(Path(KLIPPER) / "klippy"))      # shaper_defs imports mathutil
    spec = importlib.util.spec_from_file_location("klipper_shaper_defs", Path(KLIPPER) / "klippy/extras/shaper_defs.py")
    sd = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(sd)
    cfg = sd.get_shaper_cfg(name) if hasattr(sd, "get_shaper_cfg") else \
        next(s for s in sd.INPUT_SHAPERS if s.name == name)
    a, t = cfg.init_func(freq, zeta)
    # klippy/chelper/kin_shaper.c init_shaper: reversed, normalised, shifted to a zero mean
    n = len(a)
    ra = [a[n - i - 1] / sum(a) for i in range(n)]
    rt = [-t[n - i - 1] for i in range(n)]
    ts = sum(x * y for x, y in zip(ra, rt))
    rt = [x - ts for x in rt]
    pre, post = rt[-1], -rt[0]      # shaper_note_generation_time
    ours = shaper(name, freq, zeta).window_s()
    assert ours == pytest.approx((pre, post), rel=1e-9, abs=1e-12)


# ------------------------------------------------------------------------------------------------
# through Klipper's own host with the module (bench/klipper_replay.py)
def _replay_bench():
    sys.path.insert(0, str(REPO / "bench"))
    try:
        import klipper_replay as kr
    finally:
        sys.path.pop(0)
    return kr


@pytest.mark.parametrize("shaped", [False, True])
def test_klipper_with_the_module_gates_exactly_the_emitted_lines(shaped, tmp_path):
    kr = _replay_bench()
    host = kr.find_host()
    if isinstance(host, str):
        pytest.skip(f"no Klipper host for the replay: {host}")
    shaper_spec = kr.parse_shaper("mzv:30" if shaped else "none")
    cfg = kr.printer_config(shaper_spec, {})
    (tmp_path / "printer.cfg").write_text(cfg)
    printer = read_printer_config(tmp_path / "printer.cfg")
    prog = parse(GCODE.encode(), source="tiny.gcode")
    o = _options(printer)
    res = run(prog, o, formulation="dp", order=False)
    assert res.report.ok
    lines = scheduled_lines(parse(res.text.encode()), firmware="klipper-gating", start_ahead_s=o.start_ahead_s,
                            end_late_s=o.end_late_s, printer=printer, original=prog)
    want = {name: sum(1 for s in lines if s.motor == m and s.gated)
            for m, name in enumerate(("stepper_x", "stepper_y"))}
    assert sum(want.values()) > 0
    with kr.KlippyRunner(host, MODULE_PATH) as k:
        rep = k.run(cfg, kr.replay_text(res.text)[0], kr.stepper_pins(cfg))
    for name, n in want.items():
        st = rep.steppers[name]
        assert st.gated == n, name                       # the module gated every line, nothing else
        assert st.gated_steps_while_off == 0, name
        if n:
            assert st.start_ahead_min_s >= o.start_ahead_s - 1e-6
            assert st.end_late_min_s >= o.end_late_s - 1e-6


def test_the_planner_time_model_plans_with_the_printer_configs_limits(tmp_path):
    """``GatingOptions.time_model = "planner"`` (klipper-gating's): the problem's timeline is
    ``planner.plan`` with Klipper's rules and the printer.cfg's limits, and the verifier's too."""
    from gatesopt.gating import build
    from gatesopt.limits import machine_limits
    from gatesopt.planner import plan
    prog = parse(GCODE.encode(), source="tiny.gcode")
    totals = {}
    for accel in (500, 3000):
        (tmp_path / f"p{accel}.cfg").write_text(f"[printer]\nkinematics: cartesian\nmax_velocity: 300\n"
                                                f"max_accel: {accel}\nminimum_cruise_ratio: 0.5\n")
        printer = read_printer_config(tmp_path / f"p{accel}.cfg")
        o = GatingOptions(rotate="none", time_model="planner", planner_family="klipper", printer=printer)
        p = build(prog, o)
        want = plan(prog, machine_limits(prog, family="klipper", printer=printer)).duration_s.sum()
        assert p.total_s == pytest.approx(want, rel=1e-12)
        assert timeline_s(prog, "klipper-gating", printer).sum() == pytest.approx(want, rel=1e-12)
        totals[accel] = p.total_s
    assert totals[500] > totals[3000] > prog.duration_s.sum()


def test_the_command_line_solves_and_verifies_for_a_printer_config(tmp_path, capsys):
    from gatesopt.cli import main
    src, out, rep, cfg = (tmp_path / n for n in ("in.gcode", "out.gcode", "rep.json", "printer.cfg"))
    src.write_text(GCODE)
    cfg.write_text(MZV30_CFG)
    assert main(["solve", str(src), "-o", str(out), "--firmware", "klipper-gating", "--printer-config", str(cfg),
                 "--no-order", "--rotate", "none", "--json", str(rep)]) == 0
    assert "GATESOPT_GATE STEPPERS=" in out.read_text()
    assert main(["verify", str(src), str(out), "--claimed", str(rep), "--printer-config", str(cfg)]) == 0
    capsys.readouterr()
    # the same claim read without the shaper's window: the module would switch later and earlier
    assert main(["verify", str(src), str(out), "--claimed", str(rep)]) == 1
    assert "energy recomputed from the text" in capsys.readouterr().out
    cfg.write_text("[printer]\nmax_accel: lots\n")
    assert main(["solve", str(src), "-o", str(tmp_path / "o2.gcode"), "--firmware", "klipper-gating",
                 "--printer-config", str(cfg)]) != 0
    assert "max_accel" in capsys.readouterr().err


def test_the_modules_start_ahead_in_printer_cfg_is_what_solve_and_verify_use(tmp_path):
    from gatesopt.cli import main
    src, out, rep, cfg = (tmp_path / n for n in ("in.gcode", "out.gcode", "rep.json", "printer.cfg"))
    src.write_text(GCODE)
    cfg.write_text(MZV30_CFG + "start_ahead: 0.004\nend_late: 0.002\n")
    assert main(["solve", str(src), "-o", str(out), "--firmware", "klipper-gating", "--printer-config", str(cfg),
                 "--no-order", "--rotate", "none", "--json", str(rep)]) == 0
    import json
    report = json.loads(rep.read_text())
    printer = read_printer_config(cfg)
    lines = scheduled_lines(parse(out.read_text().encode()), firmware="klipper-gating", start_ahead_s=0.004,
                            end_late_s=0.002, printer=printer, original=parse(GCODE.encode()))
    assert lines and all(s.gated for s in lines)
    assert sum(s.on_s - s.off_s for s in lines) == pytest.approx(sum(report["off_time_s"].values()), abs=1e-9)
    assert main(["verify", str(src), str(out), "--claimed", str(rep), "--printer-config", str(cfg)]) == 0
    # a command-line value that disagrees with the module's is refused
    assert main(["solve", str(src), "-o", str(tmp_path / "o2.gcode"), "--firmware", "klipper-gating",
                 "--printer-config", str(cfg), "--start-ahead-ms", "3"]) != 0


def test_the_verifier_reads_repeated_and_early_lines_as_the_module_does():
    """A second line for X before X steps again is the module's "repeated" (the first covers the
    stretch); a line before homing is "motor_off" (Klipper has not enabled Y yet)."""
    prog = parse(GCODE.encode(), source="tiny.gcode")
    text = GCODE.replace("G1 X40 E3 F1200\n", "G1 X40 E3 F1200\nGATESOPT_GATE STEPPERS=stepper_x\n"
                                              "GATESOPT_GATE STEPPERS=stepper_x\n")
    text = text.replace("G28\n", "GATESOPT_GATE STEPPERS=stepper_y\nG28\n")
    out = parse(text.encode(), source="hand.gcode")
    got = [(s.motor, s.gated, s.reason) for s in
           scheduled_lines(out, firmware="klipper-gating", start_ahead_s=1.8e-3, end_late_s=1e-3, original=prog)]
    assert got == [(1, False, "motor_off"), (0, True, ""), (0, False, "repeated")]


# ------------------------------------------------------------------------------------------------
# the rotation adds no planned time beyond issue 34's 0.05 %
def test_auto_rotation_that_lengthens_the_planned_print_is_refused():
    """A 45 deg turn that saves energy but lengthens the travel out of the print (to an absolute
    park point the rotation does not move) by far more than 0.05 % of the planned print: --rotate
    auto keeps 0 deg for klipper-gating and says why; without the limit it turns the print."""
    import gatesopt
    from gatesopt.firmware import klipper_gating
    from test_rotation_policy import diagonal_part
    text = diagonal_part().replace("G1 X0 Y200 F6000", "G1 X70 Y70 F6000\nG1 X0 Y200 F6000")
    prog = gatesopt.parse(text)
    o = GatingOptions.for_firmware("klipper-gating", bed_size_mm=(235, 235))
    assert o.max_rotation_added_time_pct == klipper_gating.MAX_ROTATION_ADDED_TIME_PCT == 0.05
    res = run(prog, o, order=False)
    s = res.summary()
    assert res.report.ok and s["rotation_deg"] == 0.0
    assert s["rotation_line"].startswith("none: 45 deg, the best of ")
    assert "to the planned print, more than the 0.05 % allowed (--rotate 45 to take it)" in s["rotation_line"]
    free = run(prog, o.replace(max_rotation_added_time_pct=None), order=False)
    assert free.report.ok and free.summary()["rotation_deg"] == 45.0
    assert res.report.energy_j > free.report.energy_j      # the refusal costs energy, not time


def _arc_turns(text: str) -> list[float]:
    """Klipper's turn of every G2/G3 with I/J in ``text`` (absolute XY, no offsets)."""
    from gatesopt.gating.emit_line import klipper_arc_turn
    cur, out = [0.0, 0.0], []
    for line in text.splitlines():
        w = line.split(";")[0].split()
        if not w or w[0] not in ("G0", "G1", "G2", "G3"):
            continue
        d = {x[0]: x[1:] for x in w[1:]}
        tgt = [float(d["X"]) if "X" in d else cur[0], float(d["Y"]) if "Y" in d else cur[1]]
        if w[0] in ("G2", "G3") and "I" in d:
            out.append(klipper_arc_turn(cur, tgt, (float(d["I"]), float(d["J"])), w[0] == "G2"))
        cur = tgt
    return out


def test_a_rotated_spiral_lift_turns_in_klipper_as_the_original():
    """Orca's spiral lift ``G3 Z.. I.. J.. P1`` (target = start): Klipper's planArc makes it a full
    circle only if its float sums give exactly 0, a null arc for a hair more. Turned 45 deg and
    rounded, such arcs flipped (+4.6 s on real_orca230_arcs in Klipper); the rotated I/J keep every
    one as Klipper turned the original."""
    rng = np.random.default_rng(7)
    out = ["G21", "G90", "M83", "G28", "G1 Z0.2 F600"]
    for k in range(80):
        x, y = (float(v) for v in np.round(rng.uniform(60, 140, 2), 3))
        out += [f";LAYER:{k}", f"G1 X{x:.3f} Y{y:.3f} F6000", f"G1 X{x + 20:.3f} Y{y:.3f} E1 F1800",
                f"G3 Z{0.4 + 0.2 * k:.1f} I{rng.uniform(-1.2, 1.2):.3f} J{rng.choice([-1, 1]) * 1.1:.3f} P1 F30000",
                f"G1 Z{0.2 + 0.2 * k:.1f}", f"G1 X{x + 20:.3f} Y{y + 20:.3f} E1 F1800"]
    out += ["G1 X0 Y200 F6000"]
    prog = parse("\n".join(out).encode() + b"\n", source="lift.gcode")
    o = GatingOptions.for_firmware("klipper-gating", bed_size_mm=(235, 235), rotate=45.0)
    res = run(prog, o, order=False)
    assert res.report.ok, res.report.findings
    before, after = _arc_turns("\n".join(out)), _arc_turns(res.text)
    assert len(before) == len(after) == 80
    assert sum(abs(a) > math.pi for a in before) not in (0, 80)       # both kinds among the originals
    assert all(abs(a - b) < math.pi for a, b in zip(before, after))
