"""The ``marlin`` dialect: Marlin 2.x.

``Marlin/src/gcode/control/M17_M18_M84.cpp`` (read at MarlinFirmware/Marlin@008dcb7):
``GcodeSuite::M18_M84()`` with axis words calls ``planner.synchronize()`` -- it waits until the
motion queue is empty, i.e. the head decelerates to a full stop -- and then
``stepper.disable_axis(X_AXIS)``. ``GcodeSuite::M17()`` calls ``stepper.enable_axis`` at once,
without draining, so it takes effect when the command is *parsed*, up to a queue of moves
(``BLOCK_BUFFER_SIZE``, 16 by default) before the moves around it run. A move with X steps
re-enables X by itself when the planner queues it. Disabling marks the axis position untrusted;
moves are refused only with ``NO_MOTION_BEFORE_HOMING`` + ``HOME_AFTER_DEACTIVATE``.

A gating line never splits an extrude-only move here (``split_moves``): an ``M18`` between
the halves of a retraction drains the queue in the middle of it (a stop more, and a retraction
paused for the drain), and what the planner makes of the two halves was not measured; the line goes
after (off) or before (on) the whole move, which only keeps the motor on longer.

The stall of a disable is a full stop, priced per move where it stands (``disable_is_stop``, as
Klipper's ``ENABLE=0`` flush is): ``planner.stop_restart_s`` at the line -- v / (2 a) to stop from
the speed the planner reaches there plus v / (2 a) to get back to it, with the file's own limits
-- and nothing on top (``disable_fixed_s`` 0: ``M18`` dwells nowhere, the drain is the stop). A
stop where the head is nearly at rest (a retraction, a layer change) costs next to nothing, one in
the middle of a fast infill line up to v / a. Before this (2026-11-26) every ``M18`` was charged
``MARLIN_STOP_S`` = 0.05 s, an assumed v / a (50 mm/s at 1000 mm/s^2): the planner measured the
stops where gating put them far lower (cura413_star_triangles20: 20.7 s charged, 0.28 s added to
the print), so the 1 % budget left most of the saving unused. ``MARLIN_STOP_S`` stays the
constant the gating kernel prices first (``GatingOptions.stall_off_s``); the per-move price
replaces it before any choice (``gating.problem._per_move_stalls``), and the verifier prices the
output the same way (``verify.energy.stall_s``).

Planner rules (``gatesopt.limits``, ``gatesopt.planner``): Marlin 2.x Configuration.h defaults
(DEFAULT_MAX_FEEDRATE {300,300,5,25}, DEFAULT_MAX_ACCELERATION {3000,3000,100,10000},
DEFAULT_ACCELERATION / RETRACT / TRAVEL 3000, CLASSIC_JERK off -> JUNCTION_DEVIATION_MM 0.013,
DEFAULT_EJERK 5); a slicer's jerk or junction-deviation settings say which junction rule runs.
"""
from __future__ import annotations

import math

from ..program import AXES
from . import Firmware, PlannerRules

MARLIN_STOP_S = 0.05
INF = math.inf

PLANNER = PlannerRules(
    family="marlin", junction="deviation", config_picks_junction=True,
    defaults=dict(max_accel_x=3000, max_accel_y=3000, max_accel_z=100, max_accel_e=10000,
                  max_feed_x=300, max_feed_y=300, max_feed_z=5, max_feed_e=25,
                  jerk_x=10, jerk_y=10, jerk_z=0.3, jerk_e=5,
                  accel_print=3000, accel_travel=3000, accel_retract=3000, accel_to_decel=INF,
                  junction_deviation=0.013, square_corner_velocity=math.nan, max_velocity=INF,
                  min_segment_time=0.0, min_feed=0.0, min_travel_feed=0.0,
                  min_cruise_ratio=0.0))

DIALECT = Firmware(
    name="marlin", off_word="M18", on_word="M17", merge_motors=True, stall_off_s=MARLIN_STOP_S,
    stall_on_s=0.0, reenable="early-by-queue", homing_kept=True, allowed_motors=frozenset(AXES),
    executes=frozenset({"M17", "M18", "M84"}),
    description="Marlin 2.x: M18 drains the queue (full stop), M17 enables at parse time",
    rank=1, detect_words=("M17", "M18"), detect_rank=20,
    no_drain_words=frozenset({"M17"}), split_moves="kinematic", planner=PLANNER,
    disable_is_stop=True, disable_fixed_s=0.0)   # the drain is the stop: priced per move
