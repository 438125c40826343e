"""Curve ordering problem, solution and options: plain data over numpy arrays.

Fleming et al. (continuous extrusion toolpaths), Section 3: a layer is a set of curves, each
traversable from either end; travel between curves is the Euclidean distance from the end of one
to the start of the next; the layer starts where the previous layer ended (Eq. 1). gatesopt
generalises this to *groups*: a layer is a sequence of groups that keep the slicer's order
(walls before infill, island by island, object by object: ``--order-mode safe``); curves are
re-ordered only inside a group. ``--order-mode free`` puts every curve of a layer in one group, as
the paper does.

Each curve becomes a *cluster* of oriented candidates (formulations/ordering.md, "Candidates"):

- an open curve in a re-orderable group: two candidates, forward (enter at its start, leave at its
  end) and reversed;
- a closed loop: one candidate that enters and leaves at its seam, traversed in its own direction
  (reversing a loop changes no travel; keeping its direction keeps the slicer's wall direction);
  with ``move_seams`` one candidate per vertex (up to ``seam_candidates``), each still in the
  loop's own direction;
- a curve of a fixed-order group: one candidate (the group is never re-ordered).

Solvers see one ``Group`` at a time: a start point plus the candidates' entry and exit points.
Units: ``_mm`` millimetres, ``_s`` seconds, ``_j`` joules (see gatesopt.program).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import GatesoptError
from ..solvers import STATUSES, Status, relative_gap

#: closed-loop tolerance: a curve whose end lies within this of its start is a closed loop
CLOSED_TOL_MM = 1e-3


class OrderingOptionsError(GatesoptError, ValueError):
    """Bad ordering options or formulation: one line from the CLI (a ValueError for callers)."""


@dataclass(frozen=True)
class OrderingOptions:
    """How to build an ordering problem from a Program (or polylines)."""

    mode: str = "safe"                  # "safe": keep the slicer's feature groups; "free": one group per layer
    move_seams: bool = False            # closed loops may start at another vertex
    seam_candidates: int = 16           # with move_seams: vertices tried per loop (evenly spread, seam included)
    cost: str = "distance"              # objective unit: "distance" (mm), "time" (s) or "energy" (J)
    travel_feed_mm_s: float | None = None   # travel speed for "time"/"energy"; None: the file's most common
    travel_power_w: float = 21.30       # travel power for "energy" (3DGates Table 2, G0 row)

    def __post_init__(self):
        if self.mode not in ("safe", "free"):
            raise OrderingOptionsError(f"order mode must be 'safe' or 'free', not {self.mode!r}")
        if self.cost not in ("distance", "time", "energy"):
            raise OrderingOptionsError(f"cost must be 'distance', 'time' or 'energy', not {self.cost!r}")
        if self.seam_candidates < 1:
            raise OrderingOptionsError("seam_candidates must be >= 1")


@dataclass(frozen=True, eq=False)
class Group:
    """One solver instance: an open path from ``start_xy`` through every curve once.

    Candidate k belongs to local curve ``cand_curve[k]`` (0..n_curves-1); choosing it means the path
    arrives at ``cand_entry_xy[k]`` and leaves from ``cand_exit_xy[k]``. ``cand_flip[k]`` is the
    candidate that traverses the same curve the other way round (``k`` itself for a loop, whose
    entry and exit coincide). Travel from point p to point q costs |p - q| (mm).
    """

    start_xy: np.ndarray        # (2,)
    cand_curve: np.ndarray      # (m,) int64
    cand_entry_xy: np.ndarray   # (m, 2)
    cand_exit_xy: np.ndarray    # (m, 2)
    cand_flip: np.ndarray       # (m,) int64
    n_curves: int
    layer: int = 0
    label: str = ""
    cand_reversed: np.ndarray | None = None   # (m,) bool: traverses its curve backwards
    cand_seam: np.ndarray | None = None       # (m,) int64: vertex a closed loop starts at (0: its seam)
    end_xy: np.ndarray | None = None          # (2,) where the path must go after its last curve
                                              # (the next group's fixed entry), or None: it just ends

    @property
    def n_cands(self) -> int:
        return len(self.cand_curve)

    def start_cost_mm(self) -> np.ndarray:
        """(m,) travel from the start point to each candidate's entry."""
        return np.hypot(*(self.cand_entry_xy - self.start_xy).T)

    def arc_cost_mm(self) -> np.ndarray:
        """(m, m) travel from candidate u's exit to candidate v's entry; inf within one curve."""
        d = self.cand_exit_xy[:, None, :] - self.cand_entry_xy[None, :, :]
        c = np.hypot(d[..., 0], d[..., 1])
        c[self.cand_curve[:, None] == self.cand_curve[None, :]] = np.inf
        return c

    def end_cost_mm(self) -> np.ndarray:
        """(m,) travel from each candidate's exit to the end point (0 without one)."""
        if self.end_xy is None:
            return np.zeros(self.n_cands)
        return np.hypot(*(self.cand_exit_xy - self.end_xy).T)

    def path_cost_mm(self, order: np.ndarray) -> float:
        """Travel of the open path visiting candidates ``order`` (one per curve) from start_xy
        (and on to end_xy if the group has one)."""
        order = np.asarray(order, dtype=np.int64)
        if len(order) == 0:
            return 0.0 if self.end_xy is None else float(np.hypot(*(self.end_xy - self.start_xy)))
        travel = path_travel_mm(self.start_xy, self.cand_entry_xy[order], self.cand_exit_xy[order])
        last = 0.0 if self.end_xy is None else float(np.hypot(*(self.cand_exit_xy[order[-1]] - self.end_xy)))
        return travel + last

    def check_order(self, order: np.ndarray) -> None:
        """Raise ValueError unless ``order`` visits every curve exactly once."""
        order = np.asarray(order, dtype=np.int64)
        if len(order) != self.n_curves or not np.array_equal(
                np.sort(self.cand_curve[order]), np.arange(self.n_curves)):
            raise ValueError("order does not visit every curve exactly once")

    def exit_xy(self, order: np.ndarray) -> np.ndarray:
        """Where the path leaves its last curve."""
        return self.cand_exit_xy[order[-1]] if len(order) else self.start_xy

    def key(self) -> bytes:
        """Exact identity of this group instance (coordinates to 0.1 µm): identical groups recur
        layer after layer, and a solve's answer is kept under this key."""
        parts = [self.start_xy, self.cand_entry_xy, self.cand_exit_xy,
                 np.zeros(2) - 1e9 if self.end_xy is None else self.end_xy]
        q = np.concatenate([np.ravel(np.rint(np.asarray(a, float) * 1e4)) for a in parts]).astype(np.int64)
        return q.tobytes() + self.cand_curve.tobytes()

    def backwards(self) -> "Group":
        """The mirror image of this group for a path whose end is fixed and whose start is free:
        it starts at ``end_xy`` and ends wherever it likes, each candidate's entry and exit
        swapped. Candidate indices keep their meaning, so its path k1..kn is this group's path
        kn..k1, and its cost is that path's cost without the travel into its first curve. (The
        helper process solves groups this way when only the next group's entry is known.)"""
        if self.end_xy is None:
            raise ValueError("a group without an end point has no backwards problem")
        return Group(np.asarray(self.end_xy, float).copy(), self.cand_curve, self.cand_exit_xy,
                     self.cand_entry_xy, self.cand_flip, self.n_curves, self.layer, self.label,
                     self.cand_reversed, self.cand_seam, None)


#: an objective within this of its bound counts as proven optimal (float noise, integer scaling);
#: also the absolute tolerance of the gap (``solvers.relative_gap``): 0 within it
OPTIMAL_ABS_TOL_MM = 1e-3


@dataclass(frozen=True, eq=False)
class GroupSolution:
    """A formulation's answer for one Group (objective, bound in mm of travel)."""

    order: np.ndarray           # (n_curves,) candidate indices in visiting order
    objective_mm: float
    bound_mm: float             # proven lower bound (0 where the formulation has none)
    status: Status              # optimal | feasible | fallback (gatesopt.solvers)
    solve_s: float
    formulation: str            # what produced it, e.g. "auto:milp", "greedy+kept"
    gap: float = field(default=0.0)     # solvers.relative_gap (abs_tol OPTIMAL_ABS_TOL_MM)

    @staticmethod
    def make(order, objective_mm, bound_mm, status, solve_s, formulation) -> "GroupSolution":
        objective_mm = float(objective_mm)
        bound_mm = float(min(max(bound_mm, 0.0), objective_mm))
        if status not in STATUSES:
            raise ValueError(f"unknown status {status!r}: one of {', '.join(STATUSES)}")
        status = Status(status)
        if status == Status.OPTIMAL:
            bound_mm = objective_mm
        # the bound is finite here (0 at worst: travel is never negative), so the gap is never
        # NaN: 0 within OPTIMAL_ABS_TOL_MM, else (objective - bound) / objective
        gap = relative_gap(objective_mm, bound_mm, abs_tol=OPTIMAL_ABS_TOL_MM)
        return GroupSolution(np.asarray(order, dtype=np.int64), objective_mm, bound_mm, status,
                             float(solve_s), formulation, gap)


def trivial_solution(group: Group, t0: float, formulation: str) -> GroupSolution | None:
    """The answer for a group of 0 or 1 curves (no solver needed; ``t0``: when the solve
    started), else None."""
    if group.n_curves == 0:
        return GroupSolution.make([], 0.0, 0.0, Status.OPTIMAL, time.perf_counter() - t0,
                                  formulation)
    if group.n_curves == 1:
        c = group.start_cost_mm() + group.end_cost_mm()
        k = int(np.argmin(c))
        return GroupSolution.make([k], c[k], c[k], Status.OPTIMAL, time.perf_counter() - t0,
                                  formulation)
    return None


@dataclass(frozen=True, eq=False)
class OrderingProblem:
    """Per layer, a sequence of groups of curves (see module docstring).

    Curves are numbered in the slicer's order; group g holds curves
    ``group_curve_start[g]:group_curve_start[g+1]`` and groups are numbered in print order.
    A curve's vertices are ``points_xy[curve_point_start[c]:curve_point_start[c+1]]``.
    """

    curve_start_xy: np.ndarray      # (n, 2)
    curve_end_xy: np.ndarray        # (n, 2)
    curve_closed: np.ndarray        # (n,) bool: end == start (within CLOSED_TOL_MM)
    curve_layer: np.ndarray         # (n,) int
    points_xy: np.ndarray           # (P, 2) polyline vertices of all curves
    curve_point_start: np.ndarray   # (n + 1,) int64
    group_curve_start: np.ndarray   # (G + 1,) int64
    group_layer: np.ndarray         # (G,) int
    group_fixed: np.ndarray         # (G,) bool: keep the slicer's order and direction
    group_label: tuple = ()         # (G,) str, e.g. "L12 obj0 island1 infill"
    origin_xy: np.ndarray = field(default_factory=lambda: np.zeros(2))
    options: OrderingOptions = OrderingOptions()
    cost_per_mm: float = 1.0        # objective units per mm of travel (1, 1/feed, power/feed)
    cost_unit: str = "mm"
    # Program-built problems: the step rows each curve covers (first, last+1); -1 for polylines
    curve_step_start: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    curve_step_stop: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    notes: tuple = ()               # why some layers were left alone (barriers, unsupported)
    travel_feed_mm_s: float = 0.0   # travel speed used for travel time (0: unknown)
    layout: object = None           # layout.Layout for Program-built problems (used by emit)

    @property
    def n_curves(self) -> int:
        return len(self.curve_start_xy)

    @property
    def n_groups(self) -> int:
        return len(self.group_layer)

    @property
    def n_layers(self) -> int:
        return int(self.group_layer.max()) + 1 if self.n_groups else 0

    @property
    def group_reorderable(self) -> np.ndarray:
        """(G,) bool: groups a solver decides (not fixed, >= 2 curves): what reports count."""
        return ~np.asarray(self.group_fixed, bool) & (np.diff(self.group_curve_start) >= 2)

    def group_curves(self, g: int) -> np.ndarray:
        return np.arange(self.group_curve_start[g], self.group_curve_start[g + 1])

    def group(self, g: int, start_xy, end_xy=None) -> Group:
        """Group g as a solver instance starting at ``start_xy`` (the previous group's end) and,
        if ``end_xy`` is given, travelling on to it after its last curve."""
        curves = self.group_curves(g)
        fixed = bool(self.group_fixed[g])
        cc, ent, ext, flip, rev, seam = [], [], [], [], [], []
        for local, c in enumerate(curves):
            a, b = self.curve_start_xy[c], self.curve_end_xy[c]
            k0 = len(cc)
            if fixed:
                cc.append(local); ent.append(a); ext.append(b); flip.append(k0)
                rev.append(False); seam.append(0)
            elif self.curve_closed[c]:
                for v in self.seam_vertices(c):
                    p = self.points_xy[self.curve_point_start[c] + v]
                    flip.append(len(cc)); cc.append(local); ent.append(p); ext.append(p)
                    rev.append(False); seam.append(int(v))
            else:
                cc += [local, local]; ent += [a, b]; ext += [b, a]; flip += [k0 + 1, k0]
                rev += [False, True]; seam += [0, 0]
        m = len(cc)
        return Group(np.asarray(start_xy, float).copy(), np.asarray(cc, np.int64),
                     np.asarray(ent, float).reshape(m, 2), np.asarray(ext, float).reshape(m, 2),
                     np.asarray(flip, np.int64), len(curves), int(self.group_layer[g]),
                     self.group_label[g] if self.group_label else "",
                     np.asarray(rev, bool), np.asarray(seam, np.int64),
                     None if end_xy is None else np.asarray(end_xy, float).copy())

    def seam_vertices(self, c: int) -> np.ndarray:
        """Vertex offsets a closed loop may start at: 0 (its seam) and, with move_seams, others."""
        if not (self.options.move_seams and self.curve_closed[c]):
            return np.zeros(1, np.int64)
        n_vert = int(self.curve_point_start[c + 1] - self.curve_point_start[c]) - 1  # last == first
        k = min(self.options.seam_candidates, max(n_vert, 1))
        return np.unique(np.linspace(0, n_vert, k, endpoint=False).astype(np.int64))

    def original_travel_mm(self) -> float:
        """Travel of the slicer's own order under the same Euclidean model."""
        return path_travel_mm(self.origin_xy, self.curve_start_xy, self.curve_end_xy)


def path_travel_mm(origin_xy, entry_xy, exit_xy) -> float:
    """Travel from ``origin_xy`` through points entered at ``entry_xy[i]`` and left at
    ``exit_xy[i]``, in that order (arrays (n, 2))."""
    entry_xy = np.asarray(entry_xy, float).reshape(-1, 2)
    if len(entry_xy) == 0:
        return 0.0
    prev = np.vstack([np.asarray(origin_xy, float).reshape(1, 2),
                      np.asarray(exit_xy, float).reshape(-1, 2)[:-1]])
    return float(np.hypot(*(entry_xy - prev).T).sum())


@dataclass(frozen=True, eq=False)
class OrderingSolution:
    """Solved ordering for a whole problem.

    ``curve_order``: curves in print order; ``curve_reversed[c]``: curve c is printed backwards;
    ``curve_seam[c]``: vertex offset a closed loop starts at (0: the slicer's seam).
    ``model_travel_before_mm`` / ``_after_mm``: the solver's *model* travel (straight links
    between curve ends, from the origin on), the objective, not the travel of the file as printed
    (the emitted travels go around walls, retract, start from the start G-code's end): that one
    is measured on the emitted file (``rewrite.figures.travel``, what every report gives).
    """

    curve_order: np.ndarray     # (n,) int64
    curve_reversed: np.ndarray  # (n,) bool
    curve_seam: np.ndarray      # (n,) int64
    groups: tuple               # (G,) GroupSolution
    model_travel_before_mm: float
    model_travel_after_mm: float
    solve_s: float
    formulation: str

    def layer_summary(self, problem: OrderingProblem) -> list[dict]:
        """Per layer: curves, largest group, worst status and gap, solve time."""
        rank = {"optimal": 0, "feasible": 1, "fallback": 2}
        out = {}
        for g, gs in enumerate(self.groups):
            lay = int(problem.group_layer[g])
            n = int(problem.group_curve_start[g + 1] - problem.group_curve_start[g])
            d = out.setdefault(lay, {"layer": lay, "curves": 0, "groups": 0, "largest_group": 0,
                                     "status": "optimal", "gap": 0.0, "solve_s": 0.0,
                                     "travel_mm": 0.0})
            d["curves"] += n
            d["groups"] += 1
            d["largest_group"] = max(d["largest_group"], n)
            if rank.get(gs.status, 2) > rank[d["status"]]:
                d["status"] = gs.status
            d["gap"] = max(d["gap"], gs.gap)
            d["solve_s"] += gs.solve_s
            d["travel_mm"] += gs.objective_mm
        return [out[k] for k in sorted(out)]
