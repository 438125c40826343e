"""Scoring: the single place that turns off intervals into energy, lines and time.

A decision (per-motor off intervals on the problem's timeline) is cut at every instruction into
``Pieces`` scored with the one energy function (``gatesopt.energy.step_energy_j``), plus one stall
piece per instruction line; ``Instructions`` are the lines it needs, in time order (what the
emitter writes). formulations/gating.md §1 "Scoring", equation (1).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..energy import step_energy_j
from ..program import AXES
from .problem import GatingProblem, off_stall_s, on_stall_s, steps_motor_at
from .timeline import TIME_EPS_S, is_split, nearest_boundary, row_at


@dataclass(frozen=True, eq=False)
class Pieces:
    """The print cut at every gating instruction: scored with the one energy function.

    ``energy_j(problem)`` == ``step_energy_j(duration_s, coeffs.take(row), enable)`` summed, with
    ``stall_coeffs`` for the stall pieces.
    """

    row: np.ndarray         # (k,) step each piece belongs to
    duration_s: np.ndarray  # (k,)
    enable: np.ndarray      # (k, 4) bool
    stall: np.ndarray       # (k,) bool: a firmware stall at an instruction line (not a step piece)

    def energy_j(self, problem: GatingProblem) -> float:
        s = self.stall
        e = step_energy_j(self.duration_s[~s], problem.coeffs.take(self.row[~s]), self.enable[~s]).sum()
        if s.any():
            e += step_energy_j(self.duration_s[s], problem.stall_coeffs.take(self.row[s]), self.enable[s]).sum()
        return float(e)


@dataclass(frozen=True, eq=False)
class Instructions:
    """The gating instruction lines a solution needs, in time order (what emit writes).

    One entry per (moment, direction) line when ``merge_lines``, else per (moment, direction, motor).
    ``row``: the step the line goes into; ``split``: the line falls strictly inside that step (which
    is split there, at ``fraction`` of its duration); otherwise it goes right before the step.
    """

    time_s: np.ndarray      # (k,)
    row: np.ndarray         # (k,) int64
    on: np.ndarray          # (k,) bool: True = enable line, False = disable line
    motor_mask: np.ndarray  # (k,) uint8: bit m set = motor m (axis index) switched by the line
    split: np.ndarray       # (k,) bool
    fraction: np.ndarray    # (k,) position inside the row, 0..1 (0 when not split)
    stall_s: np.ndarray     # (k,) firmware stall of each line

    @property
    def motors(self) -> "_MotorLists":
        """``motors[k]``: tuple of the axis indices switched by line k (X Y Z E order)."""
        return _MotorLists(self.motor_mask)


class _MotorLists:
    """Sequence view of a motor bitmask array: item k is a tuple of axis indices."""

    _TUPLES = tuple(tuple(m for m in range(4) if b >> m & 1) for b in range(16))

    def __init__(self, mask):
        self._mask = mask

    def __len__(self):
        return len(self._mask)

    def __getitem__(self, k):
        return self._TUPLES[int(self._mask[k])]

    def __iter__(self):
        return (self._TUPLES[b] for b in self._mask.tolist())



def normalise(problem, off_motor, off_start_s, off_end_s):
    """Off intervals sorted by motor and time; an interval of a motor on a shared enable pin is an
    interval of every motor of its group (duplicates dropped)."""
    m = np.asarray(off_motor, np.int64).ravel()
    a = np.asarray(off_start_s, float).ravel()
    b = np.asarray(off_end_s, float).ravel()
    keep = b > a + TIME_EPS_S
    m, a, b = m[keep], a[keep], b[keep]
    groups = [g for g in problem.options.groups if len(g) > 1]
    if groups and len(m):
        ms, as_, bs = [m], [a], [b]
        for g in groups:
            sel = np.isin(m, g)
            for x in g:
                ms.append(np.full(int(sel.sum()), x))
                as_.append(a[sel])
                bs.append(b[sel])
        m, a, b = np.concatenate(ms), np.concatenate(as_), np.concatenate(bs)
        order = np.lexsort((b, a, m))
        m, a, b = m[order], a[order], b[order]
        new = np.ones(len(m), bool)
        new[1:] = (m[1:] != m[:-1]) | (a[1:] != a[:-1]) | (b[1:] != b[:-1])
        return m[new], a[new], b[new]
    order = np.lexsort((a, m))
    return m[order], a[order], b[order]


def line_moments(problem, motor, t_off) -> tuple[np.ndarray, np.ndarray]:
    """(moment, row) of the off lines of intervals of ``motor`` that go off at ``t_off``: the off
    moment itself, in the step that holds it; with a firmware that times its own switches
    (``options.schedule``) the step boundary ``off_margin_s`` before it, where the line goes
    right after the motor's last step (the line stands before that row)."""
    o = problem.options
    if o.schedule is None:
        return t_off, row_at(problem.start_s, t_off, "off")
    margin = np.array([o.off_margin_s(i) for i in range(4)])
    r = nearest_boundary(problem.start_s, np.asarray(t_off, float) - margin[np.asarray(motor, np.int64)])
    return problem.start_s[r], r


def instructions(problem, off_motor, off_start_s, off_end_s) -> Instructions:
    """The instruction lines of off intervals, in time order (one per moment and direction when
    ``merge_lines``), each placed in the step that holds it."""
    o = problem.options
    n = problem.n_steps
    T = problem.total_s
    m, a, b = normalise(problem, off_motor, off_start_s, off_end_s)
    t_off, r_off = line_moments(problem, m, a)
    has_on = (b < T - TIME_EPS_S) & o.on_line
    t_on, r_on = b[has_on], row_at(problem.start_s, b[has_on], "on")
    t = np.concatenate((t_off, t_on))
    r = np.concatenate((r_off, r_on)).astype(np.int64)
    on = np.concatenate((np.zeros(len(t_off), bool), np.ones(len(t_on), bool)))
    mot = np.concatenate((m, m[has_on]))
    if len(t) == 0:
        z = np.zeros(0)
        return Instructions(z, z.astype(np.int64), z.astype(bool), z.astype(np.uint8), z.astype(bool), z, z)
    order = np.lexsort((mot, on, t))
    t, r, on, mot = t[order], r[order], on[order], mot[order]
    bits = (1 << mot).astype(np.uint8)
    if o.merge_lines:
        # one line per (moment, direction): exactly the same time and the same on/off
        new = np.ones(len(t), bool)
        new[1:] = (t[1:] != t[:-1]) | (on[1:] != on[:-1])
        first = np.flatnonzero(new)
        bits = np.bitwise_or.reduceat(bits, first).astype(np.uint8)
        t, r, on = t[first], r[first], on[first]
    split = is_split(problem.start_s, r, t)
    r0 = np.minimum(r, max(n - 1, 0))
    frac = np.where(split, (t - problem.start_s[r0]) / np.where(problem.duration_s[r0] > 0,
                                                                problem.duration_s[r0], 1.0), 0.0)
    # a line's stall: per move where the dialect's lines are stops (Klipper's flush)
    stall = np.where(on, on_stall_s(problem, r, split), off_stall_s(problem, r, split))
    return Instructions(t, r, on, bits, split, frac, stall.astype(float))


def pieces(problem, off_motor, off_start_s, off_end_s, ins: Instructions | None = None) -> Pieces:
    """The print cut at every off interval's ends, with the motors each piece runs with, plus one
    stall piece per instruction line (``ins``, computed if not given) and per own motor line."""
    n = problem.n_steps
    m, a, b = normalise(problem, off_motor, off_start_s, off_end_s)
    start_s = problem.start_s
    cuts = np.unique(np.concatenate((a, b)))
    cuts = cuts[(cuts > 0) & (cuts < problem.total_s)]
    # step boundaries plus every instruction time (both sorted: merge by insertion); pieces are
    # the intervals between them, a piece after a cut belongs to the step holding the cut
    at = np.searchsorted(start_s, cuts, "right")
    bounds = np.insert(start_s, at, cuts)
    row_of = np.insert(np.arange(n + 1), at, row_at(start_s, cuts, "off"))
    p_row = np.minimum(row_of[:-1], n - 1)
    p_dur = np.diff(bounds)
    keep = p_dur > 0
    p_row, p_lo, p_dur = p_row[keep], bounds[:-1][keep], p_dur[keep]
    mid = p_lo + p_dur / 2.0
    enable = problem.enable0[p_row].copy()
    for mm in np.unique(m):
        sel = m == mm
        aa, bb = a[sel], b[sel]
        j = np.searchsorted(aa, mid, "right") - 1
        off = (j >= 0) & (mid < bb[np.maximum(j, 0)])
        enable[off, mm] = False
    # firmware stalls: one piece per instruction line, motors as in the file (no gating credit);
    # the file's own motor lines stall too, whatever gating does (``GatingProblem.own_stall_s``)
    if ins is None:
        ins = instructions(problem, m, a, b)
    st = ins.stall_s > 0
    s_row = np.concatenate((np.minimum(ins.row[st], n - 1), problem.own_stall_row)).astype(np.int64)
    row = np.concatenate((p_row, s_row)).astype(np.int64)
    dur = np.concatenate((p_dur, ins.stall_s[st], problem.own_stall_s))
    en = np.concatenate((enable, problem.enable0[s_row]))
    stall = np.concatenate((np.zeros(len(p_row), bool), np.ones(len(s_row), bool)))
    return Pieces(row, dur, en, stall)


@dataclass(frozen=True)
class Score:
    energy_j: float
    lines_added: int
    added_time_s: float


def score(problem: GatingProblem, off_motor, off_start_s, off_end_s) -> Score:
    """Energy (one energy function over the pieces), added lines and stall time of off intervals."""
    ins = instructions(problem, off_motor, off_start_s, off_end_s)
    p = pieces(problem, off_motor, off_start_s, off_end_s, ins)
    # a step split at one moment is split once, whatever number of lines go there
    split_t = np.unique(ins.time_s[ins.split])
    lines = len(ins.time_s) + len(split_t)
    return Score(p.energy_j(problem), int(lines), float(ins.stall_s.sum()))


def check_feasible(problem: GatingProblem, angle_index: int, off_motor, off_start_s, off_end_s) -> list[str]:
    """Violations of the gating invariants (empty list = feasible): every off interval of motor m
    keeps its on margin before and its off margin after every step of m (``options.on_margin_s``:
    start-ahead, 0 when re-enable is automatic at the first step, plus a firmware's own lead;
    ``off_margin_s``), and intervals of one motor do not overlap. Under a firmware schedule, rule
    B between consecutive intervals of a motor too (rule A holds for every idle interval built)."""
    o = problem.options
    steps, _ = steps_motor_at(problem, angle_index)
    m, a, b = normalise(problem, off_motor, off_start_s, off_end_s)
    bad = []
    tol = 1e-9
    for mm in np.unique(m):
        sel = m == mm
        aa, bb = a[sel], b[sel]
        if np.any(aa[1:] < bb[:-1] - tol):
            bad.append(f"motor {AXES[mm]}: overlapping off intervals")
        bad += _spacing_violations(problem, angle_index, int(mm), aa, bb)
        rows = np.flatnonzero(steps[:, mm])
        lo = problem.start_s[rows] - o.on_margin_s(int(mm))
        hi = problem.start_s[rows + 1] + o.off_margin_s(int(mm))
        # any required interval (lo, hi) intersecting an off interval (aa, bb)?
        j = np.searchsorted(aa, hi - tol, "left") - 1
        hit = (j >= 0) & (bb[np.maximum(j, 0)] > lo + tol)
        if hit.any():
            r = rows[np.argmax(hit)]
            bad.append(f"motor {AXES[mm]}: off within start-ahead/end-late of step {r}")
    return bad


def _spacing_violations(problem: GatingProblem, angle_index: int, motor: int, a, b) -> list[str]:
    """Rule B of a firmware schedule between consecutive off intervals (a, b) of ``motor``, each
    one of the problem's idle intervals."""
    if not problem.has_spacing or len(a) < 2:
        return []
    g = np.flatnonzero((problem.idle_angle == angle_index) & (problem.idle_motor == motor))
    j = np.searchsorted(problem.idle_start_s[g], a)
    if np.any(j >= len(g)) or np.any(np.abs(problem.idle_start_s[g[np.minimum(j, len(g) - 1)]] - a) > 1e-9):
        return [f"motor {AXES[motor]}: an off interval that is no idle interval under the firmware's schedule"]
    g = g[j]
    off, on = problem.idle_lb_off_s[g], problem.idle_lb_on_s[g]
    if not np.all(problem.spacing_ok(motor, off[:-1], on[:-1], off[1:], on[1:], tol_s=1e-12)):
        sch = problem.options.schedule
        what = ("an off within {:g} s of the previous on" if sch.pin_queue_slots == 1 else
                "an off or an on within {:g} s of the one before the previous change")
        return [f"motor {AXES[motor]}: rule B: " + what.format(sch.min_spacing_s)]
    return []
