"""The ``klipper`` dialect: stock Klipper.

``klippy/extras/stepper_enable.py`` (read at Klipper3d/klipper@0e30b86 and 84104bb):
``cmd_SET_STEPPER_ENABLE`` -> ``set_motors_enable``. For ``ENABLE=0`` it flushes the look-ahead
(``toolhead.flush_step_generation``: the moves before it end at rest), dwells
``DISABLE_STALL_TIME`` (0.100 s), switches the pin, and dwells 0.100 s again: 0.22 s measured. For
``ENABLE=1`` it flushes the same way and switches the pin at ``toolhead.get_last_move_time()``,
without a dwell: after the flush ``_calc_print_time`` restarts the clock ``2 * kin_flush_delay``
later (``motion_queuing.calc_step_gen_restart``: ``SDS_CHECK_TIME`` 1 ms, or the input shaper's
step window if longer), so one enable line costs a full stop plus 2 ms (17-19 ms measured).

Re-enable. Without an enable line Klipper re-enables a stepper by itself: ``motor_disable``
re-registers ``add_active_callback(self.motor_enable)``, called with the print time of the first
move that steps it (klippy/stepper.py ``_check_active``), i.e. the move's *nominal* start. That
honours no start-ahead, and with an input shaper the shaped steps begin up to the shaper's
pre-active time before the nominal start (klippy/chelper/kin_shaper.c: the last pulse time; mzv at
30 Hz 14.3 ms, 3hump_ei at 20 Hz 58.3 ms, ``extras/shaper_defs.py``): steps were sent while the pin
was off (docs/RESULTS.md). So this dialect writes ``SET_STEPPER_ENABLE STEPPER=... ENABLE=1``
start-ahead before the stepper's next move, and counts ``SHAPER_LEAD_S`` on top of the start-ahead
asked for (``start_lead_s``): the motor is on before the first shaped step of any of Klipper's
shapers at 20 Hz or more. The pin goes on at the end of the moves before the line (the flush), so
the moves between line and step are the start-ahead; the flush's stop only delays them.

A flush brings the head to rest at the line: inside a move from its cruising speed (v / a, 50 ms
at 150 mm/s and 3000 mm/s^2), between two moves from their junction speed, which is 0 next to a
retraction (an extrude-only move starts and ends at rest, ``Move.calc_junction``). So an enable
line is priced per move (``enable_is_stop``): ``planner.stop_restart_s`` -- v / (2 a) to stop
from the speed v the head passes the line at and as much to get back to it, 0 next to an
extrude-only move -- plus the restart ``2 * kin_flush_delay`` (below), in the gating problem, the
verifier and the report's print time alike (where no planner prices it, ``KLIPPER_ENABLE_STALL_S``:
a stop at 50 mm/s). A disable line likewise (``disable_is_stop``): its flush's stop, the two
0.1 s dwells and the restart (``KLIPPER_STALL_S``, 0.22 s, where no planner prices it; 203-241 ms
measured without a shaper). No line of this dialect splits an extrude-only move (``split_moves``
"kinematic": Klipper plans each half from rest to rest); splitting no move at all ("none") was
tried and gated next to nothing: most idle intervals worth a 0.22 s stall lie inside one long
single-axis move.

With an input shaper the restart is longer: ``2 * kin_flush_delay``, the largest step window of
any stepper (``restart_s``: 28.6 ms at mzv 30 Hz instead of 2 ms), priced from ``--printer-config``
(``Klipper.enable_fixed_s``); without one the restart is priced without a shaper
(``KLIPPER_RESTART_S``), and with a shaper each line costs ``2 * (window - 1 ms)`` more than
priced (+26.6 ms at mzv 30 Hz): the ``note`` says so.

Measured in Klipper's host in batch mode (``klippy -o``) a line can cost 0.25 s more than this:
the batch flush timer (klippy/extras/motion_queuing.py ``_flush_handler_debug``) moves the last
step time ``BGFLUSH_EXTRA_TIME`` past the flushed moves when it runs between a flush and the next
moves, which depends on where klippy's 4096-byte reads of the file end. A printer's
``_flush_handler`` flushes no further than the MCU's clock + 0.4 s, behind the ~1 s of moves the
host keeps queued, and ``_calc_print_time``'s ``est_print_time + BUFFER_TIME_START`` lies behind
the flushed moves too: no such delay while the host keeps ahead, so it is not priced
(bench/klipper/gatesopt_replay_clock.py measures it in a replay).

What it cannot honour (``note``): an end-late below Klipper's 0.1 s dwell (the pin goes off 0.1 s
after the moves before the line end, whatever end-late asked).

Klipper has no ``M17``: ``klippy/gcode.py`` ``cmd_default`` answers 'Unknown command:"M17"' and
goes on (no dwell, nothing switched). ``SET_STEPPER_ENABLE`` takes one ``STEPPER=`` per command (a
mux command on that parameter, no list), so we write one line per stepper, each with its own
stall. ``M18``/``M84`` go to ``motor_off()``, which disables *all* steppers and sends
``stepper_enable:motor_off`` (homing cleared): never emitted for Klipper.

Planner rules: klippy/toolhead.py -- one ``max_accel`` for every move (M204 S sets it, else
min(P, T)), junctions by ``square_corner_velocity`` (default 5), ``max_velocity`` caps every move
(it and ``max_accel`` have no default there; we use a common 300 mm/s, 3000 mm/s^2), the
Z caps of the kinematics (``max_z_velocity`` / ``max_z_accel`` scaled by move_d / |dz|,
kinematics/cartesian.py ``check_move``), the extruder's ``max_extrude_only_velocity`` /
``max_extrude_only_accel`` on extrude-only moves, Z-with-E moves and retractions (defaults from a
0.4 mm nozzle and 1.75 mm filament: 79.8 mm/s, 798 mm/s^2; kinematics/extruder.py), the
"smoothed" look-ahead of ``max_accel_to_decel`` / ``minimum_cruise_ratio``; a slicer writes a
Klipper printer's square corner velocity as ``machine_max_jerk_x`` (OrcaSlicer).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from ..program import AXES
from . import ExtendedMotorCommand, Firmware, PlannerRules

# DISABLE_STALL_TIME = 0.100 s dwelled before and after the pin change, plus the look-ahead
# flush: 0.22 s measured (DESIGN.md)
KLIPPER_STALL_S = 0.22
KLIPPER_ENABLE_DWELL_S = 2 * 0.100
#: klippy/extras/motion_queuing.py SDS_CHECK_TIME: the least ``kin_flush_delay``
SDS_CHECK_TIME_S = 0.001
#: a full stop and restart at a print speed of 50 mm/s with Klipper's 3000 mm/s^2: v / a
#: (decelerating from v and accelerating back cost v/(2a) each over moving at v)
KLIPPER_STOP_S = 50.0 / 3000.0
#: counted on top of the start-ahead: the longest pre-active time of Klipper's input shapers
#: (klippy/extras/shaper_defs.py) at 20 Hz, 3hump_ei's 58.3 ms, rounded up
SHAPER_LEAD_S = 0.060
#: the clock's restart after a flush (``restart_s``: 2 x kin_flush_delay) where no printer config
#: says which input shaper the printer runs: that of a printer without one (2 x SDS_CHECK_TIME).
#: With a shaper each line then costs 2 x (its window - 1 ms) more than priced (26.6 ms at mzv
#: 30 Hz, measured in Klipper: docs/RESULTS.md); ``--printer-config`` prices the printer's own.
#: Pricing the longest window of Klipper's shapers at 20 Hz instead (2 x ``SHAPER_LEAD_S``, 120 ms
#: a line, the start lead's assumption) was tried: the budget then holds on any printer, but
#: ``--firmware klipper`` gated nothing on two of the three corpus files it was tried on and 4
#: lines on the third (each gate 0.24 s dearer than its saving), so it is not the default.
KLIPPER_RESTART_S = 2 * SDS_CHECK_TIME_S
#: an ``ENABLE=1`` line: the look-ahead flush (a full stop) and the clock's restart
#: ``2 * kin_flush_delay`` later (toolhead ``_calc_print_time``); 17-19 ms measured, no shaper
KLIPPER_ENABLE_STALL_S = round(KLIPPER_STOP_S + KLIPPER_RESTART_S, 4)
#: on top of a printer's own pre-active time (``Klipper.start_lead``): stepcompress may send a step
#: 25 us early (klippy/chelper/stepcompress.c, MAX_STEPCOMPRESS_ERROR), and MCU clock rounding
SHAPER_LEAD_SLACK_S = 25e-6 + 1e-6
INF = math.inf
#: klippy/kinematics/extruder.py PrinterExtruder: without ``max_extrude_only_velocity`` /
#: ``_accel`` in [extruder], max_velocity and max_accel times ``4 nozzle^2 / filament area``
#: (the default cross-section over the filament's); 0.4 mm nozzle, 1.75 mm filament here
KLIPPER_NOZZLE_MM, KLIPPER_FILAMENT_MM = 0.4, 1.75


def kin_flush_delay_s(printer=None) -> float:
    """Klipper's ``kin_flush_delay`` on a printer (``PrinterConfig`` or None: no shaper):
    klippy/extras/motion_queuing.py ``check_step_generation_scan_windows``, the largest of
    ``SDS_CHECK_TIME`` and every stepper's step-generation pre- and post-active time (its input
    shaper's window, klippy/chelper/kin_shaper.c; ``PrinterConfig.window_s``)."""
    if printer is None:
        return SDS_CHECK_TIME_S
    return max([SDS_CHECK_TIME_S] + [w for a in "xyz" for w in printer.window_s(a)])


def restart_s(printer=None) -> float:
    """What the print clock loses after a flush that generates every step
    (``toolhead.flush_step_generation``, as ``SET_STEPPER_ENABLE`` does) when the next move
    comes: ``flush_all_steps`` generates steps up to the last move's end + ``kin_flush_delay``
    (``note_mcu_movequeue_activity``), and the next move, in the "NeedPrime" state, starts at
    ``_calc_print_time``'s ``calc_step_gen_restart``: that + ``kin_flush_delay`` again
    (klippy/toolhead.py, klippy/extras/motion_queuing.py). 2 ms without a shaper; with mzv at
    30 Hz (post-active 14.3 ms) 28.6 ms."""
    return 2.0 * kin_flush_delay_s(printer)


def arc_turn(cur, target, offset, clockwise: bool) -> float:
    """The angle (rad, < 0 clockwise) Klipper turns a G2/G3 through, computed as klippy's
    gcode_arcs.py ``planArc`` does, float for float: from ``cur`` (X, Y) to ``target`` about
    ``cur + offset`` (I, J); 2 pi when the angle comes out exactly 0 and target is cur."""
    r_p, r_q = -offset[0], -offset[1]
    center_p, center_q = cur[0] - r_p, cur[1] - r_q
    rt_a, rt_b = target[0] - center_p, target[1] - center_q
    turn = math.atan2(r_p * rt_b - r_q * rt_a, r_p * rt_a + r_q * rt_b)
    if turn < 0.0:
        turn += 2.0 * math.pi
    if clockwise:
        turn -= 2.0 * math.pi
    if turn == 0.0 and cur[0] == target[0] and cur[1] == target[1]:
        turn = 2.0 * math.pi
    return turn


_G2_RE = re.compile(r"\s*(?:N\d+\s*)?G0*2(?![0-9.])", re.I)
_IJ_RE = re.compile(r"([IJ])\s*([-+]?(?:\d+\.?\d*|\.\d+))", re.I)


def null_arcs(program, rows) -> np.ndarray:
    """Of the arc steps ``rows`` (G2/G3 in the XY plane), those Klipper moves straight to their
    target instead of turning (bool per row): an arc whose target is its start is a full circle
    in Klipper only when ``planArc``'s float angle comes out exactly 0 (``arc_turn``); a hair
    either way and it is a turn of ~0 rad, one segment straight to the target (Orca's spiral lift
    ``G3 Z.. I.. J.. P1``: a 0.4 mm Z move, 0.138 s, where a full circle of 1.2 mm radius takes
    0.2 s; 119 of real_orca230_arcs' 189). The angle is computed from the file's I and J words
    (read from its text as klippy reads them) and the parsed positions (exact as float(text)
    where no G92 offsets X or Y, ``_scan_words.scan_number``)."""
    rows = np.asarray(rows, dtype=np.int64)
    out = np.zeros(len(rows), dtype=bool)
    same = np.all(program.start_mm[rows, :2] == program.end_mm[rows, :2], axis=1)
    for k in np.flatnonzero(same).tolist():
        r = int(rows[k])
        code = program.line_text(int(program.line[r])).split(";", 1)[0]
        words = {a.upper(): float(v) for a, v in _IJ_RE.findall(code)}
        if not words:
            continue
        cw = _G2_RE.match(code) is not None
        cur = (float(program.start_mm[r, 0]), float(program.start_mm[r, 1]))
        turn = arc_turn(cur, cur, (words.get("I", 0.0), words.get("J", 0.0)), cw)
        out[k] = abs(turn) < math.pi
    return out


def default_extrude_ratio(nozzle_mm: float = KLIPPER_NOZZLE_MM, filament_mm: float = KLIPPER_FILAMENT_MM) -> float:
    """Klipper's ``def_max_extrude_ratio`` (extruder.py): 4 nozzle^2 / (pi (filament / 2)^2)."""
    return 4.0 * nozzle_mm ** 2 / (math.pi * (filament_mm / 2.0) ** 2)

#: Klipper's stepper names of the axes on a cartesian printer (printer.cfg sections)
STEPPER_NAMES = {"X": "stepper_x", "Y": "stepper_y", "Z": "stepper_z", "E": "extruder"}

PLANNER = PlannerRules(
    family="klipper", junction="scv", junction_fixed=True,
    junction_note="Klipper: square_corner_velocity", jerk_is_scv=True, one_accel=True,
    m204="klipper", smoothed_lookahead=True, disable_dwell_s=KLIPPER_ENABLE_DWELL_S,
    defaults=dict(max_accel_x=INF, max_accel_y=INF, max_accel_z=100,
                  max_accel_e=3000 * default_extrude_ratio(),
                  max_feed_x=INF, max_feed_y=INF, max_feed_z=15, max_feed_e=300 * default_extrude_ratio(),
                  jerk_x=math.nan, jerk_y=math.nan, jerk_z=math.nan, jerk_e=math.nan,
                  accel_print=3000, accel_travel=3000, accel_retract=3000, accel_to_decel=INF,
                  junction_deviation=math.nan, square_corner_velocity=5.0, max_velocity=300,
                  min_segment_time=0.0, min_feed=0.0, min_travel_feed=0.0,
                  min_cruise_ratio=0.0))

#: Klipper's ``SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=0`` (klippy/extras/stepper_enable.py
#: ``cmd_SET_STEPPER_ENABLE``: a mux command on one ``STEPPER``, ``ENABLE`` an integer, 1 when
#: absent; Klipper 84104bb has no ``STEPPERS=`` list for it: such a line is an error there)
SET_STEPPER_ENABLE = ExtendedMotorCommand("SET_STEPPER_ENABLE", "STEPPER",
                                          tuple((STEPPER_NAMES[m], m) for m in AXES), "ENABLE",
                                          default_enable=1)


@dataclass(frozen=True)
class Klipper(Firmware):
    """Klipper writes one ``SET_STEPPER_ENABLE`` line per stepper."""

    def _lines(self, word: str, motors, enable: int) -> list[str]:
        return [f"SET_STEPPER_ENABLE STEPPER={STEPPER_NAMES[m]} ENABLE={enable}" for m in motors]

    def enable_fixed_s(self, printer=None) -> float:
        """The clock's restart after an ``ENABLE=1`` line's flush: ``2 * kin_flush_delay``
        (``restart_s``); ``enable_restart_s`` without a printer config (``KLIPPER_RESTART_S``:
        no shaper)."""
        return self.enable_restart_s if printer is None else restart_s(printer)

    def disable_fixed_s_at(self, printer=None) -> float:
        """An ``ENABLE=0`` line's two 0.1 s dwells and the restart (``enable_fixed_s``)."""
        if printer is None:
            return self.disable_fixed_s
        return self.disable_fixed_s - self.enable_restart_s + restart_s(printer)

    def start_lead(self, printer=None) -> float:
        """``SHAPER_LEAD_S`` (any of Klipper's shapers at 20 Hz or more) without a printer config;
        with one, its own input shaper's pre-active time: the largest of the shaped axes' (a
        cartesian stepper moves one axis; ``PrinterConfig.window_s``, Klipper's shaper_defs
        pulses time-centred as klippy/chelper/kin_shaper.c does), 0 without ``[input_shaper]``,
        plus ``SHAPER_LEAD_SLACK_S`` (stepcompress may send a step early; MCU clock rounding)."""
        if printer is None:
            return self.start_lead_s
        pre = max(printer.window_s(a)[0] for a in "xyz")
        return pre + SHAPER_LEAD_SLACK_S if pre > 0 else 0.0


DIALECT = Klipper(
    name="klipper", off_word="SET_STEPPER_ENABLE", on_word="SET_STEPPER_ENABLE", merge_motors=False,
    stall_off_s=KLIPPER_STALL_S, stall_on_s=KLIPPER_ENABLE_STALL_S, reenable="exact",
    homing_kept=True, allowed_motors=frozenset(AXES),
    executes=frozenset({"SET_STEPPER_ENABLE", "M18", "M84"}),
    description="Klipper: SET_STEPPER_ENABLE per stepper, ~0.22 s stall off, ~0.02 s on",
    start_lead_s=SHAPER_LEAD_S, split_moves="kinematic",
    enable_is_stop=True, enable_restart_s=KLIPPER_RESTART_S,
    disable_is_stop=True, disable_fixed_s=KLIPPER_ENABLE_DWELL_S + KLIPPER_RESTART_S,
    note=(f"klipper: each motor switched on {SHAPER_LEAD_S * 1e3:g} ms more than the start-ahead "
          "before its next move (an input shaper's steps start before the move; with "
          "--printer-config: that printer's shaper pre-active time); each "
          "SET_STEPPER_ENABLE stops the print head (ENABLE=0 also dwells 2 x 0.1 s, so a motor "
          "goes off >= 0.1 s after its last step whatever the end-late); with an input shaper "
          "every such line restarts 2 x its step window later: priced from --printer-config, "
          "without one as without a shaper (with mzv at 30 Hz 26.6 ms a line more than priced)"),
    rank=2, detect_words=("SET_STEPPER_ENABLE",), detect_rank=10,
    motor_commands=(SET_STEPPER_ENABLE,), planner=PLANNER)
