"""The ``klipper`` dialect: stock Klipper.

``klippy/extras/stepper_enable.py`` (read at Klipper3d/klipper@0e30b86 and 84104bb):
``cmd_SET_STEPPER_ENABLE`` -> ``set_motors_enable`` runs ``toolhead.dwell(DISABLE_STALL_TIME)``
(0.100 s), flushes the look-ahead (``get_last_move_time``), switches the pin, and dwells 0.100 s
again: ~0.2 s of dwell plus the flush, 0.22 s measured. Klipper has no ``M17``: ``klippy/gcode.py``
``cmd_default`` answers 'Unknown command:"M17"' and goes on (no dwell, nothing switched). Re-enable
is automatic: ``motor_disable`` re-registers ``add_active_callback(self.motor_enable)``, so the
first step of that stepper turns it back on at the step's own print time. ``SET_STEPPER_ENABLE``
takes one ``STEPPER=`` per command (a mux command on that parameter, no list), so we write one line
per stepper, each with its own stall. ``M18``/``M84`` go to ``motor_off()``, which disables *all*
steppers and sends ``stepper_enable:motor_off`` (homing cleared): never emitted for Klipper.

Planner rules: klippy/toolhead.py -- one ``max_accel`` for every move (M204 S sets it, else
min(P, T)), junctions by ``square_corner_velocity`` (default 5), ``max_velocity`` caps every move
(it and ``max_accel`` have no default there; we use a common 300 mm/s, 3000 mm/s^2), the
"smoothed" look-ahead of ``max_accel_to_decel`` / ``minimum_cruise_ratio``; a slicer writes a
Klipper printer's square corner velocity as ``machine_max_jerk_x`` (OrcaSlicer).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..program import AXES
from . import ExtendedMotorCommand, Firmware, PlannerRules

# DISABLE_STALL_TIME = 0.100 s dwelled before and after the pin change, plus the look-ahead
# flush: 0.22 s measured (DESIGN.md)
KLIPPER_STALL_S = 0.22
KLIPPER_ENABLE_DWELL_S = 2 * 0.100
INF = math.inf

#: Klipper's stepper names of the axes on a cartesian printer (printer.cfg sections)
STEPPER_NAMES = {"X": "stepper_x", "Y": "stepper_y", "Z": "stepper_z", "E": "extruder"}

PLANNER = PlannerRules(
    family="klipper", junction="scv", junction_fixed=True,
    junction_note="Klipper: square_corner_velocity", jerk_is_scv=True, one_accel=True,
    m204="klipper", smoothed_lookahead=True, disable_dwell_s=KLIPPER_ENABLE_DWELL_S,
    defaults=dict(max_accel_x=INF, max_accel_y=INF, max_accel_z=100, max_accel_e=INF,
                  max_feed_x=INF, max_feed_y=INF, max_feed_z=15, max_feed_e=INF,
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


DIALECT = Klipper(
    name="klipper", off_word="SET_STEPPER_ENABLE", on_word=None, merge_motors=False,
    stall_off_s=KLIPPER_STALL_S, stall_on_s=KLIPPER_STALL_S, reenable="auto-first-step",
    homing_kept=True, allowed_motors=frozenset(AXES),
    executes=frozenset({"SET_STEPPER_ENABLE", "M18", "M84"}),
    description="Klipper: SET_STEPPER_ENABLE per stepper, ~0.22 s stall, auto re-enable",
    rank=2, detect_words=("SET_STEPPER_ENABLE",), detect_rank=10,
    motor_commands=(SET_STEPPER_ENABLE,), planner=PLANNER)
