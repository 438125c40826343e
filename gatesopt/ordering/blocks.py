"""Safe mode's blocks (issue 36; formulations/ordering.md, "Blocks"): whole islands of a layer
re-ordered as units, each keeping the slicer's order inside (walls before infill, its seams, its
directions).

Safe mode keeps each run of one feature in place, so a layer of many small islands (a pin plate:
per pin two wall loops and a little infill) is a chain of one-curve groups in which nothing can
move, although the slicer chose the islands' order greedily. Here, per *segment* of a layer (the
curves between two hard breaks: a layer change, any barrier line), the curves are assigned to
islands by the layer's geometry -- an island is the outermost wall loop that covers a curve's
middle vertex (shapely: ``STRtree.query(..., predicate="covered_by")``), curves no loop covers
(support, say) pin the segment -- and the islands' order is one more curve-ordering problem: a
``Group`` whose "curves" are the blocks, each with one candidate (entered where its first curve
starts, left where its last curve ends), the links priced as every other link
(``cost.TimePricer``: the slicer's own gap where a block follows the block it followed, else a
rebuilt travel), solved by ``auto``. The first block of each segment stays first: its gap holds
the layer change. The problem is then permuted to the new block order (``OrderingProblem.
curve_source``, ``base``) and solved as usual: inside each block, its re-orderable groups (infill)
are decided by the same chain of groups.

Labelled objects (``slicers.OBJECT_LABELS``: ``; printing object``, M486, EXCLUDE_OBJECT, Cura's
``;MESH:``) are blocks too (``object_runs``): a *run* is the curves between two gaps holding
label lines (``layout.LINE_LABEL``), an object's moves of one layer; consecutive runs of one layer
that each open an object's labels in the gap before them and close them in the gap after, with
no barrier line inside or between them, are re-ordered as islands are (the first stays first),
after the islands inside each run. The emitter writes each run's labels around it
(``emitter._closing``), so a firmware's object cancel still skips exactly that object's moves. A
run that cannot move says why (``OBJECT_KEPT_WHY``, in the problem's notes).
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from ..program import Program
from ..slicers import LABEL_CLOSE, LABEL_OPEN, LABEL_OUTSIDE
from ..solvers import Status
from .layout import LINE_BARRIER, LINE_FATAL, LINE_LABEL
from .problem import Anchor, Group, LinkCosts, OrderingProblem, group_starts

#: what a file's block orders may spend beyond greedy's path, in work (deterministic seconds,
#: ``budget.WorkPlan``'s units: issue 36, the same block orders on every run, whatever the
#: machine's load): the subset DP, the matching step, ILS. Beyond it the greedy path and local
#: search only; islands repeat layer after layer (a cache takes those)
BLOCKS_WORK_S = 1.0
#: ILS kicks per block of a segment the DP does not take (a fixed number: no deadline); 5, not
#: ILS's 15 per curve: a pin plate's 35-block segment then costs ~0.07 s of work (0.06 s CPU
#: measured), so ``BLOCKS_WORK_S`` pays for ~15 of them (``budget.WORK_ILS_S_PER_KICK_CURVE``)
BLOCK_KICKS_PER_BLOCK = 5
#: loops smaller than this (mm^2) outline no island
MIN_ISLAND_AREA_MM2 = 1e-3
#: why a labelled object's run of a layer keeps its place (``object_runs``)
OBJECT_KEPT_WHY = {
    "barrier": "a barrier line inside the object (heater, fan other than the part fan, dwell, "
               "tool or an unknown command)",
    "nest": "its labels do not nest (an object opened before the one before it closed, or not "
            "closed after it)",
    "layers": "its labels span a layer change",
}


@dataclass(frozen=True, eq=False)
class CurveGroups:
    """What ``groups.build`` decided per curve (program order), to group a permuted problem the
    same way: the gap before each curve is a group boundary; each curve's group key (feature,
    fixed) and fixed flag; the label of a group it would start; whether it is a wall loop."""

    boundary: np.ndarray
    key: np.ndarray
    fixed: np.ndarray
    labels: tuple
    wall_like: np.ndarray


def order_blocks(program: Program, problem: OrderingProblem, cg: CurveGroups) -> OrderingProblem:
    """``problem`` with each segment's islands in the order the block problem chose (see module
    docstring), or ``problem`` itself if no segment has three islands or none moved."""
    lay = problem.layout
    n = problem.n_curves
    if n < 3 or lay is None:
        return problem
    perm = np.arange(n)
    report = {"segments": 0, "blocks": 0, "segments_moved": 0, "proven": 0, "solve_s": 0.0,
              "layers_moved": 0, "object_runs": 0, "objects": 0, "object_runs_moved": 0,
              "objects_proven": 0, "objects_kept": {}}
    moved_layers = set()
    cache: dict = {}
    work = [BLOCKS_WORK_S]     # deterministic seconds left (``_solve`` charges each segment)
    for seg in segments(problem):
        blocks = island_blocks(problem, seg, cg.wall_like)
        if len(blocks) < 3:
            continue
        report["segments"] += 1
        report["blocks"] += len(blocks)
        moved, proven = _order_run(problem, blocks, seg, work, cache, perm, moved_layers, report)
        report["proven"] += proven
        report["segments_moved"] += moved
    runs, kept = object_runs(problem)
    report["objects_kept"] = kept
    for objs in runs:
        # each object's curves in the order the islands pass left them (it never crosses a
        # label gap, so an object's positions in ``perm`` hold exactly its curves)
        blocks = [perm[a:b + 1].copy() for a, b in objs]
        seg = np.arange(objs[0][0], objs[-1][1] + 1)
        report["object_runs"] += 1
        report["objects"] += len(blocks)
        moved, proven = _order_run(problem, blocks, seg, work, cache, perm, moved_layers, report)
        report["objects_proven"] += proven
        report["object_runs_moved"] += moved
    report["layers_moved"] = len(moved_layers)
    problem = dataclasses.replace(problem, notes=problem.notes + kept_notes(kept))
    if np.array_equal(perm, np.arange(n)):
        return dataclasses.replace(problem, block_report=report)
    return permuted(problem, perm, cg, report)


def _order_run(problem, blocks, seg, work, cache, perm, moved_layers, report) -> tuple[int, int]:
    """Order one run of blocks (islands or objects) within the work left (``work[0]``,
    deterministic seconds, charged here); a new order is written into ``perm`` and its layer into
    ``moved_layers``. Returns (moved 0/1, proven 0/1); the solve time goes to
    ``report["solve_s"]``, its work to ``report["work_s"]``."""
    order, proven, took, spent = _solve(problem, blocks, seg, work[0], cache,
                                        perm[seg[0]:seg[-1] + 1].copy())
    work[0] -= spent
    report["solve_s"] += took
    report["work_s"] = report.get("work_s", 0.0) + spent
    if np.array_equal(order, np.arange(len(blocks))):
        return 0, int(proven)
    moved_layers.add(int(problem.curve_layer[seg[0]]))
    perm[seg[0]:seg[-1] + 1] = np.concatenate([blocks[i] for i in order])
    return 1, int(proven)


def kept_notes(kept: dict) -> tuple:
    """One note per reason a labelled object kept its place (``object_runs``)."""
    return tuple(f"{count} labelled object run(s) kept in place as barriers: "
                 f"{OBJECT_KEPT_WHY[why]} (first at line {line})"
                 for why, (count, line) in sorted(kept.items()))


def object_runs(problem: OrderingProblem) -> tuple[list[list[tuple[int, int]]], dict]:
    """Labelled objects that may move, and why others may not (module docstring): per layer
    not kept, each sequence of >= 3 consecutive movable object runs as ``(first, last)`` curves;
    and ``{OBJECT_KEPT_WHY key: [runs, first line (1-based)]}`` of the object runs that keep their
    place."""
    lay = problem.layout
    n = problem.n_curves
    kept: dict = {}
    if lay is None or not lay.labels or n < 3:
        return [], kept
    cls = lay.line_class
    l0, l1 = lay.curve_l0, lay.curve_l1
    n_lines = len(cls)
    lab = np.concatenate(([0], np.cumsum(cls == LINE_LABEL)))
    bar = np.concatenate(([0], np.cumsum((cls == LINE_BARRIER) | (cls == LINE_FATAL))))
    gap0 = np.concatenate(([0], l1[:-1] + 1))             # gap before curve c: [gap0[c], l0[c])
    starts = np.ones(n, bool)
    starts[1:] = lab[l0[1:]] - lab[gap0[1:]] > 0
    first = np.flatnonzero(starts)
    last = np.concatenate((first[1:] - 1, [n - 1]))
    layer = problem.curve_layer
    keep = np.asarray(lay.layer_keep, bool)
    label_at = sorted(lay.labels)

    def gap_labels(a: int, b: int) -> list:
        lo = np.searchsorted(label_at, a)
        hi = np.searchsorted(label_at, b)
        return [lay.labels[i] for i in label_at[lo:hi]]

    def why_not(a: int, b: int) -> str:
        """'' if the run of curves a..b is a movable object, else the OBJECT_KEPT_WHY key."""
        if layer[a] != layer[b]:
            return "layers"
        if bar[l1[b] + 1] - bar[l0[a]] > 0:
            return "barrier"
        after = l0[b + 1] if b + 1 < n else n_lines
        entry, exit_ = gap_labels(gap0[a], l0[a]), gap_labels(l1[b] + 1, after)
        opened = set()
        for fam, kind, _ in entry:
            if kind in (LABEL_CLOSE, LABEL_OUTSIDE) and fam not in opened:
                continue                    # the region before it ending
            if kind != LABEL_OPEN or fam in opened:
                return "nest"               # opened twice, or closed after it opened
            opened.add(fam)
        if not opened:
            return "nest"
        ended = set()
        for fam, kind, _ in exit_:
            if fam in opened and kind in (LABEL_CLOSE, LABEL_OPEN, LABEL_OUTSIDE):
                ended.add(fam)
        return "" if ended == opened else "nest"

    runs = []
    cur: list = []

    def flush():
        if len(cur) >= 3:
            runs.append(list(cur))
        cur.clear()

    for a, b in zip(first.tolist(), last.tolist()):
        la = int(layer[a])
        if la < len(keep) and keep[la]:
            flush()
            continue
        if not any(kind == LABEL_OPEN for _, kind, _ in gap_labels(gap0[a], l0[a])):
            flush()                         # moves of no object (skirt, NONMESH): they pin
            continue
        why = why_not(a, b)
        if why:
            row = kept.setdefault(why, [0, int(l0[a]) + 1])
            row[0] += 1
            flush()
            continue
        if cur and (layer[cur[-1][0]] != layer[a] or bar[l0[a]] - bar[gap0[a]] > 0):
            flush()                         # a new layer, or a barrier line before it: it
                                            # starts a new sequence (and stays its first)
        cur.append((a, b))
    flush()
    return runs, kept


def segments(problem: OrderingProblem) -> list[np.ndarray]:
    """Runs of consecutive curves of one layer that is not kept, with no hard break (a barrier
    line, the layer change: ``Layout.gap_boundary``) between them."""
    lay = problem.layout
    n = problem.n_curves
    layer = problem.curve_layer
    keep = np.asarray(lay.layer_keep, bool)
    brk = np.ones(n, bool)
    brk[1:] = lay.gap_boundary[1:] | (layer[1:] != layer[:-1])
    starts = np.concatenate((np.flatnonzero(brk), [n]))
    out = []
    for a, b in zip(starts[:-1].tolist(), starts[1:].tolist()):
        lay_c = int(layer[a])
        if b - a >= 3 and not (lay_c < len(keep) and keep[lay_c]):
            out.append(np.arange(a, b))
    return out


def island_blocks(problem: OrderingProblem, seg: np.ndarray, wall_like: np.ndarray) -> list[np.ndarray]:
    """The blocks of a segment: per island (the outermost wall loop covering a curve's middle
    vertex), its curves in the slicer's order, islands in the order the slicer began them. A
    curve no loop covers pins the segment: blocks are formed between such curves only, and those
    curves stay where they are (then fewer than 3 blocks come back)."""
    import shapely
    pts, pstart = problem.points_xy, problem.curve_point_start
    loops = [c for c in seg.tolist() if wall_like[c] and pstart[c + 1] - pstart[c] >= 4]
    if len(loops) < 2:
        return []
    polys = []
    for c in loops:
        ring = pts[pstart[c]:pstart[c + 1]]
        poly = shapely.make_valid(shapely.Polygon(ring))
        polys.append(poly)
    area = shapely.area(np.asarray(polys, object))
    ok = area >= MIN_ISLAND_AREA_MM2
    polys = [p for p, good in zip(polys, ok) if good]
    area = area[ok]
    if len(polys) < 2:
        return []
    mid = pts[pstart[seg] + (pstart[seg + 1] - pstart[seg] - 1) // 2]
    tree = shapely.STRtree(polys)
    which, poly = tree.query(shapely.points(mid), predicate="covered_by")
    island = np.full(len(seg), -1, np.int64)
    best = np.full(len(seg), -1.0)
    for i, p in zip(which.tolist(), poly.tolist()):
        if area[p] > best[i]:
            best[i], island[i] = area[p], p
    if (island < 0).any():
        return []               # a curve outside every island (support, a skirt): keep the order
    firsts = {}
    for i, isl in enumerate(island.tolist()):
        firsts.setdefault(isl, i)
    order = sorted(firsts, key=firsts.get)
    return [seg[island == isl] for isl in order]


def _solve(problem: OrderingProblem, blocks: list, seg: np.ndarray, work_left_s: float,
           cache: dict, current: np.ndarray | None = None):
    """(block order, proven optimal?, seconds, work) for one segment: the first block stays
    first, the others are one candidate each of a group solved by the greedy formulation
    (``greedy_pass.solve``: the subset DP up to ``budget.DP_CURVES`` blocks, greedy's path and
    bound, the matching step where it applies and ``work_left_s`` pays for it), then, unproven,
    the subset DP where it fits (``dp.fits``) or ILS with ``BLOCK_KICKS_PER_BLOCK`` kicks per
    block, where ``work_left_s`` pays for it; kept as the slicer had them unless the solved order
    costs less, among block orders and, the links inside the blocks counted, than the segment's
    curves as printed now (``current``, default ``seg``: ``_beats_current``). Every step runs to
    its end (no clock is read): the same order on every run. The work (deterministic seconds,
    ``budget``'s constants) is counted from the segment's size."""
    from . import budget, dp, greedy_pass, ils
    t0 = time.perf_counter()
    first = [int(b[0]) for b in blocks]
    last = [int(b[-1]) for b in blocks]
    k = len(blocks) - 1
    entry = problem.curve_start_xy[first[1:]]
    exit_ = problem.curve_end_xy[last[1:]]
    start = Anchor(problem.curve_end_xy[last[0]].copy(), last[0], False)
    after = int(seg[-1]) + 1
    # the next layer's first curve too: where the segment's last block ends prices the layer
    # change (a rebuilt one retracts and lifts where the slicer's went straight on), which the
    # next layer's first block, staying first, cannot change (real_cura231_puzzle: islands
    # swapped to save 21 ms made the layer change 88 ms longer, 12 layers)
    end = (Anchor(problem.curve_start_xy[after].copy(), after, False)
           if after < problem.n_curves else None)
    grp = Group(start.xy.copy(), np.arange(k), entry, exit_, np.arange(k), k,
                int(problem.curve_layer[seg[0]]), "blocks", np.zeros(k, bool),
                np.zeros(k, np.int64), None if end is None else end.xy.copy())
    grp = dataclasses.replace(grp, costs=_block_costs(problem, first[1:], last[1:], start, end))
    key = grp.key()
    got = cache.get(key)
    spent = 0.0
    if got is None:
        small = greedy_pass.dp_first(grp)
        spent = float(budget.greedy_work_s(k, k, problem.pricer is not None, small))
        extra = budget.matching_work_s(k, k)
        gs = greedy_pass.solve(grp, with_matching=spent + extra <= work_left_s)
        if gs.formulation == greedy_pass.MATCHING_FORMULATION:
            spent += extra
        if gs.status != Status.OPTIMAL and k >= 4:
            dp_s = budget.WORK_DP_S_PER_GROUP + budget.WORK_DP_S_PER_STATE * dp.work(grp)
            kicks = BLOCK_KICKS_PER_BLOCK * k
            ils_s = budget.WORK_ILS_S_PER_GROUP + budget.WORK_ILS_S_PER_KICK_CURVE * kicks * k
            if dp.fits(grp) and spent + dp_s <= work_left_s:
                spent += dp_s
                gs = dp.solve(grp)
            elif spent + ils_s <= work_left_s:
                spent += ils_s
                order = ils.improve_ils(grp, gs.order, kicks=kicks, local_optimum=True)
                if grp.path_cost(order) < gs.objective - 1e-9:
                    gs = dataclasses.replace(gs, order=np.asarray(order, np.int64),
                                             objective=grp.path_cost(order))
        ident = np.arange(k)
        if grp.path_cost(gs.order) < grp.path_cost(ident) - 1e-9:
            got = (gs.order, gs.status == Status.OPTIMAL)
        else:
            got = (ident, gs.status == Status.OPTIMAL and
                   grp.path_cost(ident) <= gs.objective + 1e-9)
        cache[key] = got
    order, proven = got
    order = np.concatenate(([0], np.asarray(order) + 1))
    if (not np.array_equal(order, np.arange(k + 1))
            and not _beats_current(problem, blocks, order, seg if current is None else current,
                                   end)):
        order = np.arange(k + 1)
    return order, bool(proven), time.perf_counter() - t0, spent


def _beats_current(problem: OrderingProblem, blocks: list, order, seg: np.ndarray,
                   end: Anchor | None) -> bool:
    """Whether the curves of ``blocks`` in block order ``order`` cost less, from the first curve
    to the curve after the segment (``end``), than the segment as it stands (``seg``: the blocks'
    curves in the order they are printed now). The block problem prices the links between blocks
    only: a block's links inside it are the same in every block order, but not those of the order
    kept, where the slicer interleaved its islands (walls of one island, walls of another, then
    the first one's gap infill) and a block's consecutive curves were not its neighbours:
    real_orca230_arcs layer 168, a block order 25 ms better than the blocks in the slicer's order
    of islands was 94 ms worse than the slicer's interleaved order, and the time guard put the
    layer back."""
    pr = problem.pricer
    cur = np.asarray(seg, np.int64)
    new = np.concatenate([blocks[i] for i in order]).astype(np.int64)
    if np.array_equal(cur, new):
        return False

    def cost(seq):
        if end is not None:
            seq = np.append(seq, end.curve)
        a, b = seq[:-1], seq[1:]
        if pr is None:
            return float(np.hypot(*(problem.curve_start_xy[b] - problem.curve_end_xy[a]).T).sum())
        return float(pr.links_ms(a, False, problem.curve_end_xy[a], b, False,
                                 problem.curve_start_xy[b]).sum())
    return cost(new) < cost(cur) - 1e-9


def _block_costs(problem: OrderingProblem, first, last, start: Anchor, end) -> LinkCosts:
    """Link costs between blocks: from block u's last curve to block v's first, both as the
    slicer printed them (time: ``TimePricer``, the slicer's own gap where v followed u)."""
    first, last = np.asarray(first, np.int64), np.asarray(last, np.int64)
    k = len(first)
    u, v = np.divmod(np.arange(k * k), k)
    entry, exit_ = problem.curve_start_xy[first], problem.curve_end_xy[last]
    pr = problem.pricer
    if pr is None:
        arc = np.hypot(*(exit_[u] - entry[v]).T)
        s = np.hypot(*(entry - start.xy).T)
        e = np.zeros(k) if end is None else np.hypot(*(exit_ - end.xy).T)
    else:
        no = np.zeros(k, bool)
        arc = pr.links_ms(last[u], False, exit_[u], first[v], False, entry[v])
        s = pr.links_ms(start.curve, False, start.xy, first, no, entry)
        e = (np.zeros(k) if end is None else
             pr.links_ms(last, no, exit_, end.curve, False, end.xy))
    arc = np.asarray(arc, float).reshape(k, k)
    np.fill_diagonal(arc, np.inf)
    return LinkCosts(arc, np.asarray(s, float), np.asarray(e, float))


def permuted(problem: OrderingProblem, perm: np.ndarray, cg: CurveGroups,
             report: dict) -> OrderingProblem:
    """``problem`` with its curves in the order ``perm`` (program curves), grouped as
    ``groups.build`` groups them: a group never spans a jump between curves that were not
    neighbours in the program."""
    n = len(perm)
    pstart = problem.curve_point_start
    counts = pstart[perm + 1] - pstart[perm]
    new_pstart = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    idx = np.concatenate([np.arange(pstart[c], pstart[c + 1]) for c in perm.tolist()])
    boundary = cg.boundary[perm].copy()
    boundary[1:] |= perm[1:] != perm[:-1] + 1
    key = cg.key[perm]
    gstart = group_starts(boundary, key)
    heads = perm[gstart[:-1]]
    layer = problem.curve_layer[perm]
    # the problem in the program's order, grouped as the permuted one is: each permuted group is
    # a run of consecutive program curves, so its first curve starts a group there too. The
    # emitter and the pricer read group boundaries from it (a link entering a group from outside
    # consumes the gap before the group's first curve: with the old groups, a group split across
    # two islands had its boundary gap, a layer change, written twice: real_orca230_arcs)
    heads_prog = perm[gstart[:-1]]
    by = np.argsort(heads_prog, kind="stable")
    bstart = np.concatenate((heads_prog[by], [n])).astype(np.int64)
    if not np.array_equal(np.diff(bstart), np.diff(gstart)[by]):
        raise AssertionError("blocks.permuted: a permuted group is not a run of program curves")
    heads = bstart[:-1]
    base = dataclasses.replace(
        problem, group_curve_start=bstart, group_layer=problem.curve_layer[heads],
        group_fixed=cg.fixed[heads], group_label=tuple(cg.labels[c] for c in heads.tolist()),
        pricer=None)
    heads = perm[gstart[:-1]]
    notes = problem.notes + (f"safe mode: islands re-ordered as blocks in "
                             f"{report['segments_moved']} of {report['segments']} segments",)
    if report.get("object_runs"):
        notes += (f"labelled objects re-ordered as blocks in "
                  f"{report['object_runs_moved']} of {report['object_runs']} runs of >= 3 objects",)
    return dataclasses.replace(
        problem, curve_start_xy=problem.curve_start_xy[perm], curve_end_xy=problem.curve_end_xy[perm],
        curve_closed=problem.curve_closed[perm], curve_layer=layer, points_xy=problem.points_xy[idx],
        curve_point_start=new_pstart, group_curve_start=gstart, group_layer=layer[gstart[:-1]],
        group_fixed=cg.fixed[heads], group_label=tuple(cg.labels[c] for c in heads.tolist()),
        curve_step_start=problem.curve_step_start[perm], curve_step_stop=problem.curve_step_stop[perm],
        notes=notes, curve_source=perm.astype(np.int64), base=base, block_report=report,
        pricer=None, curve_one_way=(None if problem.curve_one_way is None
                                    else problem.curve_one_way[perm]))
