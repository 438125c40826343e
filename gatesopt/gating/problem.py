"""The power-gating problem: plain data over numpy arrays, and ``build`` from a parsed Program.

3DGates (Chen et al., ASPLOS'17) Section 4: for each motor m the steps that move its axis must run
with it on; it is switched on at least Start-Ahead (``start_ahead_s``, instruction inertia) before
its first step and kept on at least End-Late (``end_late_s``, instruction delay) after its last.
Between those *required on-intervals* lie *idle intervals*; an idle interval may be switched off.
The math, with these symbol names, is in ``formulations/gating.md``.

Everything here is on the problem's *timeline* (``gating.timeline``): step ``i`` runs from
``start_s[i]`` to ``start_s[i + 1]`` (the original print, no stalls). A firmware stall (Marlin's
queue drain, Klipper's dwell) is a separate piece of time at an instruction line, priced with the
coefficients a ``Kind.MOTOR`` row at that step would get from the energy profile (``stall_coeffs``)
and the motors as the file has them (``enable0``): the whole printer keeps drawing power during a
stall, no gating credit is taken for it. The file's own motor lines (a start G-code ``M17``, a
mid-print ``M84``) stall as ``gatesopt.firmware.stall_durations`` says -- the function the verifier
prices the output with -- a fixed cost in ``energy_before_j``/``time_before_s`` and one stall piece
each in ``scoring.Pieces``.

Energy is computed ONLY with ``gatesopt.energy.step_power_w`` / ``step_energy_j`` (the one model):
``rate_w[i, m]`` is what switching motor m off saves per second in step i with the other motors
as in the file, ``xy_inter_w[i]`` is the correction when X and Y are both off (non-additive power;
0 under the paper profile's linear assumption).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from .. import firmware as fw_mod
from ..energy import PowerCoefficients, load_profile, step_energy_j, step_power_w
from ..errors import GatesoptError
from ..limits import machine_limits
from ..planner import enable_price, min_move_time_s, plan, stop_restart_s
from ..program import AXES, Kind, Program, X, Y
from . import _kernels as _k
from .options import GatingOptions
from .rotation import greedy_angle, rotated_rows, rotation_candidates, rotation_center, steps_at
from .timeline import is_split, whole_steps


@dataclass(frozen=True, eq=False)
class GatingProblem:
    """One gating instance: steps, energy coefficients, rotation candidates and the idle intervals.

    Idle-interval arrays (prefix ``idle_``) are flattened over (angle, motor) and sorted by angle,
    motor, time. An idle interval is an open interval ``(idle_start_s, idle_end_s)`` of motor
    ``idle_motor`` (axis index, X=0) under rotation ``angles_deg[idle_angle]`` in which the motor
    does not have to be on.
    """

    options: GatingOptions
    source: str
    n_lines: int                   # lines of the original file (denominator of the lines budget)
    # --- steps (n) ----------------------------------------------------------------------------
    duration_s: np.ndarray         # (n,) step durations on the problem's timeline
    start_s: np.ndarray            # (n+1,) cumulative start times; start_s[n] = total time
    coeffs: PowerCoefficients      # (n) energy-model coefficients of each step
    stall_coeffs: PowerCoefficients  # (n) coefficients of a firmware stall (Kind.MOTOR row) at step i
    enable0: np.ndarray            # (n, 4) bool: motors on in the file itself (no gating)
    rate_w: np.ndarray             # (n, 4) W saved per second by switching motor m off (others as
                                   # enable0); computed for X, Y and the gated motors, 0 for others
    xy_inter_w: np.ndarray         # (n,) added W when X and Y are both off (non-additive correction)
    start_mm: np.ndarray           # (n, 4) X Y Z E before each step (original coordinates)
    end_mm: np.ndarray             # (n, 4)
    steps_motor0: np.ndarray       # (n, 4) bool: motors that step, unrotated (Program.steps_motor())
    layer: np.ndarray              # (n,) int32 layer index (-1 before the first layer)
    arc: np.ndarray                # (n,) bool: G2/G3 rows (step X and Y whatever the rotation)
    rotate_lo: int                 # rows [rotate_lo, rotate_hi) are rotated (first..last extrusion)
    rotate_hi: int
    center_mm: np.ndarray          # (2,) rotation centre (XY bbox centre of the rotated rows)
    # --- rotation candidates (K) --------------------------------------------------------------
    angles_deg: np.ndarray         # (K,) counter-clockwise rotation about center_mm
    angle_snap_mm: np.ndarray      # (K,) largest other-axis displacement snapped to 0 at that angle
    angle_single_axis_s: np.ndarray  # (K,) time of XY moves that run on one axis at that angle
    angle_straight_moves: np.ndarray  # (K,) count of straight X + straight Y moves (greedy's criterion)
    angle_saving_ub_j: np.ndarray  # (K,) upper bound on the energy gating can save at that angle
    angle_built: np.ndarray        # (K,) bool: idle intervals built; False = pruned by the bound (never optimal)
    # --- idle intervals (G) -------------------------------------------------------------------
    idle_angle: np.ndarray           # (G,) int32 index into angles_deg
    idle_motor: np.ndarray           # (G,) int8 axis index (0..3)
    idle_start_s: np.ndarray         # (G,) off may start here (last step of m + end_late_s), or 0
    idle_end_s: np.ndarray           # (G,) must be on again here (next step of m - start_ahead_s), or T
    idle_off_row: np.ndarray         # (G,) int64 row at (or in) which the off instruction takes effect
    idle_on_row: np.ndarray          # (G,) int64 row at (or in) which the on instruction takes effect (n: none)
    idle_prev_row: np.ndarray        # (G,) int64 last row stepping the motor before the interval (-1: none)
    idle_next_row: np.ndarray        # (G,) int64 first row stepping the motor after the interval (n: none)
    idle_saving_j: np.ndarray        # (G,) energy saved by the motor being off (others as in the file)
    idle_lines: np.ndarray           # (G,) int lines this interval adds on its own (off + on + splits)
    idle_stall_s: np.ndarray         # (G,) stall time this interval adds on its own
    idle_stall_j: np.ndarray         # (G,) energy of that stall
    # --- totals without gating (the file's own motor-line stalls included) ---------------------
    energy_before_j: float = 0.0
    time_before_s: float = 0.0     # total_s + own_stall_s.sum()
    header: dict = field(default_factory=dict, repr=False)
    notes: tuple[str, ...] = ()    # what the user should know about the choices made (rotation)
    rotation_plan: object = field(default=None, repr=False)   # rotation.RotationPlan: the bed, the
                                   # margin and why the candidates are what they are
    # --- the file's own motor lines (start G-code M17, a mid-print M84 ...) -----------------------
    # their firmware stalls (``gatesopt.firmware.stall_durations``, as the verifier prices them):
    # a fixed cost of the print, whatever gating does; one stall piece each in ``Pieces``
    # a dialect whose lines are full stops priced per move (``Firmware.enable_is_stop`` /
    # ``disable_is_stop``): the stop at a line placed at the start of step r (``stop_at_s[r]``,
    # n + 1) or inside it (``stop_in_s[r]``), ``planner.stop_restart_s``; empty: the options'
    # constant ``stall_on_s`` / ``stall_off_s`` everywhere
    stop_at_s: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    stop_in_s: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    own_stall_row: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64), repr=False)
    own_stall_s: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    # --- a firmware that times its own switches (``options.schedule``, formulations/gating.md §9) --
    # the lower-bound clock (sum of ``planner.min_move_time_s``) at each idle interval's off line
    # (after its motor's last step) and at the start of the step that ends it; 0 without a schedule
    idle_lb_off_s: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    idle_lb_on_s: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    @property
    def n_steps(self) -> int:
        return len(self.duration_s)

    @property
    def n_idle_intervals(self) -> int:
        return len(self.idle_start_s)

    @property
    def n_angles(self) -> int:
        return len(self.angles_deg)

    @property
    def motors(self) -> tuple[int, ...]:
        return self.options.motor_index

    @property
    def total_s(self) -> float:
        return float(self.start_s[-1])

    @property
    def idle_net_j(self) -> np.ndarray:
        """Energy an idle interval saves off on its own, stall included (the dp's decision value)."""
        return self.idle_saving_j - self.idle_stall_j

    def idle_intervals_of(self, angle_index: int) -> np.ndarray:
        """Indices of the idle intervals of one rotation candidate (a contiguous range; empty if
        pruned)."""
        lo, hi = np.searchsorted(self.idle_angle, [angle_index, angle_index + 1])
        return np.arange(lo, hi)

    def spacing_need_s(self, motor: int) -> tuple[float, float, float]:
        """Rule B of a firmware that times its switches (``options.schedule``), as three needs on the
        lower-bound clock (-inf: no such need). Off intervals i before j of ``motor``, consecutive
        among those off, may both be off only if

            idle_lb_off_s[j] - idle_lb_on_s[i]  >= on_off    (K = 1: i's on to j's off)
            idle_lb_off_s[j] - idle_lb_off_s[i] >= off_off   (K = 2: i's off to j's off)
            idle_lb_on_s[j]  - idle_lb_on_s[i]  >= on_on     (K = 2: i's on to j's on)

        with K the firmware's ``Schedule.pin_queue_slots`` (each change of a pin at least
        ``min_spacing_s`` after the change K back); returns (on_off, off_off, on_on). Each side only
        grows going back from j (``chain_predecessors``)."""
        o = self.options
        none = -math.inf
        if o.schedule is None or o.schedule.min_spacing_s <= 0:
            return none, none, none
        sp = o.schedule.min_spacing_s
        if o.schedule.pin_queue_slots == 1:
            return sp - o.on_margin_s(motor) - o.off_margin_s(motor) + RULE_EPS_S, none, none
        # K = 2: the same margin at both ends of each difference (per motor constants)
        return none, sp + RULE_EPS_S, sp + RULE_EPS_S

    def spacing_ok(self, motor: int, off_i, on_i, off_j, on_j, tol_s: float = 0.0):
        """Rule B (``spacing_need_s``) between an off interval (lower-bound clock ``off_i``,
        ``on_i``) and the next one off of the same motor (``off_j``, ``on_j``); arrays broadcast.
        ``tol_s``: slack granted (a check of someone else's sums)."""
        on_off, off_off, on_on = self.spacing_need_s(motor)
        off_j, on_j = np.asarray(off_j, float), np.asarray(on_j, float)
        return ((off_j - on_i >= on_off - tol_s) & (off_j - off_i >= off_off - tol_s)
                & (on_j - on_i >= on_on - tol_s))

    @property
    def has_spacing(self) -> bool:
        """A firmware schedule with rule B (``spacing_need_s``)."""
        o = self.options
        return o.schedule is not None and o.schedule.min_spacing_s > 0

    @property
    def separable(self) -> bool:
        """True when the exact answer is per motor: no budgets, no shared stall, additive XY power
        (the idle intervals of a motor are then independent, or a chain under rule B, which dp
        solves exactly too)."""
        o = self.options
        shared_stall = o.merge_lines and (o.stall_off_s > 0 or o.stall_on_s > 0) and len(o.groups) > 1
        return not o.has_budget and not shared_stall and not self.xy_coupled

    @property
    def xy_coupled(self) -> bool:
        """X and Y are gated with separate enable pins and their powers do not add up."""
        grp = {m: g for g in self.options.groups for m in g}
        both = X in grp and Y in grp and grp[X] != grp[Y]
        return both and bool(np.any(self.xy_inter_w != 0))

    @property
    def max_added_time_s(self) -> float:
        p = self.options.max_added_time_pct
        return math.inf if p is None else p / 100.0 * self.time_before_s

    @property
    def max_added_lines(self) -> float:
        p = self.options.max_added_lines_pct
        return math.inf if p is None else math.floor(p / 100.0 * self.n_lines + 1e-9)

    def __repr__(self) -> str:
        return (f"GatingProblem({self.source!r}, steps={self.n_steps}, angles={self.n_angles}, "
                f"idle_intervals={self.n_idle_intervals}, motors={','.join(self.options.motors)})")



def steps_motor_at(problem: GatingProblem, angle_index: int) -> tuple[np.ndarray, np.ndarray]:
    """((n, 4) bool steps, (n,) snapped other-axis displacement) under rotation ``angle_index``.

    At a non-zero angle an XY displacement below ``options.snap_mm`` is taken as zero: the emitter
    must write that coordinate exactly equal to the previous one (DESIGN.md "Rotation").
    """
    deg = float(problem.angles_deg[angle_index])
    return steps_at(problem.start_mm, problem.end_mm, problem.steps_motor0, problem.arc,
                    problem.rotate_lo, problem.rotate_hi, problem.center_mm, deg, problem.options.snap_mm)


def readonly(a) -> np.ndarray:
    """``a`` as an array that cannot be written (a view where it could): problems and solutions
    are values."""
    a = np.asarray(a)
    if a.flags.writeable:
        a = a.view()
        a.flags.writeable = False
    return a


def chain_predecessors(problem: GatingProblem, chain: np.ndarray) -> np.ndarray:
    """Rule B over ``chain`` (idle intervals of one angle and motor, in time order): p[j] = the
    number of chain members before j that may be off together with j (they are chain[:p[j]]: each
    of rule B's differences only grows going back, ``GatingProblem.spacing_need_s``). ``p[j] == j``
    for every j without rule B."""
    chain = np.asarray(chain, np.int64)
    k = len(chain)
    if k == 0:
        return np.zeros(0, np.int64)
    on_off, off_off, on_on = problem.spacing_need_s(int(problem.idle_motor[chain[0]]))
    off, on = problem.idle_lb_off_s[chain], problem.idle_lb_on_s[chain]
    p = np.arange(k, dtype=np.int64)
    # the members i with (j's clock - i's clock) >= need are those whose clock is at most
    # j's clock - need: a prefix, both clocks being non-decreasing along the chain
    for mine, theirs, need in ((off, on, on_off), (off, off, off_off), (on, on, on_on)):
        if np.isfinite(need):
            p = np.minimum(p, np.searchsorted(theirs, mine - need, side="right"))
    return p.astype(np.int64)


# ------------------------------------------------------------------------------------------------
# Builders
#: rules A and B of a firmware schedule are checked with this much to spare (s): the firmware's own
#: float sums of the same lower bounds may round the other way
RULE_EPS_S = 1e-9


@dataclass(frozen=True, eq=False)
class _Rates:
    """What switching motors off saves per step (W), from the one energy model."""

    p0_w: np.ndarray            # (n,) power of each step with the motors as in the file
    rate_w: np.ndarray          # (n, 4) saved with motor m off (X, Y and the gated motors)
    xy_inter_w: np.ndarray      # (n,) non-additive correction with X and Y both off
    group_rate_w: dict          # first motor of an enable group -> (n,) saved with the group off


def _motor_rates(coeffs: PowerCoefficients, enable0: np.ndarray, o: GatingOptions) -> _Rates:
    """Per-motor marginal power and the XY interaction, from the one energy model."""
    n = len(enable0)
    p0 = step_power_w(coeffs, enable0)
    rate = np.zeros((n, 4))
    for m in set(o.motor_index) | {X, Y}:        # X and Y always: the XY correction needs both
        en = enable0.copy()
        en[:, m] = False
        rate[:, m] = p0 - step_power_w(coeffs, en)
    en = enable0.copy()
    en[:, X] = False
    en[:, Y] = False
    xy_inter = step_power_w(coeffs, en) - (p0 - rate[:, X] - rate[:, Y])
    group_rate = {}
    for grp in o.groups:
        if len(grp) == 1:
            group_rate[grp[0]] = rate[:, grp[0]]
        else:
            en = enable0.copy()
            en[:, list(grp)] = False
            group_rate[grp[0]] = p0 - step_power_w(coeffs, en)
    # rounding noise of the subtraction is not a physical interaction
    xy_inter[np.abs(xy_inter) <= 1e-9 * (np.abs(p0) + 1.0)] = 0.0
    return _Rates(p0, rate, xy_inter, group_rate)


def enable_price_fn(o: GatingOptions):
    """``firmware.stall_durations``' ``enable_price`` for the options' dialect (None where its
    lines are not stops priced per move): ``planner.stop_restart_s`` on the program planned with
    the options' rules and printer config, as the verifier prices the output."""
    fw = fw_mod.get(o.firmware)
    if not (fw.enable_is_stop or fw.disable_is_stop):
        return None
    return enable_price(o.planner_family, o.printer)


def _stop_prices(program: Program, o: GatingOptions) -> tuple[np.ndarray, np.ndarray]:
    """(at (n+1,), in (n,)): the stop of a line at the start of each step and inside it
    (``planner.stop_restart_s``), for a dialect whose lines are stops priced per move; empty
    otherwise."""
    fw = fw_mod.get(o.firmware)
    if not (fw.enable_is_stop or fw.disable_is_stop):
        return np.zeros(0), np.zeros(0)
    n = program.n_steps
    p = plan(program, machine_limits(program, family=o.planner_family, printer=o.printer))
    rows = np.arange(n + 1)
    return stop_restart_s(p, rows), stop_restart_s(p, rows[:n], True)


def _stop_at(problem, row, split):
    row = np.asarray(row, np.int64)
    n = problem.n_steps
    return np.where(split, problem.stop_in_s[np.minimum(row, max(n - 1, 0))],
                    problem.stop_at_s[np.minimum(row, n)])


def on_stall_s(problem, row, split) -> np.ndarray | float:
    """The stall of on lines at ``row`` (inside it where ``split``): the firmware's restart plus
    the stop there where the problem prices lines per move, else ``options.stall_on_s``."""
    fw = fw_mod.get(problem.options.firmware)
    if len(problem.stop_at_s) == 0 or not fw.enable_is_stop:
        return problem.options.stall_on_s
    return fw.enable_fixed_s(problem.options.printer) + _stop_at(problem, row, split)


def off_stall_s(problem, row, split) -> np.ndarray | float:
    """The stall of off lines at ``row`` (inside it where ``split``), as ``on_stall_s``."""
    fw = fw_mod.get(problem.options.firmware)
    if len(problem.stop_at_s) == 0 or not fw.disable_is_stop:
        return problem.options.stall_off_s
    return fw.disable_fixed_s_at(problem.options.printer) + _stop_at(problem, row, split)


def _own_stalls(program: Program, firmware: str, o: GatingOptions | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(rows, seconds) of the firmware stalls of the file's own motor lines.

    The file's own motor lines stall the firmware too (Marlin's M18 in start G-code drains the
    queue, Klipper's M84 dwells), or not at all (Klipper has no M17: "Unknown command", skipped).
    That is decided in one place, ``firmware.stall_durations``, which the verifier also prices
    the output with; here it is a constant of the print, priced like a gating line's stall."""
    own_s = np.zeros(program.n_steps)
    if np.any(program.kind == Kind.MOTOR):
        own_s = fw_mod.stall_durations(program, firmware,
                                       enable_price=enable_price_fn(o) if o is not None else None,
                                       printer=o.printer if o is not None else None)
    own_row = np.flatnonzero(own_s > 0)
    return own_row, own_s[own_row]


def _stall_program(program: Program) -> Program:
    """The program with every row turned into a Kind.MOTOR row at rest: the profile then prices a
    firmware stall at that step exactly as the verifier will price the re-parsed instruction."""
    n = program.n_steps
    return program.replace(kind=np.full(n, Kind.MOTOR, np.int8), start_mm=program.end_mm,
                           length_mm=np.zeros(n), duration_s=np.zeros(n),
                           arc_center_mm=np.full((n, 2), np.nan))


@dataclass(frozen=True, eq=False)
class _Timing:
    """What the idle intervals are measured with: the timeline and, for a firmware that times its
    own switches (``options.schedule``), its lower-bound clock and where it switches by itself."""

    start_s: np.ndarray             # (n+1,) the problem's timeline
    dur: np.ndarray                 # (n,)
    stall_w: np.ndarray             # (n,) power of a stall at each step
    lb_cum_s: np.ndarray | None     # (n+1,) cumulative ``planner.min_move_time_s``; None: no schedule
    barrier_cum: np.ndarray         # (n+1, 4) cumulative count of steps where the firmware switches a
                                    # motor itself (homing, the file's own motor lines it carries out)
    whole: np.ndarray               # (n,) bool: steps no line may split (``timeline.whole_steps``;
                                    # none under a schedule: its lines go between steps)
    stop_at_s: np.ndarray = None    # per-move stops at a line (``GatingProblem.stop_at_s``), or empty
    stop_in_s: np.ndarray = None


def _schedule_keep(o: GatingOptions, t: _Timing, m: int, prev, nxt) -> np.ndarray:
    """Idle intervals of motor ``m`` a firmware schedule may gate: one after a step of ``m`` (the
    line goes after it), rule A on the lower-bound clock, nothing between line and next step where
    the firmware switches ``m`` itself (formulations/gating.md §9)."""
    n = len(t.dur)
    after = np.minimum(prev + 1, n)
    gap = t.lb_cum_s[np.minimum(nxt, n)] - t.lb_cum_s[after]
    need = o.off_margin_s(m) + o.on_margin_s(m) + o.schedule.min_off_s + RULE_EPS_S
    return (prev >= 0) & (gap >= need) & _clear_of_barriers(t, m, prev, nxt)


def _clear_of_barriers(t: _Timing, m: int, prev, nxt) -> np.ndarray:
    """Per interval (after step ``prev``, before step ``nxt``), whether no step between them is
    one where the firmware switches motor ``m`` itself (``_barrier_cum``)."""
    n = len(t.dur)
    return t.barrier_cum[np.minimum(nxt, n), m] == t.barrier_cum[np.minimum(prev + 1, n), m]


def _per_move_stalls(out: dict, t: _Timing, o: GatingOptions, per_event: int) -> None:
    """Replace the constant stalls the kernel priced each interval's lines with the per-move ones
    (``_stop_prices``: the firmware's fixed part plus the stop where the line stands), in place;
    nothing without per-move prices."""
    if t.stop_at_s is None or len(t.stop_at_s) == 0:
        return
    fw = fw_mod.get(o.firmware)
    n = len(t.dur)

    def stop(q, moment):
        split = is_split(t.start_s, q, moment)
        return np.where(split, t.stop_in_s[np.minimum(q, max(n - 1, 0))], t.stop_at_s[np.minimum(q, n)])

    delta = np.zeros(len(out["idle_stall_s"]))
    delta_j = np.zeros(len(delta))
    if fw.disable_is_stop:
        r = out["idle_off_row"]
        d = (fw.disable_fixed_s_at(o.printer) + stop(r, out["idle_start_s"]) - o.stall_off_s) * per_event
        delta += d
        delta_j += d * t.stall_w[np.minimum(r, max(n - 1, 0))]
    if fw.enable_is_stop and o.on_line:
        q = out["idle_on_row"]
        d = np.where(q < n, (fw.enable_fixed_s(o.printer) + stop(q, out["idle_end_s"]) - o.stall_on_s) * per_event, 0.0)
        delta += d
        delta_j += d * t.stall_w[np.minimum(q, max(n - 1, 0))]
    out["idle_stall_s"] = out["idle_stall_s"] + delta
    out["idle_stall_j"] = out["idle_stall_j"] + delta_j


def _idle_table(o: GatingOptions, t: _Timing, group_rate_w: dict, steps_list, angles_idx):
    """Idle-interval table for all (angle, enable group) pairs. ``steps_list[k]``: (n,4) step mask
    of angle ``angles_idx[k]``.

    A group of motors on one enable pin is one interval owner (its first motor): it must be on
    whenever any member steps, and saves what all members draw (``group_rate_w``)."""
    start_s, dur, n = t.start_s, t.dur, len(t.dur)
    rates = {g[0]: np.ascontiguousarray(group_rate_w[g[0]]) for g in o.groups}
    cums = {m: np.concatenate(([0.0], np.cumsum(r * dur))) for m, r in rates.items()}
    stall_w = np.ascontiguousarray(t.stall_w)
    names = ("idle_start_s", "idle_end_s", "idle_off_row", "idle_on_row", "idle_prev_row",
             "idle_next_row", "idle_saving_j", "idle_lines", "idle_stall_s", "idle_stall_j")
    parts = []
    for k, steps in zip(angles_idx, steps_list):
        for grp in o.groups:
            m = grp[0]
            st = steps[:, list(grp)].any(axis=1) if len(grp) > 1 else steps[:, m]
            per_event = 1 if o.merge_lines else len(grp)     # one line per motor unless merged
            out = dict(zip(names, _k.idle_intervals(
                start_s, np.ascontiguousarray(st), rates[m], cums[m], stall_w, float(o.on_margin_s(m)),
                float(o.off_margin_s(m)), bool(o.on_line), float(o.stall_off_s), float(o.stall_on_s),
                per_event, o.schedule is None, t.whole)))
            _per_move_stalls(out, t, o, per_event)
            prev, nxt = out["idle_prev_row"], out["idle_next_row"]
            # an interval across a line where the firmware switches m itself is not one
            # (``_barrier_cum``); a schedule's rules drop more (``_schedule_keep``)
            keep = (_schedule_keep(o, t, m, prev, nxt) if o.schedule is not None
                    else _clear_of_barriers(t, m, prev, nxt))
            out = {nm: v[keep] for nm, v in out.items()}
            prev, nxt = out["idle_prev_row"], out["idle_next_row"]
            if o.schedule is not None:
                out["idle_lb_off_s"] = t.lb_cum_s[np.minimum(prev + 1, n)]
                out["idle_lb_on_s"] = t.lb_cum_s[np.minimum(nxt, n)]
            else:
                out["idle_lb_off_s"] = out["idle_lb_on_s"] = np.zeros(len(prev))
            parts.append((k, m, out))
    res = {nm: np.concatenate([p[2][nm] for p in parts]) for nm in parts[0][2]}
    res["idle_angle"] = np.concatenate([np.full(len(p[2]["idle_start_s"]), p[0], np.int32) for p in parts])
    res["idle_motor"] = np.concatenate([np.full(len(p[2]["idle_start_s"]), p[1], np.int8) for p in parts])
    return res


@dataclass(frozen=True, eq=False)
class _AngleTable:
    """Per rotation candidate: step masks and the numbers the pruning and the greedy read."""

    steps: list                 # (n, 4) bool step mask of each angle
    snap_mm: np.ndarray         # (K,) largest snapped displacement
    single_axis_s: np.ndarray   # (K,) time of XY moves on one axis
    straight_moves: np.ndarray  # (K,) int64 straight X + straight Y moves
    saving_ub_j: np.ndarray     # (K,) upper bound on what gating saves


def _angle_table(program: Program, o: GatingOptions, angles, lo, hi, center, dur, rate, steps0, arc):
    """Step masks and statistics of every candidate angle (``_k.angle_stats``)."""
    gated = o.motor_index
    steps_list, snaps, single_s, straight, ub = [], [], [], [], []
    rdur = rate * dur[:, None]
    ub_zE = sum(float(rdur[:, m] @ ~steps0[:, m]) for m in gated if m not in (X, Y))
    c_in = (np.ascontiguousarray(program.start_mm[:, :2]), np.ascontiguousarray(program.end_mm[:, :2]),
            np.ascontiguousarray(steps0), np.ascontiguousarray(arc))
    rx, ry = np.ascontiguousarray(rdur[:, X]), np.ascontiguousarray(rdur[:, Y])
    for t in angles:
        st, snap = steps_at(*c_in[:2], c_in[2], c_in[3], lo, hi, center, t, o.snap_mm)
        steps_list.append(st)
        snaps.append(float(snap.max()) if len(snap) else 0.0)
        one_s, n_straight, ubx, uby = _k.angle_stats(np.ascontiguousarray(st), c_in[2], c_in[3], dur, rx, ry)
        single_s.append(one_s)
        straight.append(n_straight)
        ub.append(ub_zE + (ubx if X in gated else 0.0) + (uby if Y in gated else 0.0))
    return _AngleTable(steps_list, np.array(snaps), np.array(single_s), np.array(straight, np.int64),
                       np.array(ub))


def _built_idle_intervals(o: GatingOptions, angles_deg, table: _AngleTable, t: _Timing,
                          rates: _Rates) -> tuple[dict, np.ndarray]:
    """(idle-interval arrays of the angles built, (K,) bool built), angles pruned by their bound.

    Upper bound on what gating can save at each angle: every motor off whenever it does not step
    (no start-ahead/end-late, no stall). Without budgets and with a non-negative XY correction, an
    angle whose bound is below the separable optimum of an angle already built cannot be optimal
    for any formulation, and gets no idle intervals (formulations/gating.md §6). (The best built
    angle's positive-net intervals are a feasible decision worth at least that much unless separate
    X and Y pins interact; a negative interaction could beat the bound.)"""
    xy_inter, ub = rates.xy_inter_w, table.saving_ub_j
    grp_of = {m: g for g in o.groups for m in g}
    coupled = X in grp_of and Y in grp_of and grp_of[X] != grp_of[Y] and bool(np.any(xy_inter != 0))
    prunable = not o.has_budget and not coupled and not np.any(xy_inter < 0)
    g_angle = greedy_angle(angles_deg, table.straight_moves)
    order = [g_angle] + [int(k) for k in np.argsort(-ub, kind="stable") if k != g_angle]
    built, best = [], -math.inf
    parts = []
    tol = 1e-9 * max(abs(float(rates.p0_w @ t.dur)), 1.0)
    for k in order:
        if prunable and k != g_angle and ub[k] < best - tol:
            continue
        gk = _idle_table(o, t, rates.group_rate_w, [table.steps[k]], [k])
        net = gk["idle_saving_j"] - gk["idle_stall_j"]
        # (under a schedule's rule B the positive intervals may not all be off together: the
        # bound of a built angle is then not reached, and no angle is pruned against it)
        if o.schedule is None or o.schedule.min_spacing_s <= 0:
            best = max(best, float(net[net > 0].sum()))
        built.append(k)
        parts.append(gk)
    ordk = np.argsort(built, kind="stable")
    idle = {nm: np.concatenate([parts[i][nm] for i in ordk]) for nm in parts[0]}
    has_idle = np.zeros(len(angles_deg), bool)
    has_idle[built] = True
    return idle, has_idle


def time_model_durations(program: Program, o: GatingOptions) -> np.ndarray:
    """Step durations under the options' time model (``build``'s default timeline)."""
    if o.time_model == "planner":
        limits = machine_limits(program, family=o.planner_family, printer=o.printer)
        return plan(program, limits).duration_s
    return program.duration_s


def _barrier_cum(program: Program, o: GatingOptions, enables_only: bool) -> np.ndarray:
    """(n+1, 4) cumulative count, per motor, of the steps where the firmware switches that motor
    itself: homing, and the file's own motor lines it carries out (``Firmware.reads``), and
    those beside a line that hands the machine over (``firmware.handoff_lines``). With
    ``enables_only`` (a stock dialect, whose lines switch at once) only the own lines that switch
    it on: a start G-code ``M17`` enables every motor, while an own disable inside an off interval
    leaves the motor as the interval has it, and homing enables only the axes it homes, which step
    (Marlin's ``G28``, Klipper's homing rails; the extruder is not one). No idle interval may span
    one: the motor is on after it whatever the interval's lines say, and what the verifier prices
    would not be the claim."""
    barrier = np.zeros((program.n_steps, 4), bool)
    if not enables_only:
        barrier[program.kind == Kind.HOME] = True
    # the lines that hand the machine over (a pause, a filament or tool change:
    # ``firmware.HANDOFF_M``): no motor off across one, in any dialect. They are no steps: the
    # steps on both sides of each count (an interval across the line holds at least one of them)
    at = np.searchsorted(program.line, fw_mod.handoff_lines(program))
    if program.n_steps and len(at):
        barrier[np.minimum(at, program.n_steps - 1)] = True
        barrier[np.maximum(at - 1, 0)] = True
    fw = fw_mod.get(o.firmware)
    for r in np.flatnonzero(program.kind == Kind.MOTOR).tolist():
        parsed = fw.reads(program.line_text(int(program.line[r])))
        if parsed is not None and (parsed[0] or not enables_only):
            barrier[r, [AXES.index(m) for m in parsed[1]]] = True
    cum = np.zeros((program.n_steps + 1, 4), np.int64)
    cum[1:] = np.cumsum(barrier, axis=0)
    return cum


def _timing(program: Program, o: GatingOptions, start_s, dur, stall_w) -> _Timing:
    """The timeline, the steps where the firmware switches motors itself (``_barrier_cum``) and
    a schedule's lower-bound clock."""
    # a schedule's module switches nothing across any own line (formulations/gating.md §9); a
    # stock dialect's off interval only not across an own enable
    cum = _barrier_cum(program, o, enables_only=o.schedule is None)
    if o.schedule is None:
        # steps no line may split (not moves; moves the dialect does not split: ``split_moves``)
        whole = np.ascontiguousarray(whole_steps(program.steps_motor(), program.kind, o.split_moves))
        return _Timing(start_s, dur, stall_w, None, cum, whole)
    lb = min_move_time_s(program, o.schedule.arc_segment_mm)
    return _Timing(start_s, dur, stall_w, np.concatenate(([0.0], np.cumsum(lb))), cum,
                   np.zeros(program.n_steps, bool))


def build(program: Program, options: GatingOptions | None = None, *, duration_s=None,
          coeffs: PowerCoefficients | None = None, stall_coeffs: PowerCoefficients | None = None,
          rotate_rows: tuple[int, int] | None = None) -> GatingProblem:
    """The gating problem of ``program`` (steps, coefficients, rotation candidates, idle intervals).

    ``duration_s`` overrides the options' time model (``options.time_model``: "paper", T = L / F;
    "planner": ``planner.plan`` with the printer's limits, ``limits.machine_limits`` with
    ``options.printer`` and ``options.planner_family``).
    Rows [first extrusion, last extrusion] are the ones a rotation moves (start and end G-code
    such as purge lines and parking stay where the slicer put them); ``rotate_rows`` overrides.
    """
    o = options or GatingOptions()
    n = program.n_steps
    if n == 0:
        raise GatesoptError(f"{program.source}: no timed steps: nothing to gate")
    if duration_s is None:
        duration_s = time_model_durations(program, o)
    dur = np.asarray(duration_s, float)
    if dur.shape != (n,) or not np.all(np.isfinite(dur)) or np.any(dur < 0):
        raise GatesoptError(f"{program.source}: duration_s must be {n} finite non-negative numbers")
    prof = load_profile(o.profile)
    if coeffs is None:
        coeffs = prof.coefficients(program)
    if stall_coeffs is None:
        stall_coeffs = prof.coefficients(_stall_program(program))
    enable0 = np.asarray(program.enabled, bool)
    start_s = np.concatenate(([0.0], np.cumsum(dur)))
    T = float(start_s[-1])
    rates = _motor_rates(coeffs, enable0, o)
    rate = rates.rate_w
    stall_w = step_power_w(stall_coeffs, enable0)
    own_row, own_s = _own_stalls(program, o.firmware, o)
    stop_at, stop_in = _stop_prices(program, o)

    steps0 = np.asarray(program.steps_motor(), bool)
    arc = np.asarray(program.kind == Kind.ARC)
    lo, hi = rotated_rows(program) if rotate_rows is None else (int(rotate_rows[0]), int(rotate_rows[1]))
    center = rotation_center(program, lo, hi)
    gated = o.motor_index
    asym = (X in gated) != (Y in gated) or not np.array_equal(rate[:, X], rate[:, Y])
    plan = rotation_candidates(program, o, lo, hi, center, asym, dur, steps0, arc)
    angles, notes = list(plan.angles_deg), list(plan.notes)
    angles_arr = np.array(angles)
    table = _angle_table(program, o, angles, lo, hi, center, dur, rate, steps0, arc)
    timing = dataclasses.replace(_timing(program, o, start_s, dur, stall_w), stop_at_s=stop_at, stop_in_s=stop_in)
    idle, has_idle = _built_idle_intervals(o, angles_arr, table, timing, rates)
    energy_before = float(step_energy_j(dur, coeffs, enable0).sum()
                          + step_energy_j(own_s, stall_coeffs.take(own_row), enable0[own_row]).sum())
    ro = readonly
    return GatingProblem(
        options=o, source=program.source, n_lines=max(int(program.n_lines), n), duration_s=ro(dur),
        start_s=ro(start_s), coeffs=coeffs, stall_coeffs=stall_coeffs, enable0=ro(enable0),
        rate_w=ro(rate), xy_inter_w=ro(rates.xy_inter_w),
        start_mm=ro(np.asarray(program.start_mm, float)),
        end_mm=ro(np.asarray(program.end_mm, float)), steps_motor0=ro(steps0), arc=ro(arc),
        layer=ro(np.asarray(program.layer, np.int32)),
        rotate_lo=lo, rotate_hi=hi, center_mm=ro(center), angles_deg=ro(angles_arr),
        angle_snap_mm=ro(table.snap_mm), angle_single_axis_s=ro(table.single_axis_s),
        angle_straight_moves=ro(table.straight_moves), angle_saving_ub_j=ro(table.saving_ub_j),
        angle_built=ro(has_idle),
        **{k: ro(v) for k, v in idle.items()},
        energy_before_j=energy_before, time_before_s=T + float(own_s.sum()), header=dict(program.header),
        notes=tuple(notes), rotation_plan=plan, own_stall_row=ro(own_row.astype(np.int64)), own_stall_s=ro(own_s),
        stop_at_s=ro(stop_at), stop_in_s=ro(stop_in))
