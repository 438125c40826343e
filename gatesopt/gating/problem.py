"""Power-gating problem and solution: plain data over numpy arrays.

3DGates (Chen et al., ASPLOS'17) Section 4: for each motor m the steps that move its axis must run
with it on; it is switched on at least Start-Ahead (``start_ahead_s``, instruction inertia) before
its first step and kept on at least End-Late (``end_late_s``, instruction delay) after its last.
Between those *required on-intervals* lie *gaps*; a gap may be switched off. The math, with these
symbol names, is in ``formulations/gating.md``.

Everything here is on the problem's *timeline*: step ``i`` runs from ``start_s[i]`` to
``start_s[i + 1]`` (the original print, no stalls). A firmware stall (Marlin's queue drain,
Klipper's dwell) is a separate piece of time at an instruction line, priced with the coefficients a
``Kind.MOTOR`` row at that step would get from the energy profile (``stall_coeffs``) and the motors as
the file has them (``enable0``): the whole printer keeps drawing power during a stall, no gating
credit is taken for it. The file's own motor lines (a start G-code ``M17``, a mid-print ``M84``) stall
as ``gatesopt.firmware.stall_durations`` says -- the function the verifier prices the output with --
a fixed cost in ``energy_before_j``/``time_before_s`` and one stall piece each in ``Pieces``.

Energy is computed ONLY with ``gatesopt.energy.step_power_w`` / ``step_energy_j`` (the one model):
``rate_w[i, m]`` is what switching motor m off saves per second in step i with the other motors
as in the file, ``xy_inter_w[i]`` is the correction when X and Y are both off (non-additive power;
0 under the paper profile's linear assumption).

Public names other modules rely on (emit, verify, CLI): ``GatingOptions``, ``GatingProblem``,
``GatingSolution``, ``Pieces``, ``build``, ``from_moves``, ``score``, ``steps_motor_at``,
``rotation_matrix``.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ..energy import PowerCoefficients, load_profile, step_energy_j, step_power_w
from ..errors import GatesoptError, InfeasibleError
from ..program import AXES, Kind, Program, X, Y
from ..solvers import STATUSES
from . import _kernels as _k

_TIME_EPS_S = 1e-12          # a boundary closer than this to a step boundary is on it (no split)


class GatingOptionsError(GatesoptError, ValueError):
    """Bad gating options (unknown motor, negative time, ...)."""


# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class GatingOptions:
    """What to gate, how the firmware behaves, and the budgets.

    Firmware numbers are plain numbers here; ``GatingOptions.for_firmware(name)`` fills them from
    the presets in ``gatesopt.firmware``.
    """

    motors: tuple[str, ...] = ("X", "Y")
    start_ahead_s: float = 1.8e-3       # 3DGates Sec. 4.2: NEMA 17 start-up delay
    end_late_s: float = 1.0e-3          # 3DGates Sec. 4.2: empirical stop delay
    rotate: str | float = "auto"        # "auto" | "none" | degrees (counter-clockwise)
    max_angles: int = 16                # cap on rotation candidates under "auto" (plus 0/30/60)
    snap_mm: float = 1e-3               # other-axis displacement below this -> single-axis move
    bed_size_mm: tuple[float, float] | None = None   # None: program.header["bed_size_mm"], else no check
    profile: str = "paper"              # energy profile name or TOML path
    firmware: str = "3dgates"           # label only (the numbers below are what the solver uses)
    stall_off_s: float = 0.0            # stall per off line (whole printer keeps drawing power)
    stall_on_s: float = 0.0             # stall per on line
    on_line: bool = True                # re-enable needs a line (False: automatic at the first step)
    merge_lines: bool = True            # instructions of several motors at one moment share a line
    max_added_time_pct: float | None = None    # budget on stall time, % of the print time
    max_added_lines_pct: float | None = None   # budget on added lines, % of the file's lines
    num_workers: int = 2                # CP-SAT workers
    seed: int = 0                       # CP-SAT random seed
    mip_rel_gap: float = 1e-6           # MILP/CP-SAT relative gap at which to stop
    neighbour_mm: float = 0.5           # greedy grouping threshold (3DGates Algorithm 1 neigh_t)
    shared_enable: tuple = ()           # groups of motors wired to one enable pin, e.g. (("X", "Y"),)

    def __post_init__(self):
        motors = tuple(str(m).upper() for m in self.motors)
        bad = [m for m in motors if m not in AXES]
        if bad or not motors or len(set(motors)) != len(motors):
            raise GatingOptionsError(f"motors must be distinct letters of {','.join(AXES)}, not "
                                     f"{','.join(self.motors) or 'nothing'}")
        object.__setattr__(self, "motors", tuple(m for m in AXES if m in motors))
        for name in ("start_ahead_s", "end_late_s", "stall_off_s", "stall_on_s", "snap_mm"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise GatingOptionsError(f"{name} must be a finite number >= 0, not {v!r}")
        for name in ("max_added_time_pct", "max_added_lines_pct"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v >= 0):
                raise GatingOptionsError(f"{name} must be >= 0 or None, not {v!r}")
        r = self.rotate
        if isinstance(r, str) and r not in ("auto", "none"):
            try:
                r = float(r)
            except ValueError:
                raise GatingOptionsError(f"rotate must be 'auto', 'none' or degrees, not {r!r}") from None
            object.__setattr__(self, "rotate", r)
        if not isinstance(self.rotate, str) and not math.isfinite(float(self.rotate)):
            raise GatingOptionsError(f"rotate must be finite, not {self.rotate!r}")
        if self.bed_size_mm is not None:
            b = tuple(float(v) for v in self.bed_size_mm)
            if len(b) != 2 or min(b) <= 0:
                raise GatingOptionsError(f"bed_size_mm must be two positive numbers, not {self.bed_size_mm!r}")
            object.__setattr__(self, "bed_size_mm", b)
        if self.max_angles < 1:
            raise GatingOptionsError("max_angles must be >= 1")
        groups, seen = [], set()
        for grp in self.shared_enable:
            g = tuple(m for m in AXES if m in {str(x).upper() for x in grp})
            if len(g) < 2 or len(g) != len(tuple(grp)) or seen & set(g):
                raise GatingOptionsError(f"shared_enable groups must be disjoint sets of 2+ motors of "
                                         f"{','.join(AXES)}, not {grp!r}")
            inside = [m for m in g if m in self.motors]
            if inside and len(inside) != len(g):
                raise GatingOptionsError(f"motors {','.join(g)} share one enable pin: gate all of them or none")
            seen |= set(g)
            groups.append(g)
        object.__setattr__(self, "shared_enable", tuple(groups))

    @property
    def motor_index(self) -> tuple[int, ...]:
        return tuple(AXES.index(m) for m in self.motors)

    @property
    def groups(self) -> tuple[tuple[int, ...], ...]:
        """Gated motors by enable pin: each a tuple of axis indices, its first the representative
        that carries the group's gaps (a motor with its own pin is a group of one)."""
        out = []
        for m in self.motors:
            grp = next((g for g in self.shared_enable if m in g), (m,))
            if grp[0] == m:
                out.append(tuple(AXES.index(x) for x in grp))
        return tuple(out)

    @property
    def has_budget(self) -> bool:
        return self.max_added_time_pct is not None or self.max_added_lines_pct is not None

    def replace(self, **changes) -> "GatingOptions":
        return dataclasses.replace(self, **changes)

    @classmethod
    def for_firmware(cls, firmware: str = "3dgates", **changes) -> "GatingOptions":
        """Options with the stall/line numbers of a ``gatesopt.firmware`` preset."""
        from .. import firmware as fw_mod   # the firmware module owns the presets
        c = fw_mod.gating_costs(firmware)
        kw = dict(firmware=c.firmware, stall_off_s=c.stall_off_s, stall_on_s=c.stall_on_s,
                  on_line=c.on_lines_per_gate > 0, merge_lines=c.off_lines_merged)
        kw.update(changes)
        opts = cls(**kw)
        fw_mod.get(firmware).check_motors(opts.motors)
        return opts


# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class GatingProblem:
    """One gating instance: steps, energy coefficients, rotation candidates and the gap table.

    Gap arrays (prefix ``gap_``) are flattened over (angle, motor) and sorted by angle, motor, time.
    A gap is an open interval ``(gap_start_s, gap_end_s)`` of motor ``gap_motor`` (axis index, X=0)
    under rotation ``angles_deg[gap_angle]`` in which the motor does not have to be on.
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
    center_xy: np.ndarray          # (2,) rotation centre (XY bbox centre of the rotated rows)
    # --- rotation candidates (K) --------------------------------------------------------------
    angles_deg: np.ndarray         # (K,) counter-clockwise rotation about center_xy
    angle_snap_mm: np.ndarray      # (K,) largest other-axis displacement snapped to 0 at that angle
    angle_single_axis_s: np.ndarray  # (K,) time of XY moves that run on one axis at that angle
    angle_straight_moves: np.ndarray  # (K,) count of straight X + straight Y moves (greedy's criterion)
    angle_saving_ub_j: np.ndarray  # (K,) upper bound on the energy gating can save at that angle
    angle_built: np.ndarray        # (K,) bool: gaps built; False = pruned by the bound (never optimal)
    # --- gaps (G) -----------------------------------------------------------------------------
    gap_angle: np.ndarray          # (G,) int32 index into angles_deg
    gap_motor: np.ndarray          # (G,) int8 axis index (0..3)
    gap_start_s: np.ndarray        # (G,) off may start here (last step of m + end_late_s), or 0
    gap_end_s: np.ndarray          # (G,) must be on again here (next step of m - start_ahead_s), or T
    gap_off_row: np.ndarray        # (G,) int64 row at (or in) which the off instruction takes effect
    gap_on_row: np.ndarray         # (G,) int64 row at (or in) which the on instruction takes effect (n: none)
    gap_prev_row: np.ndarray       # (G,) int64 last row stepping the motor before the gap (-1: none)
    gap_next_row: np.ndarray       # (G,) int64 first row stepping the motor after the gap (n: none)
    gap_saving_j: np.ndarray       # (G,) energy saved by the motor being off (others as in the file)
    gap_lines: np.ndarray          # (G,) int lines this gap adds on its own (off + on + splits)
    gap_stall_s: np.ndarray        # (G,) stall time this gap adds on its own
    gap_stall_j: np.ndarray        # (G,) energy of that stall
    # --- totals without gating (the file's own motor-line stalls included) ---------------------
    energy_before_j: float = 0.0
    time_before_s: float = 0.0     # total_s + own_stall_s.sum()
    header: dict = field(default_factory=dict, repr=False)
    notes: tuple[str, ...] = ()    # what the user should know about the choices made (rotation)
    # --- the file's own motor lines (start G-code M17, a mid-print M84 ...) -----------------------
    # their firmware stalls (``gatesopt.firmware.stall_durations``, as the verifier prices them):
    # a fixed cost of the print, whatever gating does; one stall piece each in ``Pieces``
    own_stall_row: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64), repr=False)
    own_stall_s: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    @property
    def n_steps(self) -> int:
        return len(self.duration_s)

    @property
    def n_gaps(self) -> int:
        return len(self.gap_start_s)

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
    def gap_net_j(self) -> np.ndarray:
        """Energy a gap saves on its own, stall included (the dp's decision value)."""
        return self.gap_saving_j - self.gap_stall_j

    def gaps_of(self, angle_index: int) -> np.ndarray:
        """Indices of the gaps of one rotation candidate (a contiguous range; empty if pruned)."""
        lo, hi = np.searchsorted(self.gap_angle, [angle_index, angle_index + 1])
        return np.arange(lo, hi)

    @property
    def separable(self) -> bool:
        """True when gaps are independent: no budgets, no shared stall, additive XY power."""
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
                f"gaps={self.n_gaps}, motors={','.join(self.options.motors)})")


# ------------------------------------------------------------------------------------------------
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


@dataclass(frozen=True, eq=False)
class GatingSolution:
    """Decisions (rotation + per-motor off intervals), objective and solver report."""

    problem: GatingProblem = field(repr=False)
    formulation: str
    status: str                     # "optimal" | "feasible" | "fallback" | "infeasible"
    angle_index: int
    off_motor: np.ndarray           # (k,) int8 axis index
    off_start_s: np.ndarray         # (k,) on the problem's timeline
    off_end_s: np.ndarray           # (k,)
    energy_j: float                 # total energy after gating (step_energy_j over pieces())
    energy_before_j: float
    lines_added: int
    added_time_s: float
    bound: float = math.nan         # lower bound on energy_j (J) where the method has one
    gap: float = math.nan           # (energy_j - bound) / energy_j
    solve_s: float = 0.0
    message: str = ""

    @property
    def rotation_deg(self) -> float:
        return float(self.problem.angles_deg[self.angle_index])

    @property
    def center_xy(self) -> np.ndarray:
        return self.problem.center_xy

    @property
    def max_snap_mm(self) -> float:
        return float(self.problem.angle_snap_mm[self.angle_index])

    @property
    def saving_j(self) -> float:
        return self.energy_before_j - self.energy_j

    @property
    def saving_pct(self) -> float:
        return 100.0 * self.saving_j / self.energy_before_j if self.energy_before_j else 0.0

    @property
    def time_after_s(self) -> float:
        return self.problem.time_before_s + self.added_time_s

    def off_time_s(self) -> dict:
        """Total off time per motor letter."""
        d = {AXES[m]: 0.0 for m in self.problem.motors}
        for m in self.problem.motors:
            sel = self.off_motor == m
            d[AXES[m]] = float((self.off_end_s[sel] - self.off_start_s[sel]).sum())
        return d

    def steps_motor(self) -> np.ndarray:
        """(n, 4) which motors step in each row under this solution's rotation."""
        return steps_motor_at(self.problem, self.angle_index)[0]

    def pieces(self) -> Pieces:
        return _pieces(self.problem, self.off_motor, self.off_start_s, self.off_end_s)

    def enable_pieces(self):
        """(row, duration_s, enable, stall) arrays: re-score with ``gatesopt.energy.step_energy_j``."""
        p = self.pieces()
        return p.row, p.duration_s, p.enable, p.stall

    def instructions(self) -> Instructions:
        return _instructions(self.problem, self.off_motor, self.off_start_s, self.off_end_s)

    def summary(self) -> dict:
        return {
            "formulation": self.formulation, "status": self.status,
            "energy_before_j": self.energy_before_j, "energy_after_j": self.energy_j,
            "saving_pct": self.saving_pct, "time_before_s": self.problem.time_before_s,
            "time_after_s": self.time_after_s, "lines_added": int(self.lines_added),
            "rotation_deg": self.rotation_deg, "center_xy": [float(v) for v in self.center_xy],
            "max_snap_mm": self.max_snap_mm, "off_time_s": self.off_time_s(),
            "bound": None if math.isnan(self.bound) else self.bound,
            "gap": None if math.isnan(self.gap) else self.gap, "solve_s": self.solve_s,
            "message": self.message,
        }

    def __repr__(self) -> str:
        return (f"GatingSolution({self.formulation}, {self.status}, rot={self.rotation_deg:.4f}, "
                f"energy {self.energy_before_j:.1f} -> {self.energy_j:.1f} J ({self.saving_pct:.2f} %), "
                f"+{self.lines_added} lines, +{self.added_time_s:.3f} s, gap={self.gap:.2e})")


# ------------------------------------------------------------------------------------------------
# Rotation
def rotation_matrix(deg: float) -> np.ndarray:
    """Counter-clockwise rotation; exact for multiples of 90 degrees."""
    k, r = divmod(float(deg), 90.0)
    if r == 0.0:
        c, s = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))[int(k) % 4]
    else:
        a = math.radians(deg)
        c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def _rotate_points(p, center, deg):
    """Points (k, 2) rotated counter-clockwise by ``deg`` about ``center``."""
    (c, ms), (s, c2) = rotation_matrix(deg)
    x = p[:, 0] - center[0]
    y = p[:, 1] - center[1]
    return np.column_stack((c * x + ms * y + center[0], s * x + c2 * y + center[1]))


def steps_motor_at(problem: GatingProblem, angle_index: int) -> tuple[np.ndarray, np.ndarray]:
    """((n, 4) bool steps, (n,) snapped other-axis displacement) under rotation ``angle_index``.

    At a non-zero angle an XY displacement below ``options.snap_mm`` is taken as zero: the emitter
    must write that coordinate exactly equal to the previous one (DESIGN.md "Rotation").
    """
    deg = float(problem.angles_deg[angle_index])
    return _steps_at(problem.start_mm, problem.end_mm, problem.steps_motor0, problem.arc,
                     problem.rotate_lo, problem.rotate_hi, problem.center_xy, deg, problem.options.snap_mm)


def _steps_at(start_mm, end_mm, steps0, arc, lo, hi, center, deg, snap_mm):
    """((n, 4) steps, (n,) snapped displacement) under rotation ``deg`` (see ``steps_motor_at``)."""
    if deg % 360.0 == 0.0 or hi <= lo:
        return steps0, np.zeros(len(steps0))
    (c, _), (s, _) = rotation_matrix(deg)
    steps = np.array(steps0, copy=True, order="C")
    xy = np.empty((len(steps0), 2), bool)
    snapped = np.empty(len(steps0))
    _k.rotated_steps(np.ascontiguousarray(start_mm[:, :2]), np.ascontiguousarray(end_mm[:, :2]),
                     np.ascontiguousarray(steps0), np.ascontiguousarray(arc), int(lo), int(hi),
                     float(center[0]), float(center[1]), float(c), float(s), float(snap_mm), xy, snapped)
    steps[:, :2] = xy
    return steps, snapped


def greedy_angle(angles_deg, straight_moves) -> int:
    """3DGates Algorithm 1 lines 6-8: among the 30-degree steps (0 always is one), the angle with the
    most straight X + Y moves; the first on a tie. A fixed --rotate angle is the only choice."""
    deg = np.asarray(angles_deg, float)
    steps30 = np.flatnonzero(np.abs(deg / 30.0 - np.round(deg / 30.0)) < 1e-9)
    if len(steps30) == 0:
        steps30 = np.arange(len(deg))
    return int(steps30[np.argmax(np.asarray(straight_moves)[steps30])])


def _bed_fits(start_mm, end_mm, lo, hi, center, deg, bed) -> bool:
    if bed is None or hi <= lo or deg % 360.0 == 0.0:
        return True         # the slicer's own placement is taken as valid
    pts = _rotate_points(end_mm[lo:hi, :2], center, deg)
    tol = 1e-6
    return bool(pts.min() >= -tol and pts[:, 0].max() <= bed[0] + tol and pts[:, 1].max() <= bed[1] + tol)


def _candidate_angles(start_mm, end_mm, duration_s, steps0, arc, lo, hi, center, opts, asym):
    """Rotation candidates (degrees in [0, 90), or [0, 180) when X and Y are not symmetric).

    An XY move of direction theta runs on one axis after rotating by (-theta mod 90); energy is
    piecewise constant in the angle and can only improve where a move becomes single-axis, so the
    optimum (snap tolerance 0, no bed limit) is one of these angles. We keep the ``max_angles`` with
    the most single-axis time, plus 0, 30, 60 (the paper's 30-degree sweep modulo 90).
    See formulations/gating.md "Rotation".
    """
    base = [0.0, 30.0, 60.0]
    rows = np.arange(lo, hi)
    d = end_mm[rows, :2] - start_mm[rows, :2]
    L = np.hypot(d[:, 0], d[:, 1])
    ok = (L > opts.snap_mm) & ~arc[rows] & (steps0[rows, X] | steps0[rows, Y])
    d, L, w = d[ok], L[ok], duration_s[rows][ok]
    cands = list(base)
    if len(L):
        theta = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
        a = np.mod(-theta, 90.0)
        a[a >= 90.0 - 1e-9] = 0.0
        # coarse bins of 1e-3 degree, weighted by time; the representative of a bin is the angle of
        # its longest move (the narrowest snap window)
        key = np.round(a * 1000.0).astype(np.int64)
        uk, inv = np.unique(key, return_inverse=True)
        wt = np.bincount(inv, weights=w)
        top = np.argsort(-wt, kind="stable")[: 2 * opts.max_angles]
        order = np.lexsort((-L, inv))
        first = order[np.searchsorted(inv[order], np.arange(len(uk)))]
        reps = np.round(a[first[top]], 6)
        # exact single-axis time of each representative (snap tolerance), keep the best
        dx, dy, wc = np.ascontiguousarray(d[:, 0]), np.ascontiguousarray(d[:, 1]), np.ascontiguousarray(w)

        def single_time(deg):
            t = np.radians(deg)
            return _k.single_axis_time(dx, dy, wc, math.cos(t), math.sin(t), float(opts.snap_mm))
        scores = np.array([single_time(r) for r in reps])
        best = reps[np.argsort(-scores, kind="stable")][: opts.max_angles]
        cands += [float(b) for b in best]
    out = []
    for c in cands:
        c = float(np.round(c % 90.0, 6))
        if c >= 90.0:
            c = 0.0
        if all(abs(c - o) > 1e-6 for o in out):
            out.append(c)
    if asym:
        out = out + [c + 90.0 for c in out]
    return out


# ------------------------------------------------------------------------------------------------
# Gaps
def _row_at(start_s, t, side):
    """Row whose time span holds t. side='off': the last row starting at t; 'on': the first."""
    n = len(start_s) - 1
    if side == "on":
        r = np.searchsorted(start_s, t - _TIME_EPS_S, "left")
        exact = (r <= n) & (np.abs(start_s[np.minimum(r, n)] - t) <= _TIME_EPS_S)
        r = np.where(exact, r, r - 1)
    else:
        r = np.searchsorted(start_s, t + _TIME_EPS_S, "right") - 1
    return np.clip(r, 0, n)


def _is_split(start_s, row, t):
    n = len(start_s) - 1
    r = np.minimum(row, n - 1) if n else row
    inside = (start_s[r] + _TIME_EPS_S < t) & (t < start_s[np.minimum(r + 1, n)] - _TIME_EPS_S)
    return inside & (row < n)


def _integral(cum, start_s, rate, t, row):
    """Integral of ``rate`` over [0, t] with ``row`` the row holding t (prefix sum + partial row)."""
    n = len(start_s) - 1
    r = np.minimum(row, n - 1)
    part = np.where(row < n, rate[r] * (t - start_s[r]), 0.0)
    return cum[row] + part


def _build_gaps(P, steps_list, angles_idx):
    """Gap table for all (angle, enable group) pairs. ``steps_list[k]``: (n,4) step mask of angle k.

    A group of motors on one enable pin is one gap owner (its first motor): it must be on whenever
    any member steps, and saves what all members draw (``P["group_rate_w"]``)."""
    o = P["options"]
    start_s = P["start_s"]
    dur = P["duration_s"]
    sa_eff = o.start_ahead_s if o.on_line else 0.0     # automatic re-enable happens at the step
    rates = {g[0]: np.ascontiguousarray(P["group_rate_w"][g[0]]) for g in o.groups}
    cums = {m: np.concatenate(([0.0], np.cumsum(r * dur))) for m, r in rates.items()}
    stall_w = np.ascontiguousarray(P["stall_w"])
    parts = []
    for k, steps in zip(angles_idx, steps_list):
        for grp in o.groups:
            m = grp[0]
            st = steps[:, list(grp)].any(axis=1) if len(grp) > 1 else steps[:, m]
            per_event = 1 if o.merge_lines else len(grp)     # one line per motor unless merged
            out = _k.gaps(start_s, np.ascontiguousarray(st), rates[m], cums[m], stall_w,
                          float(sa_eff), float(o.end_late_s), bool(o.on_line), float(o.stall_off_s),
                          float(o.stall_on_s), per_event)
            parts.append((k, m, out))
    names = ("gap_start_s", "gap_end_s", "gap_off_row", "gap_on_row", "gap_prev_row", "gap_next_row",
             "gap_saving_j", "gap_lines", "gap_stall_s", "gap_stall_j")
    res = {nm: np.concatenate([p[2][j] for p in parts]) for j, nm in enumerate(names)}
    res["gap_angle"] = np.concatenate([np.full(len(p[2][0]), p[0], np.int32) for p in parts])
    res["gap_motor"] = np.concatenate([np.full(len(p[2][0]), p[1], np.int8) for p in parts])
    return res


# ------------------------------------------------------------------------------------------------
# Builders
def _moves_program(start_mm, end_mm, duration_s, extruding=None, source="<moves>", layer=None) -> Program:
    """A minimal Program over another planner's move arrays (no G-code), for the energy profile."""
    s = np.zeros((len(start_mm), 4))
    e = np.zeros((len(end_mm), 4))
    s[:, : np.shape(start_mm)[1]] = start_mm
    e[:, : np.shape(end_mm)[1]] = end_mm
    n = len(s)
    d = e - s
    if extruding is None:
        extruding = d[:, 3] > 0
    extruding = np.asarray(extruding, bool)
    kind = np.full(n, Kind.TRAVEL, np.int8)
    xyz = np.any(d[:, :3] != 0, axis=1)
    kind[extruding & xyz] = Kind.EXTRUDE
    kind[~xyz & (d[:, 3] < 0)] = Kind.RETRACT
    kind[~xyz & (d[:, 3] > 0)] = Kind.UNRETRACT
    kind[~xyz & (d[:, 3] == 0)] = Kind.DWELL
    kind[(d[:, 2] != 0) & (d[:, 0] == 0) & (d[:, 1] == 0) & (d[:, 3] == 0)] = Kind.Z_ONLY
    dur = np.asarray(duration_s, float)
    length = np.linalg.norm(d[:, :3], axis=1)
    z = np.zeros(n)
    kw = dict(
        source=source, data=b"", line_start=np.arange(n + 1, dtype=np.int64), line=np.arange(n, dtype=np.int64),
        kind=kind, start_mm=s, end_mm=e, feed_mm_s=np.where(dur > 0, length / np.where(dur > 0, dur, 1), 0),
        length_mm=length, duration_s=dur, layer=np.zeros(n, np.int32) if layer is None else np.asarray(layer, np.int32), feature=np.full(n, -1, np.int16),
        fan=z.astype(np.float32), hotend_c=np.full(n, 200, np.float32), bed_c=np.full(n, 60, np.float32),
        arc_center_mm=np.full((n, 2), np.nan), arc_ccw=np.zeros(n, bool), offset_mm=np.zeros((n, 4)),
        relative_xyz=np.zeros(n, bool), relative_e=np.zeros(n, bool), inch=np.zeros(n, bool),
        enabled=np.ones((n, 4), bool), line_letter=np.full(n, ord("G"), np.uint8),
        line_number=np.ones(n, np.float32))
    names = {f.name for f in dataclasses.fields(Program)}
    return Program(**{k: v for k, v in kw.items() if k in names})


def from_moves(start_mm, end_mm, duration_s, options: GatingOptions | None = None, *, extruding=None,
               coeffs: PowerCoefficients | None = None, stall_coeffs: PowerCoefficients | None = None,
               bed_size_mm=None, layer=None, source: str = "<moves>") -> GatingProblem:
    """A problem from another planner's move arrays (no G-code).

    ``start_mm``/``end_mm``: (n, 2..4) X Y [Z [E]] in absolute mm; ``duration_s``: (n,) the planner's
    own times; ``layer`` (n,) optional layer index per move (the greedy groups by layer). ``coeffs`` overrides the profile's coefficients (e.g. measured powers); by default
    the profile in ``options`` prices each move as extrusion (ΔE > 0 or ``extruding``) or travel.
    """
    options = options or GatingOptions()
    program = _moves_program(np.atleast_2d(np.asarray(start_mm, float)),
                             np.atleast_2d(np.asarray(end_mm, float)), duration_s, extruding, source, layer)
    if bed_size_mm is not None:
        program = program.replace(header={"bed_size_mm": tuple(bed_size_mm)})
    return build(program, options, coeffs=coeffs, stall_coeffs=stall_coeffs, rotate_rows=(0, program.n_steps))


def rotated_run_end(program: Program, hi: int) -> int:
    """The first row at or after ``hi`` whose end point a rotation leaves where the slicer put it:
    where the rotated run [lo, hi) really ends.

    A caller ends the run at the first XY move after the print (``problem._rotate_rows``); that
    row is the transition (its start rotated, its end not). That is right for an absolute move,
    which names a position on the bed (parking, "present print"). It is wrong for a relative move
    (G91): "G1 X5 Y5" means 5 mm from where the head *is*, and after the rotated print the head
    is in the rotated frame -- Cura's end G-code "G91 / G1 X5 Y5 ;Wipe out" would otherwise be
    written as a travel to where the *unrotated* print ended, dragging the nozzle across the top
    of the print. So relative XY moves (lines and arcs), and rows that leave X/Y where they are,
    carry the rotation on: their end is rotated too, i.e. their XY delta is turned by the
    rotation alone. The run ends at the first row that sets X/Y to a position of its own: an
    absolute (G90) move or homing. Rows that do not move X/Y are passed over whatever their mode.
    """
    n = int(program.n_steps)
    hi = int(hi)
    if hi >= n:
        return n
    kind = program.kind[hi:]
    moves_xy = (program.end_mm[hi:, :2] != program.start_mm[hi:, :2]).any(axis=1) | (kind == Kind.ARC)
    own = moves_xy & ((kind == Kind.HOME) | ~np.asarray(program.relative_xyz[hi:], bool))
    k = np.flatnonzero(own)
    return hi + int(k[0]) if len(k) else n


def _rotate_rows(program: Program) -> tuple[int, int]:
    """Rows whose end point a rotation moves: from the XY move that reaches the first extrusion of
    the print (layer >= 0) up to, not including, the first move after the last extrusion that
    sets X/Y to a position of its own (an absolute move or homing). Those two are the
    transitions (one end rotated, one not); start and end G-code (purge line, parking) stay where
    the slicer put them. Relative (G91) moves after the print -- Cura's end G-code "G91 / G1 X5 Y5
    ;Wipe out" -- are inside the run: they move the head *from* the rotated print, so their XY
    delta is rotated (``rotated_run_end``); ending the run at such a move would make it a
    travel to where the unrotated print ended."""
    ext = np.flatnonzero(program.extruding & (program.layer >= 0))
    if not len(ext):
        return 0, 0
    steps = program.steps_motor()
    xy = (steps[:, X] | steps[:, Y]) & (program.kind != Kind.HOME)   # arcs step both; homing stays
    before = np.flatnonzero(xy[: ext[0]])
    lo = int(before[-1]) if len(before) else int(ext[0])
    hi = rotated_run_end(program, int(ext[-1]) + 1)
    return lo, hi


#: an extrusion this far below the highest one before it means the print went back down to the
#: bed: objects printed one after the other (PrusaSlicer "complete_objects", Cura "one at a
#: time"). Z-hops do not extrude and a layer is at most ~0.3 mm, so 1 mm is no ordinary layer.
SEQUENTIAL_DROP_MM = 1.0


def _sequential_drop(program: Program, lo: int, hi: int):
    """(row, z_mm, z_max_mm) of the first extrusion in rows [lo, hi) that lies more than
    SEQUENTIAL_DROP_MM below an earlier extrusion, or None. Such a print was laid out by the
    slicer so that the print head (an asymmetric shape: Cura's head polygon, the gantry) clears
    the objects already printed, in this position on the bed: a rotation does not keep that."""
    ext = np.flatnonzero(program.extruding[lo:hi]) + lo
    if len(ext) < 2:
        return None
    z = program.end_mm[ext, 2]
    high = np.maximum.accumulate(z)
    down = np.flatnonzero(z[1:] < high[:-1] - SEQUENTIAL_DROP_MM)
    if not len(down):
        return None
    i = int(down[0]) + 1
    return int(ext[i]), float(z[i]), float(high[i - 1])


def _sequential_words(drop) -> str:
    return (f"objects are printed one at a time (the print goes back down to Z={drop[1]:g} "
            f"after Z={drop[2]:g})")


def own_xy_disable(program: Program, lo: int, hi: int):
    """The first row in [lo, hi) whose own motor line switches the X or Y motor off
    (``firmware.xy_disable_rows``: a gated file, gatesopt's output or the paper's re-compiler's),
    or None. Such lines were placed for the moves of that file's X and Y axes; rotated, the moves
    each motor makes change, and the lines would hold a motor off while it steps."""
    from .. import firmware as fw_mod
    rows = fw_mod.xy_disable_rows(program)
    # a disable after the last X/Y step (the slicer's closing 'M84 X Y E', with no move after it
    # in the run) holds nothing off that steps: the print is over
    steps = program.steps_motor()
    xy = np.flatnonzero((steps[:, X] | steps[:, Y])[lo:hi])
    last_xy = lo + int(xy[-1]) if len(xy) else lo
    rows = rows[(rows >= lo) & (rows < min(hi, last_xy))]
    return int(rows[0]) if len(rows) else None


def _where(program: Program, row: int) -> str:
    return f"{program.source}:{int(program.line[row]) + 1}"


def _stall_program(program: Program) -> Program:
    """The program with every row turned into a Kind.MOTOR row at rest: the profile then prices a
    firmware stall at that step exactly as the verifier will price the re-parsed instruction."""
    n = program.n_steps
    return program.replace(kind=np.full(n, Kind.MOTOR, np.int8), start_mm=program.end_mm,
                           length_mm=np.zeros(n), duration_s=np.zeros(n),
                           arc_center_mm=np.full((n, 2), np.nan))


def build(program: Program, options: GatingOptions | None = None, *, duration_s=None,
          coeffs: PowerCoefficients | None = None, stall_coeffs: PowerCoefficients | None = None,
          rotate_rows: tuple[int, int] | None = None) -> GatingProblem:
    """The gating problem of ``program`` (steps, coefficients, rotation candidates, gaps).

    ``duration_s`` overrides the paper's time model (e.g. an acceleration-aware planner's times).
    Rows [first extrusion, last extrusion] are the ones a rotation moves (start and end G-code
    such as purge lines and parking stay where the slicer put them); ``rotate_rows`` overrides.
    """
    o = options or GatingOptions()
    n = program.n_steps
    if n == 0:
        raise GatesoptError(f"{program.source}: no timed steps: nothing to gate")
    dur = np.asarray(program.duration_s if duration_s is None else duration_s, float)
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

    # per-motor marginal power and the XY interaction, from the one energy model
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
    stall_w = step_power_w(stall_coeffs, enable0)
    # The file's own motor lines stall the firmware too (Marlin's M18 in start G-code drains the
    # queue, Klipper's M84 dwells), or not at all (Klipper has no M17: "Unknown command", skipped).
    # That is decided in one place, ``firmware.stall_durations``, which the verifier also prices
    # the output with; here it is a constant of the print, priced like a gating line's stall.
    own_s = np.zeros(n)
    if np.any(program.kind == Kind.MOTOR):
        from .. import firmware as fw_mod
        own_s = fw_mod.stall_durations(program, o.firmware)
    own_row = np.flatnonzero(own_s > 0)
    own_s = own_s[own_row]

    steps0 = np.asarray(program.steps_motor(), bool)
    arc = np.asarray(program.kind == Kind.ARC)
    lo, hi = _rotate_rows(program) if rotate_rows is None else (int(rotate_rows[0]), int(rotate_rows[1]))
    ext = np.flatnonzero(program.extruding[lo:hi]) + lo
    if len(ext):
        pts = np.concatenate((program.start_mm[ext, :2], program.end_mm[ext, :2]))
        center = (pts.min(axis=0) + pts.max(axis=0)) / 2.0
    else:
        center = np.zeros(2)
    bed = o.bed_size_mm
    if bed is None and program.header.get("bed_size_mm") is not None:
        bed = tuple(float(v) for v in program.header["bed_size_mm"])

    gated = o.motor_index
    asym = (X in gated) != (Y in gated) or not np.array_equal(rate[:, X], rate[:, Y])
    notes = []
    drop = _sequential_drop(program, lo, hi)
    if drop is not None and o.rotate not in ("auto", "none") and float(o.rotate) % 360.0 != 0.0:
        raise InfeasibleError(f"{_where(program, drop[0])}: {_sequential_words(drop)}; "
                              f"rotating it by {float(o.rotate):g} deg could drive the print head into "
                              f"an object already printed: use --rotate none")
    if drop is not None and o.rotate == "auto":
        notes.append(f"rotation kept at 0 deg: {_sequential_words(drop)} "
                     f"({_where(program, drop[0])}); rotated, the print head could hit an object "
                     f"already printed")
    own_off = None if o.rotate == "none" or hi <= lo else own_xy_disable(program, lo, hi)
    if own_off is not None:
        line = program.line_text(int(program.line[own_off])).strip()[:40]
        if o.rotate != "auto" and float(o.rotate) % 360.0 != 0.0:
            raise InfeasibleError(
                f"{_where(program, own_off)}: the file switches an X/Y motor off inside the print "
                f"itself ({line!r}: already gated?); rotated by {float(o.rotate):g} deg, that line "
                "would hold a motor off while it steps: use --rotate none, or gate the slicer's "
                "original")
        notes.append(f"rotation kept at 0 deg: the file switches an X/Y motor off inside the print "
                     f"itself ({_where(program, own_off)}: {line!r}; already gated?); rotated, "
                     "that line would hold a motor off while it steps")
    if (o.rotate == "none" or hi <= lo or not (X in gated or Y in gated) or drop is not None
            or own_off is not None):
        cands = [0.0]
    elif o.rotate == "auto":
        cands = _candidate_angles(program.start_mm, program.end_mm, dur, steps0, arc, lo, hi, center, o, asym)
    else:
        cands = [float(o.rotate) % 360.0]
    angles = []
    for c in cands:
        # a quarter turn more keeps the single-axis structure (swapping X and Y): try those if the
        # angle itself does not fit the bed
        tries = [c] if o.rotate != "auto" else [c, c + 180.0] + ([] if asym else [c + 90.0, c + 270.0])
        for t in tries:
            t = t % 360.0
            if _bed_fits(program.start_mm, program.end_mm, lo, hi, center, t, bed):
                angles.append(t)
                break
    if not angles:
        raise InfeasibleError(f"{program.source}: the print rotated by {cands[0]:g} deg about "
                              f"({center[0]:.3f}, {center[1]:.3f}) does not fit the {bed[0]:g} x {bed[1]:g} mm bed")
    angles_arr = np.array(angles)
    steps_list, snaps, single_s, straight, ub = [], [], [], [], []
    rdur = rate * dur[:, None]
    ub_zE = sum(float(rdur[:, m] @ ~steps0[:, m]) for m in gated if m not in (X, Y))
    c_in = (np.ascontiguousarray(program.start_mm[:, :2]), np.ascontiguousarray(program.end_mm[:, :2]),
            np.ascontiguousarray(steps0), np.ascontiguousarray(arc))
    rx, ry = np.ascontiguousarray(rdur[:, X]), np.ascontiguousarray(rdur[:, Y])
    for t in angles:
        st, snap = _steps_at(*c_in[:2], c_in[2], c_in[3], lo, hi, center, t, o.snap_mm)
        steps_list.append(st)
        snaps.append(float(snap.max()) if len(snap) else 0.0)
        one_s, n_straight, ubx, uby = _k.angle_stats(np.ascontiguousarray(st), c_in[2], c_in[3], dur, rx, ry)
        single_s.append(one_s)
        straight.append(n_straight)
        ub.append(ub_zE + (ubx if X in gated else 0.0) + (uby if Y in gated else 0.0))
    ub = np.array(ub)
    P = dict(options=o, start_s=start_s, duration_s=dur, rate_w=rate, stall_w=stall_w, group_rate_w=group_rate)
    # Upper bound on what gating can save at each angle: every motor off whenever it does not
    # step (no start-ahead/end-late, no stall). Without budgets and with a non-negative XY
    # correction, an angle whose bound is below the separable optimum of an angle already built
    # cannot be optimal for any formulation, and gets no gaps (formulations/gating.md §6).
    # (the best built angle's positive-net gaps are a feasible decision worth at least that much
    # unless separate X and Y pins interact; a negative interaction could beat the bound)
    grp_of = {m: g for g in o.groups for m in g}
    coupled = X in grp_of and Y in grp_of and grp_of[X] != grp_of[Y] and bool(np.any(xy_inter != 0))
    prunable = not o.has_budget and not coupled and not np.any(xy_inter < 0)
    g_angle = greedy_angle(angles_arr, np.array(straight))
    order = [g_angle] + [int(k) for k in np.argsort(-ub, kind="stable") if k != g_angle]
    built, best = [], -math.inf
    parts = []
    tol = 1e-9 * max(abs(float(p0 @ dur)), 1.0)
    for k in order:
        if prunable and k != g_angle and ub[k] < best - tol:
            continue
        gk = _build_gaps(P, [steps_list[k]], [k])
        net = gk["gap_saving_j"] - gk["gap_stall_j"]
        best = max(best, float(net[net > 0].sum()))
        built.append(k)
        parts.append(gk)
    ordk = np.argsort(built, kind="stable")
    gaps = {nm: np.concatenate([parts[i][nm] for i in ordk]) for nm in parts[0]}
    has_gaps = np.zeros(len(angles), bool)
    has_gaps[built] = True
    energy_before = float(step_energy_j(dur, coeffs, enable0).sum()
                          + step_energy_j(own_s, stall_coeffs.take(own_row), enable0[own_row]).sum())
    ro = lambda a: _readonly(a)
    return GatingProblem(
        options=o, source=program.source, n_lines=max(int(program.n_lines), n), duration_s=ro(dur),
        start_s=ro(start_s), coeffs=coeffs, stall_coeffs=stall_coeffs, enable0=ro(enable0),
        rate_w=ro(rate), xy_inter_w=ro(xy_inter), start_mm=ro(np.asarray(program.start_mm, float)),
        end_mm=ro(np.asarray(program.end_mm, float)), steps_motor0=ro(steps0), arc=ro(arc),
        layer=ro(np.asarray(program.layer, np.int32)),
        rotate_lo=lo, rotate_hi=hi, center_xy=ro(center), angles_deg=ro(angles_arr),
        angle_snap_mm=ro(np.array(snaps)), angle_single_axis_s=ro(np.array(single_s)),
        angle_straight_moves=ro(np.array(straight, np.int64)), angle_saving_ub_j=ro(ub),
        angle_built=ro(has_gaps),
        **{k: ro(v) for k, v in gaps.items()},
        energy_before_j=energy_before, time_before_s=T + float(own_s.sum()), header=dict(program.header),
        notes=tuple(notes), own_stall_row=ro(own_row.astype(np.int64)), own_stall_s=ro(own_s))


def _readonly(a):
    a = np.asarray(a)
    if a.flags.writeable:
        a = a.view()
        a.flags.writeable = False
    return a


# ------------------------------------------------------------------------------------------------
# Scoring: the single place that turns off intervals into energy, lines and time
def _normalise(problem, off_motor, off_start_s, off_end_s):
    """Off intervals sorted by motor and time; an interval of a motor on a shared enable pin is an
    interval of every motor of its group (duplicates dropped)."""
    m = np.asarray(off_motor, np.int64).ravel()
    a = np.asarray(off_start_s, float).ravel()
    b = np.asarray(off_end_s, float).ravel()
    keep = b > a + _TIME_EPS_S
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


def _instructions(problem, off_motor, off_start_s, off_end_s) -> Instructions:
    o = problem.options
    n = problem.n_steps
    T = problem.total_s
    m, a, b = _normalise(problem, off_motor, off_start_s, off_end_s)
    t_off, r_off = a, _row_at(problem.start_s, a, "off")
    has_on = (b < T - _TIME_EPS_S) & o.on_line
    t_on, r_on = b[has_on], _row_at(problem.start_s, b[has_on], "on")
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
    split = _is_split(problem.start_s, r, t)
    r0 = np.minimum(r, max(n - 1, 0))
    frac = np.where(split, (t - problem.start_s[r0]) / np.where(problem.duration_s[r0] > 0,
                                                                problem.duration_s[r0], 1.0), 0.0)
    stall = np.where(on, o.stall_on_s, o.stall_off_s)
    return Instructions(t, r, on, bits, split, frac, stall.astype(float))


def _pieces(problem, off_motor, off_start_s, off_end_s, ins: Instructions | None = None) -> Pieces:
    n = problem.n_steps
    m, a, b = _normalise(problem, off_motor, off_start_s, off_end_s)
    start_s = problem.start_s
    cuts = np.unique(np.concatenate((a, b)))
    cuts = cuts[(cuts > 0) & (cuts < problem.total_s)]
    # step boundaries plus every instruction time (both sorted: merge by insertion); pieces are
    # the intervals between them, a piece after a cut belongs to the step holding the cut
    at = np.searchsorted(start_s, cuts, "right")
    bounds = np.insert(start_s, at, cuts)
    row_of = np.insert(np.arange(n + 1), at, _row_at(start_s, cuts, "off"))
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
        ins = _instructions(problem, m, a, b)
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
    ins = _instructions(problem, off_motor, off_start_s, off_end_s)
    p = _pieces(problem, off_motor, off_start_s, off_end_s, ins)
    # a step split at one moment is split once, whatever number of lines go there
    split_t = np.unique(ins.time_s[ins.split])
    lines = len(ins.time_s) + len(split_t)
    return Score(p.energy_j(problem), int(lines), float(ins.stall_s.sum()))


def check_feasible(problem: GatingProblem, angle_index: int, off_motor, off_start_s, off_end_s) -> list[str]:
    """Violations of the gating invariants (empty list = feasible): every off interval of motor m
    keeps start_ahead_s before and end_late_s after every step of m (start-ahead 0 when re-enable is
    automatic at the first step), and intervals of one motor do not overlap."""
    o = problem.options
    steps, _ = steps_motor_at(problem, angle_index)
    m, a, b = _normalise(problem, off_motor, off_start_s, off_end_s)
    sa = o.start_ahead_s if o.on_line else 0.0
    bad = []
    tol = 1e-9
    for mm in np.unique(m):
        sel = m == mm
        aa, bb = a[sel], b[sel]
        if np.any(aa[1:] < bb[:-1] - tol):
            bad.append(f"motor {AXES[mm]}: overlapping off intervals")
        rows = np.flatnonzero(steps[:, mm])
        lo = problem.start_s[rows] - sa
        hi = problem.start_s[rows + 1] + o.end_late_s
        # any required interval (lo, hi) intersecting an off interval (aa, bb)?
        j = np.searchsorted(aa, hi - tol, "left") - 1
        hit = (j >= 0) & (bb[np.maximum(j, 0)] > lo + tol)
        if hit.any():
            r = rows[np.argmax(hit)]
            bad.append(f"motor {AXES[mm]}: off within start-ahead/end-late of step {r}")
    return bad


def make_solution(problem: GatingProblem, formulation: str, status: str, angle_index: int,
                  off_motor, off_start_s, off_end_s, *, bound=math.nan, solve_s=0.0,
                  message: str = "") -> GatingSolution:
    """Score off intervals with the one energy model and wrap them (every formulation ends here)."""
    if status not in STATUSES:
        raise ValueError(f"unknown status {status!r}")
    m, a, b = _normalise(problem, off_motor, off_start_s, off_end_s)
    sc = score(problem, m, a, b)
    gap = math.nan
    if not math.isnan(bound):
        gap = max(0.0, (sc.energy_j - bound) / max(abs(sc.energy_j), 1e-12))
    return GatingSolution(problem=problem, formulation=formulation, status=status,
                          angle_index=int(angle_index), off_motor=_readonly(m.astype(np.int8)),
                          off_start_s=_readonly(a), off_end_s=_readonly(b), energy_j=sc.energy_j,
                          energy_before_j=problem.energy_before_j, lines_added=sc.lines_added,
                          added_time_s=sc.added_time_s, bound=float(bound), gap=gap,
                          solve_s=float(solve_s), message=message)


def solution_from_gaps(problem: GatingProblem, formulation: str, status: str, angle_index: int,
                       chosen: np.ndarray, **kw) -> GatingSolution:
    """A solution that switches off the gaps with indices ``chosen``."""
    chosen = np.asarray(chosen, np.int64)
    return make_solution(problem, formulation, status, angle_index, problem.gap_motor[chosen],
                         problem.gap_start_s[chosen], problem.gap_end_s[chosen], **kw)
