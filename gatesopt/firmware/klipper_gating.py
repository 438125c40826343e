"""The ``klipper-gating`` dialect: Klipper with gatesopt's extras module (issue 34).

integrations/klipper/gatesopt_gating.py (its protocol: integrations/klipper/README.md) switches a
stepper's enable pin at print time, with no flush and no dwell. gatesopt writes one line per idle
moment, right after the last move that steps the motors before their idle intervals::

    GATESOPT_GATE STEPPERS=stepper_x[,stepper_y]

No move is split and no "on" line exists: for each named stepper S the module switches the pin
off at ``t_end + off_delay`` (``t_end``: the end of the moves queued before the line) and on at
``t_next - on_lead`` (``t_next``: the start of the next move that steps S), where

    off_delay = post + end_late + 1 us        on_lead = pre + start_ahead + 25 us + 1 us

(``pre``/``post``: S's step window, the input shaper's, ``gatesopt.shaper``; 25 us: Klipper's
``MAX_STEPCOMPRESS_ERROR``; 1 us: clock rounding) -- if rule A and rule B hold, with ``gap`` the sum
of the moves' ``min_move_t`` (distance over speed, klippy/toolhead.py ``Move``) between the line
and the activating move, ``spacing`` the module's ``min_pin_spacing`` (default 0.1 s, Klipper's
own lead of one pin change's message: the module's docstring, "Pin spacing", cites the source) and
``K`` its ``pin_queue_slots`` (default 2: two changes of a pin queued on the MCU, "Pin queue"):

- rule A: ``gap >= off_delay + on_lead + floor``, ``floor`` = ``min_off_time`` (K = 2) or
  ``max(min_off_time, spacing)`` (K = 1);
- rule B, between S's previous gated interval and this one: K = 1, ``spacing`` between the
  previous "on" and this "off": ``on_lead_prev + (the min_move_t from the move that ended S's
  previous gated interval to the line) + off_delay >= spacing``; K = 2, ``spacing`` between the
  previous "off" and this "off" and between the previous "on" and this "on" (min_move_t sums
  from line to line and from activating move to activating move).

What this module declares to the gating model (``Schedule``; ``gatesopt.gating`` honours it, the
verifier derives the intervals from the lines with its own code): the firmware's own delay and lead
per motor, rule A's floor ``min_off_s``, rule B's ``spacing`` and ``pin_queue_slots`` (all from the
printer.cfg's ``[gatesopt_gating]`` section, the module's defaults without one), the lower bound of
``min_move_t`` (``planner.min_move_time_s``: L / F, arcs as
Klipper's chords), no more than ``MAX_OFF_DELAY_S`` of delay, and the planner time model with
Klipper's rules and the printer's limits (``--printer-config``), so that reported times and
off-times are what Klipper plans.

Klipper's own lines still do what they do on stock Klipper (the ``klipper`` dialect): a file's
``SET_STEPPER_ENABLE``, ``M18``, ``M84`` dwell 0.22 s; ``GATESOPT_GATE`` never stalls and never
drains the queue. Steppers: those of a cartesian printer (stepper_x moves X alone, and so on);
the module refuses an extruder, so E is not gated.
"""
from __future__ import annotations

from dataclasses import dataclass

from . import ExtendedMotorCommand, Firmware, FirmwareError, Schedule
from .klipper import KLIPPER_STALL_S, PLANNER, STEPPER_NAMES

# the module's constants (integrations/klipper/gatesopt_gating.py)
CLOCK_SLACK_S = 1e-6          # pin and step times are MCU clocks: rounding
STEP_EARLY_S = 25e-6          # stepcompress may send a step this much early (MAX_STEPCOMPRESS_ERROR)
PIN_SPACING_S = 0.100         # the module's DEFAULT_PIN_SPACING_S: between two changes of one pin
PIN_QUEUE_SLOTS = 2           # the module's DEFAULT_PIN_QUEUE_SLOTS: changes of one pin queued at once
MAX_OFF_DELAY_S = 0.050       # the module skips an interval whose off would come later than this
#: issue 34: the module adds no time (no flush, no dwell, no split move), so what a rotation adds to
#: the planned print is all klipper-gating adds; --rotate auto keeps 0 deg where the planner says a
#: rotation adds more than this (a travel into or out of the turned print, priced by the planner)
MAX_ROTATION_ADDED_TIME_PCT = 0.05
GATEABLE = ("X", "Y", "Z")    # kinematic steppers of a cartesian printer
AXIS_OF = {"X": "x", "Y": "y", "Z": "z"}   # which shaped axis each stepper is active on (cartesian)

def kinematics_refusal(source: str, kinematics: str) -> str:
    """Why klipper-gating does not write for a printer that is not cartesian.

    The module follows Klipper's kinematics (a stepper is active for a move with a nonzero
    direction on any axis it is active on: itersolve ``check_active``). On corexy both stepper_x
    (A) and stepper_y (B) are active on x and y, so each is idle only while the head does not move
    in XY at all (Z-only and extrude-only moves, dwells), and then both together; a delta's towers
    likewise. gatesopt's gating problem and energy profile are per axis (the X motor steps when X
    moves), not per motor A/B, so it cannot say which of those moments pay: it refuses."""
    if kinematics in ("corexy", "corexz", "hybrid_corexy", "hybrid_corexz", "markforged"):
        how = ("both stepper_x (A) and stepper_y (B) step for every X or Y move, so each is idle "
               "only while the head stands still in XY, and gatesopt's gating model and energy "
               "profile are per axis (X, Y), not per motor A/B")
    else:
        how = ("its steppers do not each move one axis alone, and gatesopt's gating model and "
               "energy profile are per axis (X, Y, Z)")
    return (f"{source}: kinematics {kinematics!r}: klipper-gating models cartesian printers only: "
            f"{how}. The module itself follows Klipper's kinematics, but gatesopt writes no "
            f"GATESOPT_GATE lines for this printer")


# every stepper name is read (an extruder too, which the module refuses: the verifier then names it)
GATESOPT_GATE = ExtendedMotorCommand(
    "GATESOPT_GATE", "STEPPERS", tuple((STEPPER_NAMES[m], m) for m in STEPPER_NAMES),
    enable_param="", default_enable=0, lists=True)


@dataclass(frozen=True)
class KlipperGating(Firmware):
    """One ``GATESOPT_GATE`` line per moment, motors merged; no on line."""

    def _lines(self, word: str, motors, enable: int) -> list[str]:
        if enable:
            return []
        return [f"{word} STEPPERS={','.join(STEPPER_NAMES[m] for m in motors)}"]

    def gating_defaults(self, printer=None) -> dict:
        """The module's own options from the printer's ``[gatesopt_gating]`` section (start-ahead,
        end-late, the steppers it may gate), for ``GatingOptions.for_firmware``."""
        if printer is None or printer.gating is None:
            return {}
        sec = printer.gating
        letters = {v: k for k, v in STEPPER_NAMES.items()}
        unknown = [s for s in sec.steppers if letters.get(s) not in GATEABLE]
        if unknown:
            raise FirmwareError(f"{printer.source}: [gatesopt_gating] steppers: {', '.join(unknown)} "
                                f"cannot be gated (gatesopt gates {', '.join(STEPPER_NAMES[m] for m in GATEABLE)})")
        return dict(start_ahead_s=sec.start_ahead_s, end_late_s=sec.end_late_s,
                    gateable=tuple(letters[s] for s in sec.steppers))

    def schedule(self, printer=None, *, start_ahead_s: float, end_late_s: float) -> Schedule:
        if printer is not None and printer.kinematics not in (None, "cartesian"):
            raise FirmwareError(kinematics_refusal(printer.source, printer.kinematics))
        pre, post = [0.0] * 4, [0.0] * 4
        if printer is not None:
            for i, m in enumerate("XYZ"):
                pre[i], post[i] = printer.window_s(AXIS_OF[m])
        off_extra = tuple(p + CLOCK_SLACK_S for p in post)
        on_extra = tuple(p + STEP_EARLY_S + CLOCK_SLACK_S for p in pre)
        worst = max(off_extra[:3]) + end_late_s
        if worst > MAX_OFF_DELAY_S:
            raise FirmwareError(f"the input shaper's window after a move ({max(post):.4f} s) plus end-late "
                                f"({end_late_s:.4f} s) is {worst:.4f} s, more than the module's "
                                f"{MAX_OFF_DELAY_S} s: it would gate nothing")
        sec = printer.gating if printer is not None else None
        spacing = sec.min_pin_spacing_s if sec is not None else PIN_SPACING_S
        slots = sec.pin_queue_slots if sec is not None else PIN_QUEUE_SLOTS
        min_off = sec.min_off_time_s if sec is not None else 0.0
        if slots == 1:      # one change in flight: an interval's own on waits for its off
            min_off = max(min_off, spacing)
        arc = printer.arc_resolution_mm if printer is not None and printer.arc_resolution_mm else 1.0
        return Schedule(off_delay_s=off_extra, on_lead_s=on_extra, min_off_s=min_off,
                        min_spacing_s=spacing, pin_queue_slots=slots, arc_segment_mm=arc)


DIALECT = KlipperGating(
    name="klipper-gating", off_word="GATESOPT_GATE", on_word=None, merge_motors=True,
    stall_off_s=0.0, stall_on_s=0.0, reenable="scheduled", homing_kept=True,
    allowed_motors=frozenset(GATEABLE),
    executes=frozenset({"GATESOPT_GATE", "SET_STEPPER_ENABLE", "M18", "M84"}),
    refused_note="the module switches kinematic steppers only (an extruder is refused)",
    description="Klipper with gatesopt's module: GATESOPT_GATE after the last move, no stall",
    rank=4, detect_words=("GATESOPT_GATE",), detect_rank=5,
    motor_commands=(GATESOPT_GATE,), no_drain_words=frozenset({"GATESOPT_GATE"}),
    word_stalls=(("SET_STEPPER_ENABLE", KLIPPER_STALL_S, KLIPPER_STALL_S),
                 ("M18", KLIPPER_STALL_S, KLIPPER_STALL_S), ("M84", KLIPPER_STALL_S, KLIPPER_STALL_S)),
    time_model="planner", planner=PLANNER, rotation_max_added_time_pct=MAX_ROTATION_ADDED_TIME_PCT)
