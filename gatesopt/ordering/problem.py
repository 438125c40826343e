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
- a one-way curve (``curve_one_way``: a loop clipped short of its seam, a curve that ends in the
  slicer's coasting): one candidate, forward;
- a curve of a fixed-order group: one candidate (the group is never re-ordered).

Solvers see one ``Group`` at a time: a start point plus the candidates' entry and exit points.
Units: ``_mm`` millimetres, ``_s`` seconds, ``_j`` joules (see gatesopt.program).
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import GatesoptError
from ..firmware import planner_families
from ..limits import machine_limits
from ..solvers import STATUSES, Status, relative_gap
from .candidates import candidates, candidates_with_seams

#: closed-loop tolerance: a curve whose end lies within this of its start is a closed loop
CLOSED_TOL_MM = 1e-3
#: the objectives (``OrderingOptions.objective``) and the unit of their costs: time in
#: milliseconds (so that the solvers' absolute tolerances, 1e-3 of a unit, are 1 us of print
#: time where they are 1 um of travel)
OBJECTIVES = ("time", "travel")
COST_UNIT = {"time": "ms", "travel": "mm"}
#: ``OrderingOptions.joined_links``
JOINED_LINKS = ("symmetric", "all", "none")
#: groups above this many candidates get no dense link matrix (m^2 doubles: 2000 -> 32 MB); their
#: solvers work on the XY points (``greedy``'s Euclidean kernels) and the path is priced link by link
DENSE_MAX_CANDS = 2000


class OrderingOptionsError(GatesoptError, ValueError):
    """Bad ordering options or formulation: one line from the CLI (a ValueError for callers)."""


@dataclass(frozen=True)
class OrderingOptions:
    """How to build an ordering problem from a Program (or polylines)."""

    mode: str = "safe"                  # "safe": keep the slicer's feature groups; "free": one group per layer
    move_seams: bool = False            # closed loops may start at another vertex
    seam_candidates: int = 16           # with move_seams: vertices tried per loop (evenly spread, seam included)
    #: what a link between two curves costs (formulations/ordering.md, "Cost model"): "time", the
    #: time the travel takes as emitted (its moves under ``move_times.MoveTimes``, retraction, z-hop and
    #: the slicer's own copied gaps included; in ms), or "travel", its length (mm, Fleming Eq. 1)
    objective: str = "time"
    #: safe mode: re-order whole islands and labelled objects of a layer as blocks (``blocks.py``)
    blocks: bool = True
    #: the time objective's price of a slicer's gap copied as it was (formulations/ordering.md,
    #: "Cost model"): "planner", its steps' time under ``planner.plan`` of the input (the curves
    #: around it are the same, so are its junctions); "moves", each of its moves from and to a
    #: junction speed, as a rebuilt travel is priced (a combed gap of many short moves then costs
    #: ~25 % more than it takes: cura413_xend_zigzag100, 874.7 s vs 680.8 s over the file)
    copied_gaps: str = "planner"
    #: which links are planned joined to the moves of the curves around them (formulations/
    #: ordering.md, "Cost model", "Joined to the curves"; with ``copied_gaps="planner"``):
    #: "symmetric" (the default) where the firmware's junction rule is the same run backwards
    #: (Klipper's square-corner velocity, Marlin's junction deviation), so that a link and its
    #: mirror keep one price where the physics gives them one, and under Marlin's classic jerk
    #: each link its own moves (its travel's limits, the copied gaps at the planner's time);
    #: "all": joined under every rule (classic jerk too: a link and its mirror then differ);
    #: "none": never joined
    joined_links: str = "symmetric"
    #: the rules and limits the print is planned by, as the gating problem and the report plan it
    #: (``GatingOptions.planner_family`` / ``printer``): None, the file's own
    #: (``limits.default_family``); ``printer``: the printer's Klipper config
    #: (``--printer-config``), whose limits replace the file's. The time objective prices links
    #: and the time guard measures layers with them (``limits_of``)
    planner_family: str | None = None
    printer: object = field(default=None, repr=False)

    def planned_by(self, family: str | None, printer=None) -> "OrderingOptions":
        """These options planned by ``family`` / ``printer`` (the gating options': one plan of the
        print in every stage), unless they name their own."""
        if self.planner_family is not None or self.printer is not None:
            return self
        return dataclasses.replace(self, planner_family=family, printer=printer)

    def limits_of(self, program):
        """The planner limits of ``program`` (the input or a re-ordered copy) under these options
        (``limits.machine_limits``)."""
        return machine_limits(program, family=self.planner_family, printer=self.printer)

    def __post_init__(self):
        if self.mode not in ("safe", "free"):
            raise OrderingOptionsError(f"order mode must be 'safe' or 'free', not {self.mode!r}")
        if self.objective not in OBJECTIVES:
            raise OrderingOptionsError(f"objective must be 'time' or 'travel', not {self.objective!r}")
        if self.copied_gaps not in ("planner", "moves"):
            raise OrderingOptionsError(f"copied_gaps must be 'planner' or 'moves', not {self.copied_gaps!r}")
        if self.joined_links not in JOINED_LINKS:
            raise OrderingOptionsError(f"joined_links must be one of {', '.join(JOINED_LINKS)}, "
                                       f"not {self.joined_links!r}")
        if self.seam_candidates < 1:
            raise OrderingOptionsError("seam_candidates must be >= 1")
        if self.planner_family is not None and self.planner_family not in planner_families():
            known = ", ".join(planner_families())
            raise OrderingOptionsError(f"planner_family must be one of {known}, not {self.planner_family!r}")


#: ``Anchor.curve`` of the file's end: the steps after the slicer's last curve, which the emitter
#: copies verbatim, so their first XY move starts wherever the last curve printed leaves the head
#: (``cost.TimePricer.file_end_ms``; ``chain.end_of`` gives it to the file's last group)
FILE_END = -2


@dataclass(frozen=True, eq=False)
class Anchor:
    """Where a group's path comes from (its start) or must go on to (its end).

    ``curve``: the problem curve the head leaves (a start) or enters next (an end), -1 if none;
    ``changed``: that curve is printed otherwise than the slicer printed it (reversed, or a loop
    from another vertex). The time objective needs them: the travel between a curve and the
    slicer's next one, both as the slicer printed them, is the slicer's own gap, copied
    (``cost.TimePricer``); the travel objective uses ``xy`` only."""

    xy: np.ndarray
    curve: int = -1
    changed: bool = False

    @staticmethod
    def of(value) -> "Anchor":
        """An Anchor as is; a point (x, y) as an Anchor without a curve."""
        if isinstance(value, Anchor):
            return value
        return Anchor(np.asarray(value, float)[:2].copy())


def same_anchor(a: Anchor, b: Anchor) -> bool:
    """Whether two anchors are one: the same curve, printed alike, at the same point (a group
    started from either has the same start costs)."""
    return (a.curve == b.curve and bool(a.changed) == bool(b.changed)
            and np.array_equal(np.asarray(a.xy, float)[:2], np.asarray(b.xy, float)[:2]))


@dataclass(frozen=True, eq=False)
class LinkCosts:
    """A group's link costs in the objective's unit (``OrderingProblem.cost_unit``).

    ``arc[u, v]``: from candidate u's exit to candidate v's entry (inf within one curve), or None
    for a group above ``DENSE_MAX_CANDS`` candidates (then ``link(u, v)`` prices chosen links);
    ``start[k]``: from the group's start into k; ``end[k]``: from k on to the group's end (0
    without one). Asymmetric in general (formulations/ordering.md, "Cost model")."""

    arc: np.ndarray | None
    start: np.ndarray
    end: np.ndarray
    link: object = None         # callable (u, v) -> costs, for groups without ``arc``
    direct: float = 0.0         # from the start straight on to the end (a group without curves)
    #: callable () -> the (m, m) matrix, made on first use (``matrix``) where ``arc`` is None: a
    #: group no solver searches (a fixed group, one the budget left no time for) never pays for
    #: it. The time objective's matrix is the largest per-group cost of passing a file's groups
    #: (~0.1-0.3 us a link, m^2 links; docs/BENCHMARKS.md, "Link-cost build")
    make_arc: object = None

    @property
    def has_matrix(self) -> bool:
        """Whether the group has (or makes on first use) a dense link matrix."""
        return self.arc is not None or self.make_arc is not None

    def matrix(self) -> np.ndarray | None:
        """The dense link matrix, made now if it was left for first use (None: the group has
        none, its links are priced one by one)."""
        if self.arc is None and self.make_arc is not None:
            # a frozen dataclass: the matrix is written once, past __setattr__
            object.__setattr__(self, "arc", self.make_arc())
        return self.arc

    def links(self, u, v) -> np.ndarray:
        """Costs of the links u[i] -> v[i] (candidate indices). Where the matrix is still to be
        made, links that are all the slicer's own gaps, copied (a fixed group's path, the
        slicer's order of a group left unsearched), are read without making it: the matrix
        holds exactly those numbers for them (``cost._dense``: ``copy_ms``)."""
        if self.arc is None and self.make_arc is not None:
            copied = getattr(self.link, "copied_only", None)
            out = copied(u, v) if copied is not None else None
            if out is not None:
                return out
            self.matrix()
        if self.arc is not None:
            return self.arc[u, v]
        return np.asarray(self.link(u, v), float)


@dataclass(frozen=True, eq=False)
class Group:
    """One solver instance: an open path from ``start_xy`` through every curve once.

    Candidate k belongs to local curve ``cand_curve[k]`` (0..n_curves-1); choosing it means the path
    arrives at ``cand_entry_xy[k]`` and leaves from ``cand_exit_xy[k]``. ``cand_flip[k]`` is the
    candidate that traverses the same curve the other way round (``k`` itself for a loop, whose
    entry and exit coincide). A link costs what ``costs`` says (the time objective: the travel's
    time as emitted, ms); without ``costs``, the travel's length |p - q| (mm, Fleming Eq. 1).
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
    costs: LinkCosts | None = None            # None: Euclidean travel (made on first use)

    @property
    def n_cands(self) -> int:
        return len(self.cand_curve)

    @property
    def dense(self) -> bool:
        """Whether the group has a link matrix (``arc_cost``): up to DENSE_MAX_CANDS candidates."""
        return self._costs().has_matrix

    def _costs(self) -> LinkCosts:
        if self.costs is None:
            # Euclidean, made once: a frozen dataclass, so written past __setattr__
            object.__setattr__(self, "costs", euclidean_costs(self))
        return self.costs

    def start_cost(self) -> np.ndarray:
        """(m,) cost from the start point into each candidate."""
        return self._costs().start

    def arc_cost(self) -> np.ndarray:
        """(m, m) cost from candidate u's exit to candidate v's entry; inf within one curve."""
        arc = self._costs().matrix()
        if arc is None:
            raise ValueError(f"group of {self.n_cands} candidates has no dense link matrix")
        return arc

    def end_cost(self) -> np.ndarray:
        """(m,) cost from each candidate's exit to the end point (0 without one)."""
        return self._costs().end

    def link_cost(self, u, v) -> np.ndarray:
        """Costs of the links u[i] -> v[i] (candidate indices)."""
        return self._costs().links(np.asarray(u, np.int64), np.asarray(v, np.int64))

    def path_cost(self, order: np.ndarray) -> float:
        """Cost of the open path visiting candidates ``order`` (one per curve) from the start
        (and on to the end if the group has one)."""
        order = np.asarray(order, dtype=np.int64)
        c = self._costs()
        if len(order) == 0:
            return float(c.direct) if self.end_xy is not None else 0.0
        inner = float(self.link_cost(order[:-1], order[1:]).sum()) if len(order) > 1 else 0.0
        return float(c.start[order[0]]) + inner + float(c.end[order[-1]])

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
        """Exact identity of this group instance (coordinates to 0.1 µm, costs to 1e-4 of their
        unit): identical groups recur layer after layer, and a solve's answer is kept under
        this key."""
        parts = [self.start_xy, self.cand_entry_xy, self.cand_exit_xy,
                 np.zeros(2) - 1e9 if self.end_xy is None else self.end_xy]
        c = self.costs
        if c is not None and not getattr(c, "euclidean", False):
            parts += [c.start, c.end] + ([c.matrix()] if c.has_matrix else [])
        q = np.concatenate([np.ravel(np.rint(np.nan_to_num(np.asarray(a, float), posinf=-1.0) * 1e4))
                            for a in parts]).astype(np.int64)
        return q.tobytes() + self.cand_curve.tobytes()

    def backwards(self) -> "Group":
        """The mirror image of this group for a path whose end is fixed and whose start is free:
        it starts at ``end_xy`` and ends wherever it likes, each candidate's entry and exit
        swapped. Candidate indices keep their meaning, so its path k1..kn is this group's path
        kn..k1, and its cost is that path's cost without the travel into its first curve: the
        link u -> v of the mirror is the link v -> u here, its start costs are the end costs here
        and it has no end. (The helper process solves groups this way when only the next group's
        entry is known.)"""
        if self.end_xy is None:
            raise ValueError("a group without an end point has no backwards problem")
        c = self._costs()
        link = None if c.link is None else _Mirrored(c.link)
        mirror = LinkCosts(None if not c.has_matrix else np.ascontiguousarray(c.matrix().T), c.end.copy(),
                           np.zeros(self.n_cands), link)
        return Group(np.asarray(self.end_xy, float).copy(), self.cand_curve, self.cand_exit_xy,
                     self.cand_entry_xy, self.cand_flip, self.n_curves, self.layer, self.label,
                     self.cand_reversed, self.cand_seam, None, mirror)


class _Mirrored:
    """The links of a ``Group.backwards()`` mirror: u -> v there is v -> u in the group."""

    def __init__(self, link):
        self.link = link

    def __call__(self, u, v):
        return self.link(v, u)


@dataclass(frozen=True, eq=False)
class EuclideanCosts(LinkCosts):
    """Travel length (mm): Fleming Eq. 1."""

    euclidean: bool = True


def euclidean_costs(group: Group) -> EuclideanCosts:
    """The link costs of the travel objective: |q_u - p_v| (mm)."""
    start = np.hypot(*(group.cand_entry_xy - group.start_xy).T)
    direct = 0.0
    if group.end_xy is None:
        end = np.zeros(group.n_cands)
    else:
        end = np.hypot(*(group.cand_exit_xy - group.end_xy).T)
        direct = float(np.hypot(*(group.end_xy - group.start_xy)))
    ent, ext = group.cand_entry_xy, group.cand_exit_xy
    cc = group.cand_curve
    arc = None
    if group.n_cands <= DENSE_MAX_CANDS:
        d = ext[:, None, :] - ent[None, :, :]
        arc = np.hypot(d[..., 0], d[..., 1])
        arc[cc[:, None] == cc[None, :]] = np.inf
    return EuclideanCosts(arc, start, end, _EuclideanLink(ext, ent), direct)


class _EuclideanLink:
    """|q_u - p_v| for chosen links (groups without a dense matrix)."""

    def __init__(self, exit_xy, entry_xy):
        self.exit_xy, self.entry_xy = exit_xy, entry_xy

    def __call__(self, u, v):
        return np.hypot(*(self.exit_xy[u] - self.entry_xy[v]).T)


#: an objective within this of its bound counts as proven optimal (float noise, integer scaling);
#: also the absolute tolerance of the gap (``solvers.relative_gap``): 0 within it
OPTIMAL_ABS_TOL = 1e-3


@dataclass(frozen=True, eq=False)
class GroupSolution:
    """A formulation's answer for one Group (objective and bound in the problem's cost unit:
    mm of travel, or ms of print time)."""

    order: np.ndarray           # (n_curves,) candidate indices in visiting order
    objective: float
    bound: float             # proven lower bound (0 where the formulation has none)
    status: Status              # optimal | feasible | fallback (gatesopt.solvers)
    solve_s: float
    formulation: str            # what produced it, e.g. "auto:milp", "greedy+kept"
    gap: float = field(default=0.0)     # solvers.relative_gap (abs_tol OPTIMAL_ABS_TOL)

    @staticmethod
    def make(order, objective, bound, status, solve_s, formulation) -> "GroupSolution":
        objective = float(objective)
        bound = float(min(max(bound, 0.0), objective))
        if status not in STATUSES:
            raise ValueError(f"unknown status {status!r}: one of {', '.join(STATUSES)}")
        status = Status(status)
        if status == Status.OPTIMAL:
            bound = objective
        # the bound is finite here (0 at worst: travel is never negative), so the gap is never
        # NaN: 0 within OPTIMAL_ABS_TOL, else (objective - bound) / objective
        gap = relative_gap(objective, bound, abs_tol=OPTIMAL_ABS_TOL)
        return GroupSolution(np.asarray(order, dtype=np.int64), objective, bound, status,
                             float(solve_s), formulation, gap)


def trivial_solution(group: Group, t0: float, formulation: str) -> GroupSolution | None:
    """The answer for a group of 0 or 1 curves (no solver needed; ``t0``: when the solve
    started), else None."""
    if group.n_curves == 0:
        c = group.path_cost([])
        return GroupSolution.make([], c, c, Status.OPTIMAL, time.perf_counter() - t0, formulation)
    if group.n_curves == 1:
        c = group.start_cost() + group.end_cost()
        k = int(np.argmin(c))
        return GroupSolution.make([k], c[k], c[k], Status.OPTIMAL, time.perf_counter() - t0,
                                  formulation)
    return None


def kept_solution(group: Group, t0: float, formulation: str) -> GroupSolution:
    """The slicer's own order of ``group`` (each curve as printed), unsearched: what a group gets
    when the budget has no time left for it (``runner.GroupRunner``). Status "fallback" and bound
    0 (nothing proven: its gap is 100 %), except for 0 or 1 curves (``trivial_solution``: exact
    at no cost). ``t0``: when its solve started."""
    triv = trivial_solution(group, t0, formulation)
    if triv is not None:
        return triv
    order = np.flatnonzero(~np.asarray(group.cand_reversed, bool) & (np.asarray(group.cand_seam) == 0))
    if len(order) != group.n_curves:        # (every curve has its as-printed candidate)
        raise AssertionError(f"group of {group.n_curves} curves has {len(order)} as-printed candidates")
    return GroupSolution.make(order, group.path_cost(order), 0.0, Status.FALLBACK,
                              time.perf_counter() - t0, formulation)


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
    cost_unit: str = "mm"           # of the groups' costs: "mm" (travel) or "ms" (time)
    # Program-built problems: the step rows each curve covers (first, last+1); -1 for polylines
    curve_step_start: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    curve_step_stop: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    notes: tuple = ()               # why some layers were left alone (barriers, unsupported)
    layout: object = None           # layout.Layout for Program-built problems (used by emit)
    #: the time objective's link costs (``cost.TimePricer``); None: Euclidean travel (mm)
    pricer: object = None
    #: a problem whose curves are the program's in another order (safe mode's blocks,
    #: ``blocks.py``): ``curve_source[i]`` is problem curve i's curve in ``base``, the problem in
    #: the program's order. Solutions (``layers.solve``) are in ``base``'s numbering; emit and
    #: the time guard work on ``base``. None: this problem is in the program's order
    curve_source: np.ndarray | None = None
    base: "OrderingProblem | None" = None
    #: safe mode's block pass (``blocks.order_blocks``): segments with three islands or more,
    #: their blocks, segments whose islands moved, block orders proven optimal, seconds
    block_report: dict = field(default_factory=dict)
    #: (n,) bool: open curves printed in their own direction only (``candidates``): a loop the
    #: slicer clipped short of its start, a curve with the slicer's coasting at its end; None: none
    curve_one_way: np.ndarray | None = None

    @property
    def program_problem(self) -> "OrderingProblem":
        """The problem in the program's curve order (itself unless the curves were permuted)."""
        return self if self.base is None else self.base

    def source_curves(self, curves) -> np.ndarray:
        """The program-order curves of problem curves ``curves`` (-1 stays -1)."""
        curves = np.asarray(curves, np.int64)
        if self.curve_source is None:
            return curves
        return np.where(curves >= 0, self.curve_source[np.maximum(curves, 0)], -1)

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

    def group(self, g: int, start, end=None) -> Group:
        """Group g as a solver instance starting at ``start`` (an ``Anchor`` or a point: where
        the previous group ended) and, if ``end`` is given, travelling on to it after its last
        curve. With a time pricer the group carries its link costs (``LinkCosts``)."""
        start, end = Anchor.of(start), (None if end is None else Anchor.of(end))
        start_xy, end_xy = start.xy, (None if end is None else end.xy)
        curves = self.group_curves(g)
        fixed = bool(self.group_fixed[g])
        make = candidates if fixed or not self.options.move_seams else candidates_with_seams
        cc, ent, ext, flip, rev, seam = make(self, curves, fixed)
        grp = Group(np.asarray(start_xy, float).copy(), cc, ent, ext, flip, len(curves),
                    int(self.group_layer[g]), self.group_label[g] if self.group_label else "",
                    rev, seam, None if end_xy is None else np.asarray(end_xy, float).copy())
        if self.pricer is None:
            return grp
        return dataclasses.replace(grp, costs=self.pricer.group_costs(
            self.source_curves(curves), grp, self._source_anchor(start), self._source_anchor(end)))

    def _source_anchor(self, a: "Anchor | None") -> "Anchor | None":
        """An anchor with its curve in the program's numbering (the pricer's)."""
        if a is None or self.curve_source is None or a.curve < 0:
            return a
        return Anchor(a.xy, int(self.curve_source[a.curve]), a.changed)

    def cand_anchor(self, g: int, grp: Group, k: int) -> Anchor:
        """Candidate k of group g (built by ``group``) as an Anchor at its entry (the end of a
        path into it) -- use ``exit_anchor`` for where a path leaves it."""
        return Anchor(grp.cand_entry_xy[k].copy(), int(self.group_curve_start[g] + grp.cand_curve[k]),
                      bool(grp.cand_reversed[k] or grp.cand_seam[k] != 0))

    def exit_anchor(self, g: int, grp: Group, order) -> Anchor:
        """Where the path ``order`` of group g leaves its last curve (the start of the next group);
        an empty path leaves from its start."""
        if len(order) == 0:
            return Anchor.of(grp.start_xy)
        k = int(order[-1])
        return Anchor(grp.cand_exit_xy[k].copy(), int(self.group_curve_start[g] + grp.cand_curve[k]),
                      bool(grp.cand_reversed[k] or grp.cand_seam[k] != 0))

    def link_cost(self, a: Anchor, b: Anchor) -> float:
        """Cost of the travel from ``a`` (the head leaving a.curve at a.xy) into ``b`` (entering
        b.curve at b.xy) in the objective's unit."""
        if self.pricer is None:
            return float(np.hypot(*(np.asarray(b.xy) - np.asarray(a.xy))))
        return float(self.pricer.anchor_link(self._source_anchor(a), self._source_anchor(b)))

    def order_cost(self, order, reversed_, seam) -> float:
        """Cost of a whole solution (every curve from the end of the one before, the first from
        ``origin_xy``), in the objective's unit: the model's print time of the travels, or their
        length. ``solve`` reports it for the slicer's order and the solution."""
        order = np.asarray(order, np.int64)
        a, b = self.entry_exit_xy(order, reversed_, seam)
        if self.pricer is None:
            return path_travel_mm(self.origin_xy, a, b)
        changed = (np.asarray(reversed_, bool) | (np.asarray(seam) != 0))[order]
        return float(self.pricer.order_cost(self.source_curves(order), changed, a, b))

    def entry_exit_xy(self, order, reversed_, seam):
        """(entry, exit) points of the curves ``order`` printed as ``reversed_`` / ``seam`` say."""
        order = np.asarray(order, np.int64)
        a, b = self.curve_start_xy[order].copy(), self.curve_end_xy[order].copy()
        seam = np.asarray(seam, np.int64)
        moved = np.flatnonzero(seam[order] != 0)        # a loop entered and left at another vertex
        if len(moved):
            c = order[moved]
            a[moved] = b[moved] = self.points_xy[self.curve_point_start[c] + seam[c]]
        rev = np.asarray(reversed_, bool)[order]
        a[rev], b[rev] = b[rev], a[rev].copy()
        return a, b

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


def group_starts(boundary: np.ndarray, key: np.ndarray) -> np.ndarray:
    """(G + 1,) first curve of each group and the curve count: a group is a run of curves with
    one ``key`` and no ``boundary`` (the gap before a curve) inside it."""
    n = len(key)
    new = np.asarray(boundary, bool).copy()
    if n:
        new[0] = True
        new[1:] |= key[1:] != key[:-1]
    return np.concatenate((np.flatnonzero(new), [n])).astype(np.int64)


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
    ``travel_before_mm`` / ``_after_mm``: the solver's *model* travel (straight links
    between curve ends, from the origin on), the objective, not the travel of the file as printed
    (the emitted travels go around walls, retract, start from the start G-code's end): that one
    is measured on the emitted file (``rewrite.figures.travel``, what every report gives).
    """

    curve_order: np.ndarray     # (n,) int64
    curve_reversed: np.ndarray  # (n,) bool
    curve_seam: np.ndarray      # (n,) int64
    groups: tuple               # (G,) GroupSolution
    travel_before_mm: float     # model travel (Euclidean, mm) of the slicer's order / this one
    travel_after_mm: float
    solve_s: float
    formulation: str
    #: the objective (``OrderingProblem.order_cost``) of the slicer's order and of this one, in
    #: ``cost_unit`` ("ms": the travels' print time as emitted; "mm": their length)
    cost_before: float = float("nan")
    cost_after: float = float("nan")
    cost_unit: str = "mm"
    #: the greedy chain's wall-clock safety net fired (``runner.WorkRunner``): the groups after it
    #: kept the slicer's order for want of wall-clock time, so the run is not reproducible
    work_net_fired: bool = False

    def layer_summary(self, problem: OrderingProblem) -> list[dict]:
        """Per layer: curves, largest group, worst status and gap, solve time."""
        rank = {"optimal": 0, "feasible": 1, "fallback": 2}
        out = {}
        for g, gs in enumerate(self.groups):
            lay = int(problem.group_layer[g])
            n = int(problem.group_curve_start[g + 1] - problem.group_curve_start[g])
            d = out.setdefault(lay, {"layer": lay, "curves": 0, "groups": 0, "largest_group": 0,
                                     "status": "optimal", "gap": 0.0, "solve_s": 0.0,
                                     "cost": 0.0, "cost_unit": self.cost_unit})
            d["curves"] += n
            d["groups"] += 1
            d["largest_group"] = max(d["largest_group"], n)
            if rank.get(gs.status, 2) > rank[d["status"]]:
                d["status"] = gs.status
            d["gap"] = max(d["gap"], gs.gap)
            d["solve_s"] += gs.solve_s
            d["cost"] += gs.objective
        return [out[k] for k in sorted(out)]
