"""The ``reprap`` dialect: RepRapFirmware.

``M18 X`` waits for standstill and marks X not homed; the next X move is refused by default. X/Y/Z
gating is refused with a message; only E may be gated. The disable stall is a full stop, priced as
a fixed ``marlin.MARLIN_STOP_S`` (Marlin's own is priced per move; RepRapFirmware's planner was
not checked, so its stop is not).

Planner rules: an assumption (RepRapFirmware's compiled defaults were not checked): the
M203 X6000 Y6000 Z300 E10000 (mm/min) example of its G-code documentation, M201 500, M566
900 mm/min (15 mm/s) jerk; M203 and M566 are in mm/min.
"""
from __future__ import annotations

import math

from . import Firmware, PlannerRules
from .marlin import MARLIN_STOP_S

INF = math.inf

PLANNER = PlannerRules(
    family="reprap", junction="jerk", feed_per_min=True,
    defaults=dict(max_accel_x=500, max_accel_y=500, max_accel_z=20, max_accel_e=250,
                  max_feed_x=100, max_feed_y=100, max_feed_z=5, max_feed_e=10000 / 60,
                  jerk_x=15, jerk_y=15, jerk_z=0.3, jerk_e=5,
                  accel_print=500, accel_travel=500, accel_retract=250, accel_to_decel=INF,
                  junction_deviation=math.nan, square_corner_velocity=math.nan, max_velocity=INF,
                  min_segment_time=0.0, min_feed=0.0, min_travel_feed=0.0,
                  min_cruise_ratio=0.0))

DIALECT = Firmware(
    name="reprap", off_word="M18", on_word="M17", merge_motors=True, stall_off_s=MARLIN_STOP_S,
    stall_on_s=0.0, reenable="exact", homing_kept=False, allowed_motors=frozenset({"E"}),
    executes=frozenset({"M17", "M18", "M84"}),
    refused_note="RepRapFirmware's M18 marks X/Y/Z not homed and refuses the next move on them",
    description="RepRapFirmware: M18 waits for standstill and unhomes the axis",
    rank=3, detect_rank=95, no_drain_words=frozenset({"M17"}), stall_is_stop=True, split_moves="kinematic",
    planner=PLANNER)
