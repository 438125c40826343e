"""How long a travel's moves take under a file's limits, move by move (issue 36, the time
objective): ``MoveTimes`` (per move kind an acceleration, a speed cap and a junction speed, from
``limits.MachineLimits``) and the trapezoid of one move. ``cost.TimePricer`` prices links with
them where the moves are not planned together (no file limits); moved here from ``cost`` whole."""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from .. import _planner_kernel as pk
from ..limits import MachineLimits
from ..program import MOTION_KINDS, Program
from .gap_plan import MOVE_EPS_MM, gaps_planned

#: a Marlin 2 (junction deviation) move starts from rest at MINIMUM_PLANNER_SPEED (planner.h)
REST_SPEED_MM_S = 0.05


@dataclass(frozen=True)
class MoveTimes:
    """Per move kind: acceleration (mm/s^2), speed cap (mm/s) and the junction speed a move
    starts and ends at (mm/s). A move of length L at nominal speed v takes the trapezoid
    ``trapezoid_s`` from and to that junction speed.

    The junction speed: under classic jerk (Marlin ``CLASSIC_JERK``, Prusa firmware) a move may
    start from rest at its axis jerk (the planner's "safe speed", ``planner.py``); under junction
    deviation and Klipper's square corner velocity a move started from rest starts at ~0 (and
    Klipper starts and ends extruder-only moves at rest)."""

    xy_accel_mm_s2: float = 1000.0
    xy_cap_mm_s: float = np.inf
    xy_junction_mm_s: float = 0.0
    wipe_accel_mm_s2: float = 1000.0      # a move with E steps (a wipe): the print acceleration
    e_accel_mm_s2: float = 1000.0
    e_cap_mm_s: float = np.inf
    e_junction_mm_s: float = 0.0
    z_accel_mm_s2: float = 100.0
    z_cap_mm_s: float = np.inf
    z_junction_mm_s: float = 0.0
    #: the planner's junction rule (``_planner_kernel.JUNCTION_CODE``) and the limits in force
    #: (``limits.KEYS`` order): a rebuilt travel's moves are then planned together, as the
    #: planner plans them (``plan_moves_s``); -1: each move alone, from and to its junction speed
    junction_code: int = -1
    limits_row: tuple = ()

    @staticmethod
    def from_limits(lim: MachineLimits) -> "MoveTimes":
        """The limits in force at the file's first motion step (``limits.machine_limits``)."""
        acc, feed, jerk = lim.max_accel_mm_s2, lim.max_feed_mm_s, lim.jerk_mm_s

        def finite_min(*v):
            v = [float(x) for x in v if np.isfinite(x) and x > 0]
            return min(v) if v else np.inf

        def junction(*axes):
            if lim.junction == "deviation":
                return REST_SPEED_MM_S
            if lim.junction != "jerk":
                return 0.0
            v = [float(jerk[a]) for a in axes if np.isfinite(jerk[a])]
            return min(v) if v else 0.0
        v_cap = lim.max_velocity_mm_s
        return MoveTimes(
            xy_accel_mm_s2=finite_min(lim.accel_travel_mm_s2, acc[0], acc[1]),
            xy_cap_mm_s=finite_min(feed[0], feed[1], v_cap),
            xy_junction_mm_s=junction(0, 1),
            wipe_accel_mm_s2=finite_min(lim.accel_print_mm_s2, acc[0], acc[1]),
            e_accel_mm_s2=finite_min(lim.accel_retract_mm_s2, acc[3]),
            e_cap_mm_s=finite_min(feed[3]),
            e_junction_mm_s=0.0 if lim.firmware == "klipper" else junction(3),
            z_accel_mm_s2=finite_min(lim.accel_travel_mm_s2, acc[2]),
            z_cap_mm_s=finite_min(feed[2], v_cap),
            z_junction_mm_s=junction(2),
            junction_code=pk.JUNCTION_CODE.get(lim.junction, -1),
            limits_row=tuple(float(x) for x in lim.vector()))

    def xy_s(self, length_mm, feed_mm_s):
        return trapezoid_s(length_mm, np.minimum(feed_mm_s, self.xy_cap_mm_s), self.xy_accel_mm_s2,
                           self.xy_junction_mm_s)

    def e_s(self, length_mm, feed_mm_s):
        return trapezoid_s(length_mm, np.minimum(feed_mm_s, self.e_cap_mm_s), self.e_accel_mm_s2,
                           self.e_junction_mm_s)

    def z_s(self, length_mm, feed_mm_s):
        return trapezoid_s(length_mm, np.minimum(feed_mm_s, self.z_cap_mm_s), self.z_accel_mm_s2,
                           self.z_junction_mm_s)

    def steps_s(self, program: Program, steps) -> np.ndarray:
        """Time of each of ``steps`` (non-extruding moves: a gap's travel, retraction, z-hop,
        wipe) under this model; 0 for steps that are not motion."""
        steps = np.asarray(steps, np.int64)
        d = program.end_mm[steps] - program.start_mm[steps]
        xy = np.hypot(d[:, 0], d[:, 1])
        feed = program.feed_mm_s[steps]
        kind = program.kind[steps]
        length = program.length_mm[steps]
        out = np.zeros(len(steps))
        motion = np.isin(kind, np.asarray(MOTION_KINDS, dtype=kind.dtype))
        e_only = motion & (xy <= MOVE_EPS_MM) & (np.abs(d[:, 2]) <= MOVE_EPS_MM)
        z_only = motion & (xy <= MOVE_EPS_MM) & ~e_only
        planar = motion & ~e_only & ~z_only
        wipe = planar & (np.abs(d[:, 3]) > 0)
        travel = planar & ~wipe
        out[e_only] = self.e_s(np.abs(d[e_only, 3]), feed[e_only])
        out[z_only] = self.z_s(np.abs(d[z_only, 2]), feed[z_only])
        out[travel] = self.xy_s(length[travel], feed[travel])
        out[wipe] = trapezoid_s(length[wipe], np.minimum(feed[wipe], self.xy_cap_mm_s),
                                self.wipe_accel_mm_s2, self.xy_junction_mm_s)
        return out

    def gaps_s(self, program: Program, a, b) -> np.ndarray:
        """Time (s) of each gap ``steps a[i]:b[i]`` of ``program`` (its motion steps: travel,
        retraction, z-hop, wipe): with the file's limits planned together as the planner plans
        them (``plan_moves_s``, from and to rest: the curves around a gap are not part of it),
        the way a rebuilt travel is priced; else each move alone (``steps_s``)."""
        a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
        if self.junction_code < 0:
            steps = np.concatenate([np.arange(x, y) for x, y in zip(a.tolist(), b.tolist())]
                                   + [np.zeros(0, np.int64)])
            owner = np.repeat(np.arange(len(a)), b - a)
            return np.bincount(owner, weights=self.steps_s(program, steps), minlength=len(a))
        kind = program.kind
        motion = (np.isin(kind, np.asarray(MOTION_KINDS, dtype=kind.dtype))
                  & (program.length_mm > MOVE_EPS_MM))
        d = np.ascontiguousarray(program.end_mm - program.start_mm)
        return gaps_planned(a, b, motion, d, np.ascontiguousarray(program.length_mm, float),
                             np.ascontiguousarray(program.feed_mm_s, float), self.junction_code,
                             np.asarray(self.limits_row, float))

    def vector(self) -> np.ndarray:
        """The parameters in field order (for the compiled kernels): the ten per-kind values,
        the junction code, then the limits row (``MT_ROW`` on)."""
        return np.array([self.xy_accel_mm_s2, self.xy_cap_mm_s, self.xy_junction_mm_s,
                         self.wipe_accel_mm_s2, self.e_accel_mm_s2, self.e_cap_mm_s,
                         self.e_junction_mm_s, self.z_accel_mm_s2, self.z_cap_mm_s,
                         self.z_junction_mm_s, float(self.junction_code), *self.limits_row], float)


def trapezoid_s(length_mm, speed_mm_s, accel_mm_s2, junction_mm_s):
    """Time (s) of a move of ``length_mm`` that starts and ends at ``junction_mm_s`` and may
    reach ``speed_mm_s`` accelerating at ``accel_mm_s2``: a trapezoid, or a triangle where it is
    too short to reach that speed (planner.py; Marlin ``calculate_trapezoid_for_block``)."""
    L = np.asarray(length_mm, float)
    shape = np.broadcast_shapes(L.shape, np.shape(speed_mm_s))
    L = np.ascontiguousarray(np.broadcast_to(L, shape)).ravel()
    v = np.ascontiguousarray(np.broadcast_to(np.asarray(speed_mm_s, float), shape)).ravel()
    out = _trapezoids(L, v, float(accel_mm_s2), float(junction_mm_s)).reshape(shape)
    return out if out.ndim else float(out)


@numba.njit(cache=True)
def _trapezoids(L, v, a, vj):
    out = np.empty(len(L))
    for i in range(len(L)):
        out[i] = trapezoid_one_s(L[i], v[i], a, vj)
    return out


@numba.njit(cache=True, inline="always")
def trapezoid_one_s(L, v, a, vj):
    """``trapezoid_s`` of one move, for the compiled kernels (``cost``)."""
    if L <= 0.0 or v <= 0.0:
        return 0.0
    if not np.isfinite(a) or a <= 0.0:
        return L / v
    v0 = min(vj, v)
    d_acc = (v * v - v0 * v0) / (2.0 * a)
    if L >= 2.0 * d_acc:
        return 2.0 * (v - v0) / a + (L - 2.0 * d_acc) / v
    return 2.0 * (np.sqrt(v0 * v0 + a * L) - v0) / a


#: where ``MoveTimes.vector()`` holds the junction code and the limits row
MT_CODE, MT_ROW = 10, 11
