"""Time models: the paper's T = L / F, and a firmware planner model with acceleration.

``durations(program, model="paper")`` returns ``program.duration_s`` unchanged: 3DGates
(ASPLOS'17) Eq. 2, T_i = L_i / F_i, which reproduces the paper. ``model="planner"`` returns what
the printer's motion planner does instead (``plan``):

* every move follows a trapezoidal velocity profile: accelerate at a[k] from its entry speed,
  cruise at its nominal speed, decelerate to its exit speed (a triangle when it is too short);
* entry/exit speeds come from look-ahead over the queue: a backward pass (each entry low enough
  to brake to the next) then a forward pass (each entry reachable from the previous), as in
  Marlin's ``planner.cpp`` (``reverse_pass`` / ``forward_pass`` / ``recalculate_trapezoids``) and
  Klipper's ``toolhead.py`` (``LookAheadQueue.flush``); the kernel is ``_planner_kernel``;
* the speed at the junction of two moves is limited by the firmware's junction rule:
  - classic jerk (Marlin ``CLASSIC_JERK``, Prusa firmware, and what PrusaSlicer's estimator
    simulates, ``GCodeProcessor::process_G1``): per axis the speed change across the junction may
    not exceed the axis jerk; coasting vs. reversal is told apart exactly as Marlin does, and a move
    may start from / stop to rest at its "safe speed" (``safe_speed``: every axis within its jerk);
  - junction deviation (Marlin 2 default): v^2 = a * JD * sin(theta/2) / (1 - sin(theta/2)), plus
    Marlin's small-segment limit v^2 <= a * L / theta (``JD_HANDLE_SMALL_SEGMENTS``);
  - Klipper square_corner_velocity (``Move.calc_junction``): JD = scv^2 (sqrt 2 - 1) / a with the
    same formula for both moves, the centripetal limits ``delta_v2 * tan(theta/2) / 4`` and the
    extruder's ``instant_corner_velocity`` (1 mm/s) on the change of E per mm; extruder-only moves
    are not kinematic on Klipper and start and end at rest;
* per move: nominal speed = F clamped by each axis's max feedrate (M203) and Klipper's
  max_velocity, raised to the minimum feedrate (M205 S/T), lowered by the minimum segment time
  (M205 B) where the file sets one (Marlin applies it only while its queue runs low, SLOWDOWN;
  here it applies to every move -- an upper bound; Klipper has none); acceleration = print
  (M204 P) for moves with E steps, travel (M204 T) without, retract (M204 R) for extruder-only
  moves, each capped per axis by M201. Klipper: one max_accel, the Z caps scaled by move_d / |dz|
  (kinematics/cartesian.py ``check_move``), the extruder's max_extrude_only_velocity / _accel
  on extrude-only moves (which keep their requested speed over max_velocity), Z-with-E moves and
  retractions only (kinematics/extruder.py ``check_move``), the junction deviation of the
  toolhead's max_accel times each move's own acceleration (toolhead.py ``Move.calc_junction``);
* arcs (G2/G3) are one step here but the firmware cuts them into ~1 mm segments: their nominal
  speed is capped by the junction speed between two such segments (turn angle s / R). Klipper
  (klippy/extras/gcode_arcs.py ``planArc``): ``n = max(1, floor(L / 1 mm))`` chords of the
  sweep / n turn each, planned as moves of their own: the arc is as long as its chords, meets
  its neighbours along its first and last chord, and runs at the average speed of one chord
  that starts and ends at the chords' junction speed and accelerates in between (not the
  junction speed itself: a 1.2 mm radius circle's chords reach 50 mm/s between 23.7 mm/s
  junctions); an arc whose target is its start is a straight move where Klipper's float angle
  is not exactly 0 (``firmware.klipper.null_arcs``);
* non-motion steps keep ``program.duration_s``; dwells, heat waits, homing and the motor
  instructions that drain the queue (Marlin ``M18``/``M84``, Klipper ``SET_STEPPER_ENABLE``; not
  the paper's ``S0``/``S1`` nor ``M17``, see ``drains_queue``) bring the head to rest: the moves
  before them stop, the moves after them start from rest.
* ``Plan.stop_cost_s`` prices a forced stop (a gate on stock firmware) by re-planning a window
  around it; ``Plan.time_at_fraction`` / ``fraction_at_time`` place a split inside a move.

Limits (and their changes along the file) come from ``gatesopt.limits.machine_limits``.

Klipper's smoothed look-ahead (``max_accel_to_decel``: the peak speed of short moves capped as if
they accelerated at accel_to_decel; ``klipper_cruise_cap``) is applied where the file sets
``SET_VELOCITY_LIMIT ACCEL_TO_DECEL``; elsewhere the printer.cfg value is unknown and none is
applied (Klipper's own default is half the acceleration, which would lengthen times by ~1 %
on the corpus's Klipper files). Not modelled: input shaping, pressure advance, S-curve
acceleration, and the firmware's finite queue (Marlin: 16 blocks; the look-ahead here spans every move between two stops). Where Marlin
and PrusaSlicer's estimator differ we follow Marlin: the safe speed is min_a jerk_a / |u_a|
(PrusaSlicer: min_a jerk_a), so diagonal starts and stops are a little faster than PrusaSlicer's.

Units: ``_mm``, ``_mm_s``, ``_mm_s2``, ``_s`` as in ``program.py``.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from . import _planner_kernel as _k
from . import firmware as fwmod
from .firmware import klipper as fwklipper
from ._text import code_words
from .errors import GatesoptError
from .limits import MachineLimits, machine_limits
from .program import E, MOTION_KINDS, Kind, Program, X, Y, Z

TIME_MODELS = ("paper", "planner")
ARC_SEGMENT_MM = _k.ARC_SEGMENT_MM


class TimeModelError(GatesoptError, ValueError):
    """An unknown time model name."""


# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Plan:
    """Per-step velocity profile of a Program under the planner model.

    For a motion step: accelerate for ``accel_s`` from ``entry_mm_s`` to ``cruise_mm_s`` (the peak
    speed: the nominal speed, or lower for a triangle profile), cruise ``cruise_s``, decelerate
    ``decel_s`` to ``exit_mm_s``, all at ``accel_mm_s2``. Other steps: their ``duration_s`` at rest.
    """

    duration_s: np.ndarray      # (n_steps,)
    entry_mm_s: np.ndarray
    cruise_mm_s: np.ndarray     # peak speed reached (= nominal for a trapezoid)
    exit_mm_s: np.ndarray
    accel_s: np.ndarray
    cruise_s: np.ndarray
    decel_s: np.ndarray
    accel_mm_s2: np.ndarray     # 0 for non-motion steps
    length_mm: np.ndarray
    nominal_mm_s: np.ndarray    # highest cruise speed the move may reach after the limits (and Klipper's
                                # smoothing cap); 0 for non-motion steps
    limits: MachineLimits = field(repr=False)
    free_mm_s: np.ndarray = field(repr=False, default=None)   # nominal speed before Klipper's
                                # smoothing cap (the limits alone); 0 for non-motion steps
    # kernel inputs kept for stop_cost_s (moves only)
    move_step: np.ndarray = field(repr=False, default=None)      # step index of each move
    step_move: np.ndarray = field(repr=False, default=None)      # move index of each step (-1: none)
    _vj: np.ndarray = field(repr=False, default=None)
    _vj_free: np.ndarray = field(repr=False, default=None)
    _barrier: np.ndarray = field(repr=False, default=None)    # per step: drains the queue
    _safe: np.ndarray = field(repr=False, default=None)
    _stop_before: np.ndarray = field(repr=False, default=None)

    @property
    def total_s(self) -> float:
        return float(self.duration_s.sum())

    @property
    def firmware(self) -> str:
        return self.limits.firmware

    # -- positions inside a step ----------------------------------------------------------------
    def time_at_fraction(self, step, fraction):
        """Time (s) from the start of ``step`` until the fraction ``fraction`` (0..1) of its length
        is done. Scalars or arrays (broadcast)."""
        step, f = np.broadcast_arrays(np.asarray(step, dtype=np.int64), np.asarray(fraction, dtype=float))
        f = np.clip(f, 0.0, 1.0)
        L = self.length_mm[step]
        d = f * L
        v0, vc, a = self.entry_mm_s[step], self.cruise_mm_s[step], self.accel_mm_s2[step]
        ta, tc = self.accel_s[step], self.cruise_s[step]
        d_acc = 0.5 * (v0 + vc) * ta
        d_cru = vc * tc
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = np.where(a > 0, (np.sqrt(np.maximum(v0 * v0 + 2 * a * d, 0.0)) - v0) / a, 0.0)
            t2 = ta + np.where(vc > 0, (d - d_acc) / vc, 0.0)
            # decelerating: count back from the end (stable where the speed is low)
            v1 = self.exit_mm_s[step]
            rest = np.maximum(L - d, 0.0)
            t3 = (ta + tc + self.decel_s[step]
                  - np.where(a > 0, (np.sqrt(v1 * v1 + 2 * a * rest) - v1) / a, 0.0))
        t = np.where(d <= d_acc, t1, np.where(d <= d_acc + d_cru, t2, t3))
        moving = (a > 0) & (L > 0)
        t = np.where(moving, t, f * self.duration_s[step])
        t = np.minimum(t, self.duration_s[step])
        return t if t.ndim else float(t)

    def fraction_at_time(self, step, t_into_step):
        """Inverse of ``time_at_fraction``: the fraction of ``step``'s length done after
        ``t_into_step`` seconds (clipped to the step)."""
        step, t = np.broadcast_arrays(np.asarray(step, dtype=np.int64), np.asarray(t_into_step, dtype=float))
        dur = self.duration_s[step]
        t = np.clip(t, 0.0, dur)
        L = self.length_mm[step]
        v0, vc, a = self.entry_mm_s[step], self.cruise_mm_s[step], self.accel_mm_s2[step]
        ta, tc = self.accel_s[step], self.cruise_s[step]
        d_acc = 0.5 * (v0 + vc) * ta
        d_cru = vc * tc
        s1 = v0 * t + 0.5 * a * t * t
        s2 = d_acc + vc * (t - ta)
        u = t - ta - tc
        s3 = d_acc + d_cru + vc * u - 0.5 * a * u * u
        d = np.where(t <= ta, s1, np.where(t <= ta + tc, s2, s3))
        with np.errstate(divide="ignore", invalid="ignore"):
            f = np.where(L > 0, d / L, 0.0)
            f = np.where((a > 0) & (L > 0), f, np.where(dur > 0, t / dur, 1.0))
        f = np.clip(f, 0.0, 1.0)
        return f if f.ndim else float(f)

    # -- forced stops -----------------------------------------------------------------------------
    def stop_cost_s(self, step, firmware: str | None = None):
        """Time (s) a forced full stop at the start of ``step`` costs (scalar or array).

        Marlin ``M18``/``M84`` with axes call ``planner.synchronize()``: the queue drains, the head
        decelerates to rest and accelerates again; the cost is the re-planned time with the stop
        minus the time without it. Klipper ``SET_STEPPER_ENABLE`` flushes the look-ahead the same
        way and dwells 2 x 0.1 s on top (the dialect's ``PlannerRules.disable_dwell_s``).
        ``firmware``: a dialect of ``gatesopt.firmware`` ("marlin", "reprap", "klipper", or
        "3dgates": the paper's patch, no stop, 0); default: the file's.

        ``step`` may be a move (the stop is added before it; 0 if the head is at rest there anyway)
        or a step that itself drains the queue, such as a motor instruction already in the file
        (then: what that stop costs against the same program without it; 0 if something else
        stops the head in the same gap). With Klipper's ACCEL_TO_DECEL smoothing the window keeps
        the plan's smoothed speed caps (an approximation near the stop). Never negative: under classic jerk a move may leave at its
        own safe speed and the next start at its own, which can beat the speed they share at a
        junction; a stop is not credited with that.
        """
        fw = fwmod.get(firmware or self.limits.firmware)
        steps = np.atleast_1d(np.asarray(step, dtype=np.int64))
        if not fw.drains_on_disable:
            out = np.zeros(len(steps))
        else:
            moves = self.step_move[steps].copy()
            n_moves = len(self.move_step)
            other = moves < 0
            if other.any():
                # a non-motion step: the stop falls before the next move, and is removable only
                # if this step is the one thing that drains the queue between the two moves
                nxt = np.searchsorted(self.move_step, steps[other], side="right")
                nb = np.concatenate([[0], np.cumsum(self._barrier)])
                prev_step = np.where(nxt > 0, self.move_step[np.maximum(nxt - 1, 0)], -1)
                next_step = np.where(nxt < n_moves, self.move_step[np.minimum(nxt, n_moves - 1)], -1)
                n_drain = nb[np.maximum(next_step, 0)] - nb[prev_step + 1]
                ok = (nxt < n_moves) & (nxt > 0) & self._barrier[steps[other]] & (n_drain == 1)
                moves[other] = np.where(ok, nxt, -1)
            else:
                ok = None
            # a move the head already reaches from rest (for another reason) costs nothing
            is_move = ~other
            already = np.zeros(len(steps), dtype=bool)
            already[is_move] = self._stop_before[moves[is_move]]
            moves[already] = -1
            ms = self.move_step
            out = _k.stop_costs(moves, self.length_mm[ms], self.accel_mm_s2[ms], self.nominal_mm_s[ms],
                                self._vj, self._vj_free, self._safe, self._stop_before,
                                self.entry_mm_s[ms], self.exit_mm_s[ms])
            if fw.planner is not None and fw.planner.disable_dwell_s:
                out = out + fw.planner.disable_dwell_s
        return out if np.ndim(step) else float(out[0])


# ------------------------------------------------------------------------------------------------
def durations(program: Program, model: str = "paper", limits: MachineLimits | None = None) -> np.ndarray:
    """One duration (s) per Program step under ``model`` ("paper": ``program.duration_s`` unchanged,
    3DGates Eq. 2; "planner": ``plan(program, limits).duration_s``)."""
    if model == "paper":
        return program.duration_s
    if model == "planner":
        return planned_durations_s(program, limits)
    raise TimeModelError(f"unknown time model {model!r} (choose from {', '.join(TIME_MODELS)})")


def arc_tangents(program: Program, steps: np.ndarray, L: np.ndarray, klipper: bool = False,
                 backwards: bool = False):
    """Unit tangents (X Y Z E per mm of path) at the start and end of the arcs ``steps``, the
    signed turn angle of one firmware arc segment (ARC_SEGMENT_MM / R; CCW positive), one
    segment's length, and the arcs' path lengths.

    ``klipper``: as klippy/extras/gcode_arcs.py ``planArc`` cuts them: ``n = max(1, floor(L /
    resolution))`` chords of sweep / n each (``L`` the helix length, Klipper's ``mm_of_travel``),
    Z and E split evenly; the "tangents" are then the first and the last chord's directions (the
    start tangent turned by half a chord's angle, the end tangent turned back by it), the segment
    a chord, the path the sum of the chords.

    ``backwards``: the arcs printed from their end to their start (a re-ordered curve, priced by
    ``ordering.curve_time``): turning the other way, Z the other way, E still forward."""
    d = np.array(program.end_mm[steps] - program.start_mm[steps], dtype=float)
    c = program.arc_center_mm[steps]
    sign = np.where(program.arc_ccw[steps], 1.0, -1.0)
    ends = (program.start_mm[steps, :2], program.end_mm[steps, :2])
    if backwards:
        sign, ends = -sign, ends[::-1]
        d[:, Z] = -d[:, Z]
    rs = ends[0] - c
    R = np.maximum(np.hypot(rs[:, 0], rs[:, 1]), 1e-9)
    if klipper:
        n_seg = np.maximum(1.0, np.floor(L / ARC_SEGMENT_MM))
        sweep = np.sqrt(np.maximum(L * L - d[:, Z] ** 2, 0.0)) / R
        theta = sweep / n_seg
        chord_xy = 2.0 * R * np.sin(theta / 2.0)
        seg = np.hypot(chord_xy, d[:, Z] / n_seg)
        seg = np.where(seg > 0, seg, np.maximum(L / n_seg, 1e-12))
        turn = (0.5 * theta, -0.5 * theta)
        xy_frac = chord_xy / seg
        dz_frac, de_frac = d[:, Z] / n_seg / seg, d[:, E] / n_seg / seg
        path = n_seg * seg
        phi = np.where(n_seg > 1, sign * theta, 0.0)     # one chord: a line, no inner junction
    else:
        seg = np.minimum(ARC_SEGMENT_MM, L)
        turn = (np.zeros(len(steps)), np.zeros(len(steps)))
        xy_frac = np.sqrt(np.maximum(L * L - d[:, Z] ** 2, 0.0)) / L   # XY share of the path
        dz_frac, de_frac = d[:, Z] / L, d[:, E] / L
        path = L
        phi = sign * seg / R
    out = []
    for pt, rot in zip(ends, turn):
        r = pt - c
        n = np.maximum(np.hypot(r[:, 0], r[:, 1]), 1e-12)
        tx, ty = -sign * r[:, 1] / n, sign * r[:, 0] / n
        cs, sn = np.cos(sign * rot), np.sin(sign * rot)
        u = np.empty((len(steps), 4))
        u[:, X] = (tx * cs - ty * sn) * xy_frac
        u[:, Y] = (tx * sn + ty * cs) * xy_frac
        u[:, Z] = dz_frac
        u[:, E] = de_frac
        out.append(u)
    return out[0], out[1], phi, seg, path


def drains_queue(program: Program) -> np.ndarray:
    """(n_steps,) bool: steps that bring the motion queue to rest before the next move.

    Dwells (G4: Marlin ``dwell()`` synchronizes first), heat waits and homing always do. A motor
    instruction does if the firmware drains for it: Marlin ``M18``/``M84`` (``planner.synchronize()``),
    Klipper ``SET_STEPPER_ENABLE`` (a look-ahead flush); the paper's ``S0``/``S1`` and Marlin's
    ``M17`` do not (the dialects' ``no_drain_words``, ``gatesopt.firmware.no_drain_words``).
    """
    no_drain = fwmod.no_drain_words()
    kind = program.kind
    out = np.isin(kind, np.asarray((Kind.DWELL, Kind.WAIT, Kind.HOME), dtype=kind.dtype))
    for r in np.flatnonzero(kind == Kind.MOTOR).tolist():
        i = int(program.line[r])
        words = code_words(program.data[program.line_start[i]:program.line_start[i + 1]])
        out[r] = not (words and words[0] in no_drain)
    return out


def move_geometry(program: Program, klipper: bool) -> tuple[np.ndarray, np.ndarray]:
    """(n_steps,) path length and arc flag of every step as the firmware moves it: under
    Klipper a target-is-start arc is a straight move to its target (``null_arcs``)."""
    length = np.array(program.length_mm, dtype=float)
    is_arc = program.kind == Kind.ARC
    if klipper and is_arc.any():
        rows = np.flatnonzero(is_arc)
        null = rows[fwklipper.null_arcs(program, rows)]
        if len(null):
            dd = program.end_mm[null] - program.start_mm[null]
            straight = np.sqrt((dd[:, :3] ** 2).sum(axis=1))
            length[null] = np.where(straight > 0, straight, np.abs(dd[:, 3]))
            is_arc[null] = False
    return length, is_arc


def plan(program: Program, limits: MachineLimits | None = None) -> Plan:
    """The planner time model for every step of ``program`` (see module docstring)."""
    (dur, idx, limits, length, entry, exit_, peak, t_acc, t_cruise, t_dec, acc, vnom, vfree, vj,
     vj_free, safe, stop_before, barrier) = _profile(program, limits)
    n, m = program.n_steps, len(idx)
    # the speeds the trapezoids use (Klipper's set_junction clips them to the cruise cap)
    entry = np.minimum(entry, vnom)
    exit_ = np.minimum(exit_, vnom)

    def full(vals, fill=0.0):
        out = np.full(n, fill)
        out[idx] = vals
        return out

    step_move = np.full(n, -1, dtype=np.int64)
    step_move[idx] = np.arange(m)
    return Plan(duration_s=dur, entry_mm_s=full(entry), cruise_mm_s=full(peak), exit_mm_s=full(exit_),
                accel_s=full(t_acc), cruise_s=full(t_cruise), decel_s=full(t_dec),
                accel_mm_s2=full(acc), length_mm=length,
                nominal_mm_s=full(vnom), limits=limits, free_mm_s=full(vfree), move_step=idx,
                step_move=step_move,
                _vj=vj, _vj_free=vj_free, _safe=safe, _stop_before=stop_before, _barrier=barrier)


def planned_durations_s(program: Program, limits: MachineLimits | None = None) -> np.ndarray:
    """``plan(program, limits).duration_s`` without the rest of the ``Plan`` (its per-step speed
    arrays): what the time guard and the reports' print times read (the same computation)."""
    return _profile(program, limits)[0]


def _profile(program: Program, limits: MachineLimits | None):
    """The planner's computation (``plan``): per step its duration, and per move the kernels'
    speeds and times."""
    if limits is None:
        limits = machine_limits(program)
    kind = program.kind
    klipper = limits.firmware == "klipper"
    length, is_arc = move_geometry(program, klipper)
    motion = np.isin(kind, np.asarray(MOTION_KINDS, dtype=kind.dtype)) & (length > 0)
    idx = np.flatnonzero(motion)
    m = len(idx)
    L = length[idx]

    # limits in force at each move: one table row per limit-changing line
    table, regime = limits.regimes_at(program.line[idx])

    d = program.end_mm[idx] - program.start_mm[idx]
    arc = is_arc[idx]
    arc_row = np.full(m, -1, dtype=np.int64)
    ai = np.flatnonzero(arc)
    arc_row[ai] = np.arange(len(ai))
    arc_us, arc_ue, arc_phi, arc_seg, arc_path = arc_tangents(program, idx[ai], L[ai], klipper)
    if klipper and len(ai):
        L[ai] = arc_path            # Klipper moves along the chords
        length[idx[ai]] = arc_path

    # stops: a dwell / wait / home step, or a motor instruction that drains the queue, between
    # two moves brings the head to rest
    barrier = drains_queue(program)
    nb = np.cumsum(barrier)
    stop_before = np.ones(m, dtype=np.bool_)
    if m > 1:
        stop_before[1:] = nb[idx[1:]] != nb[idx[:-1]]

    vnom, acc, safe, vj, vj_free = _k.prepare_moves(
        _k.JUNCTION_CODE[limits.junction], d, L, program.feed_mm_s[idx].astype(float),
        arc_row, arc_us, arc_ue, arc_phi, arc_seg, stop_before, regime, np.ascontiguousarray(table))
    if m and not np.all(np.isfinite(acc) & (acc > 0)):
        raise GatesoptError(f"{program.source}: no finite positive acceleration for some moves; "
                            f"check the machine limits (profile {limits.profile})")
    if m and not np.all(np.isfinite(vnom) & (vnom > 0)):
        raise GatesoptError(f"{program.source}: no finite positive speed for some moves; "
                            f"check the feedrates and machine limits (profile {limits.profile})")

    vfree = vnom
    rules = fwmod.planner_rules(limits.firmware, None)
    if m and (rules.smoothed_lookahead if rules is not None else limits.junction == "scv"):
        # Klipper's smoothed look-ahead, where the file sets ACCEL_TO_DECEL below ACCEL
        # (newer Klipper: minimum_cruise_ratio, the pseudo acceleration max_accel * (1 - ratio))
        # the pseudo acceleration is the toolhead's max_accel times (1 - ratio), whatever lowered
        # the move's own (Z, extruder caps): toolhead.py Move.mcr_delta_v2 = min(2 d
        # mcr_pseudo_accel, delta_v2), so a Z or extrude-only move is not smoothed below its accel
        a_smooth = np.minimum(np.minimum(table[regime, _k.C_ACCEL_TO_DECEL], acc),
                              table[regime, _k.C_ACCEL_PRINT] * (1.0 - table[regime, _k.C_MIN_CRUISE_RATIO]))
        if np.any(a_smooth < acc):
            vnom = _k.klipper_cruise_cap(L, acc, a_smooth, vnom, vj, stop_before)

    entry, exit_, peak, t_acc, t_cruise, t_dec = _k.plan_moves(
        L, acc, vnom, vj, safe, stop_before)
    dur = np.array(program.duration_s, dtype=float, copy=True)
    zero_motion = np.isin(kind, np.asarray(MOTION_KINDS, dtype=kind.dtype)) & ~motion
    dur[zero_motion] = 0.0
    dur[idx] = t_acc + t_cruise + t_dec
    return (dur, idx, limits, length, entry, exit_, peak, t_acc, t_cruise, t_dec, acc, vnom, vfree,
            vj, vj_free, safe, stop_before, barrier)


def stop_restart_s(p: Plan, rows, split=False) -> np.ndarray:
    """Per query, what a full stop and restart costs at an instruction line placed before step
    ``rows[i]`` (``split[i]``: inside that move instead), priced from the speeds the moves there
    allow and nothing else, so that the same line costs the same in the original (where the solver
    places it) and in the output (where the verifier finds it between two moves): the head passes
    the place at ``v`` -- the junction speed of the move before and the next move without a stop
    (``Plan._vj_free``: the junction rule, both nominal speeds; 0 next to an extrude-only move on
    Klipper), or inside a move its nominal speed before any smoothing cap -- and stopping there
    costs ``v / (2 a_before) + v / (2 a_after)`` over passing at ``v`` (decelerate and accelerate
    again at the moves' own accelerations). A line with no move after it costs nothing (the
    print is over). This ignores whatever else stops the head nearby (a dwell) and moves too short
    to reach ``v`` again: an upper bound there."""
    rows = np.atleast_1d(np.asarray(rows, dtype=np.int64))
    split = np.broadcast_to(np.asarray(split, dtype=bool), rows.shape)
    out = np.zeros(len(rows))
    ms = p.move_step
    if len(ms) == 0:
        return out
    # the next move: the row itself when it is a move (or is split), else the first move after it
    c = np.searchsorted(ms, rows, side="left")
    ok = c < len(ms)
    cc = np.minimum(c, len(ms) - 1)
    acc = p.accel_mm_s2[ms]
    inside = split & ok & (ms[cc] == rows)
    v = np.where(inside, p.free_mm_s[ms[cc]], p._vj_free[cc])
    a_next = acc[cc]
    a_prev = np.where(inside, acc[cc], acc[np.maximum(cc - 1, 0)])
    first = (cc == 0) & ~inside
    out = np.where(ok & ~first, v / (2.0 * a_prev) + v / (2.0 * a_next), 0.0)
    return out


def enable_price(family: str | None = None, printer=None):
    """``firmware.stall_durations``' ``enable_price`` callable: ``stop_restart_s`` at the given rows
    of a program planned with ``family``'s rules (``printer``: the printer's Klipper config)."""
    def price(program: Program, rows) -> np.ndarray:
        return stop_restart_s(plan(program, machine_limits(program, family=family, printer=printer)), rows)
    return price


# ------------------------------------------------------------------------------------------------
_SPEED_FACTOR_RE = re.compile(rb"^[ \t]*(?:N\d+[ \t]*)?M22([01])(?![0-9.])[^;\r\n]*?S[ \t]*([-+]?\d+\.?\d*)", re.M | re.I)
#: relative margin taken off every lower bound: Klipper's own float sums may round the other way
MIN_MOVE_MARGIN = 1e-9


def min_move_time_s(program: Program, arc_segment_mm: float = ARC_SEGMENT_MM) -> np.ndarray:
    """(n_steps,) a lower bound of the time each step takes in the firmware's planner that never
    exceeds Klipper's ``Move.min_move_t`` (klippy/toolhead.py: the move's distance over its speed,
    the speed after every limit) -- what a firmware that proves gating rules from its queued moves
    sums (``firmware.Schedule``). formulations/gating.md §9 argues it:

    * a line move: L / F, L its XYZ length (``|dE|`` for an extrude-only move) and F the requested
      speed. Klipper's ``min_move_t`` is ``move_d / v`` with ``move_d`` the same length and ``v =
      min(F, max_velocity, the kinematics' and extruder's caps)`` <= F, so L / F <= min_move_t;
      bed-mesh splitting only lengthens the path;
    * an arc Klipper does not turn (target = start, its float angle not exactly 0:
      ``firmware.klipper.null_arcs``): the straight move to its target, as a line;
    * an arc: Klipper's gcode_arcs cuts it into ``n = max(1, floor(L / resolution))`` chords that
      are shorter than the arc: ``n`` chords of the start radius, an ``n`` taken one less where
      ``L / resolution`` is within rounding of an integer (fewer chords are shorter), less the
      difference between the arc's start and end radius (the last chord ends on the target);
    * M220 above 100 % speeds every move up and M221 below 100 % shortens an extrude-only move:
      the bound is scaled by the smallest factor the file sets anywhere;
    * every other step (dwell, heating, homing, motor lines) 0: none of them is a queued move.

    Less a relative ``MIN_MOVE_MARGIN`` for the rounding of Klipper's own sums."""
    kind = program.kind
    n = program.n_steps
    moving = np.isin(kind, np.asarray(MOTION_KINDS, dtype=kind.dtype)) & (program.length_mm > 0)
    out = np.where(moving, np.asarray(program.duration_s, float), 0.0)
    arcs = np.flatnonzero(moving & (kind == Kind.ARC))
    if len(arcs):
        # an arc Klipper does not turn (``firmware.klipper.null_arcs``) is one straight move
        null = fwklipper.null_arcs(program, arcs)
        if null.any():
            r = arcs[null]
            dd = program.end_mm[r] - program.start_mm[r]
            straight = np.sqrt((dd[:, :3] ** 2).sum(axis=1))
            out[r] = np.where(straight > 0, straight, np.abs(dd[:, 3])) / program.feed_mm_s[r]
            arcs = arcs[~null]
    if len(arcs):
        L = program.length_mm[arcs].astype(float)
        dz = program.end_mm[arcs, Z] - program.start_mm[arcs, Z]
        c = program.arc_center_mm[arcs]
        r0 = np.hypot(program.start_mm[arcs, X] - c[:, 0], program.start_mm[arcs, Y] - c[:, 1])
        r1 = np.hypot(program.end_mm[arcs, X] - c[:, 0], program.end_mm[arcs, Y] - c[:, 1])
        flat = np.sqrt(np.maximum(L * L - dz * dz, 0.0))
        theta = flat / np.maximum(r0, 1e-12)
        n_seg = np.maximum(1.0, np.floor(L / arc_segment_mm * (1.0 - 1e-9) - 1e-9))
        chord = np.hypot(2.0 * r0 * np.sin(theta / (2.0 * n_seg)), dz / n_seg)
        chords = np.maximum(n_seg * chord - np.abs(r1 - r0), 0.0)
        out[arcs] = np.minimum(chords, L) / program.feed_mm_s[arcs]
    speed, extrude = 1.0, 1.0
    for m in _SPEED_FACTOR_RE.finditer(program.data):
        pct = float(m.group(2))
        if m.group(1) == b"0" and pct > 0:
            speed = min(speed, 100.0 / pct)
        elif m.group(1) == b"1" and pct >= 0:
            extrude = min(extrude, pct / 100.0)
    e_only = moving & ~np.any(program.end_mm[:, :3] != program.start_mm[:, :3], axis=1) if n else moving
    out = out * speed
    out[e_only] *= extrude
    return out * (1.0 - MIN_MOVE_MARGIN)


# ------------------------------------------------------------------------------------------------
# the slicer's own estimate
_DHMS_RE = re.compile(r"(\d+(?:\.\d+)?)\s*([dhms])")
_PRUSA_RE = re.compile(rb"^; estimated printing time(?: \(normal mode\))? = ([^\r\n]+)", re.M)
_CURA_RE = re.compile(rb"^;TIME:(\d+(?:\.\d*)?)\s*$", re.M)
#: what CuraEngine run from the command line writes as ``;TIME:`` (the Cura front end replaces it
#: after slicing); the engine's own estimate is then its last ``;TIME_ELAPSED:`` marker
_CURA_PLACEHOLDER_S = 6666.0
_CURA_ELAPSED_RE = re.compile(rb"^;TIME_ELAPSED:(\d+(?:\.\d*)?)\s*$", re.M)
_IDEAMAKER_RE = re.compile(rb"^;Print Time: *(\d+(?:\.\d*)?)", re.M)
_S3D_RE = re.compile(rb"^;\s*Build time: *([^\r\n]+)", re.M)
_S3D_PART_RE = re.compile(r"(\d+(?:\.\d+)?)\s*(hour|minute|second|hr|min|sec)", re.I)
_KISS_RE = re.compile(rb"^; (?:Calculated-during-export|Estimated) Build Time:\s*(\d+(?:\.\d+)?)\s*minutes", re.M)


def _dhms(text: str) -> float | None:
    parts = _DHMS_RE.findall(text)
    if not parts:
        return None
    mult = {"d": 86400.0, "h": 3600.0, "m": 60.0, "s": 1.0}
    return sum(float(x) * mult[u] for x, u in parts)


def slicer_estimate_s(program: Program) -> float | None:
    """The print time the slicer wrote into the file (seconds), or None.

    PrusaSlicer / SuperSlicer / OrcaSlicer / Bambu / Creality Print ``; estimated printing time
    (normal mode) = 1h 2m 3s``; Cura ``;TIME:3723`` (CuraEngine from the command line writes
    ``;TIME:6666``, a placeholder: its last ``;TIME_ELAPSED:`` then); ideaMaker ``;Print Time: 3723``; Simplify3D
    ``;   Build time: 1 hours 2 minutes``; KISSlicer ``; Estimated Build Time: 62.05 minutes``.
    """
    data = program.data
    m = _PRUSA_RE.search(data)
    if m:
        return _dhms(m.group(1).decode("ascii", "replace"))
    m = _CURA_RE.search(data, 0, 65536)
    if m is None or float(m.group(1)) == _CURA_PLACEHOLDER_S:
        # CuraEngine from the command line: a placeholder (or no header); the per-layer
        # elapsed-time markers carry its estimate, the last one near the end of the file
        tail = max(0, len(data) - 1_000_000)
        last = None
        for last in _CURA_ELAPSED_RE.finditer(data, tail):
            pass
        if last is not None:
            return float(last.group(1))
        if m is not None:
            return None                 # the placeholder is no estimate
    if m:
        return float(m.group(1))
    m = _IDEAMAKER_RE.search(data, 0, 65536) or _IDEAMAKER_RE.search(data)
    if m:
        return float(m.group(1))
    m = _S3D_RE.search(data)
    if m:
        parts = _S3D_PART_RE.findall(m.group(1).decode("ascii", "replace"))
        if parts:
            mult = {"h": 3600.0, "m": 60.0, "s": 1.0}
            return sum(float(x) * mult[u[0].lower()] for x, u in parts)
    m = _KISS_RE.search(data)
    if m:
        return float(m.group(1)) * 60.0
    return None


def comparable_total_s(program: Program, duration_s: np.ndarray) -> float:
    """Total of ``duration_s`` over every step except heat-up waits and homing: what a slicer's
    estimate covers (none counts those; their durations here are profile assumptions)."""
    keep = ~np.isin(program.kind, np.asarray((Kind.WAIT, Kind.HOME), dtype=program.kind.dtype))
    return float(np.asarray(duration_s)[keep].sum())


def estimated_total_s(program: Program, model: str = "planner", limits: MachineLimits | None = None) -> float:
    """Print time under ``model`` comparable with a slicer's estimate (``comparable_total_s``)."""
    return comparable_total_s(program, durations(program, model, limits))
