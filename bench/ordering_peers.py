"""Curve ordering: gatesopt's exact solver against peers, per group (issue 4, "Evaluation").

    python bench/ordering_peers.py run [--files F1,F2,...] [--modes safe,free] [--min-curves 8]
        [--max-curves 80] [--per-file 25] [--max-groups 150] [--time-limit 2] [--formulation auto]
        [--elkai-runs 10] [--elkai-timeout 30] [--ortools-s 1] [--out bench/ordering-peers.jsonl]
    python bench/ordering_peers.py report [--out ...] [--write docs/RESULTS.md]

Benchmark only. Peers:

- LKH-3 through ``elkai`` (PyPI; licence non-commercial: a benchmark peer, never a dependency of
  gatesopt). The open path with two orientations per curve becomes an ATSP by the Noon-Bean
  GTSP->ATSP transform: one node per candidate (two oriented nodes per open curve, one per loop),
  the candidates of a curve on a zero-cost cycle, every arc between clusters shifted to the
  cycle predecessor and raised by a constant M larger than any path, plus a depot node for the
  fixed start whose return arcs cost 0 (or the travel on to the group's fixed end). Each group is
  solved in a fresh subprocess (LKH can abort the process) with a timeout.
- OR-Tools routing (``pywrapcp``): a depot start node, one node per candidate, one mandatory
  disjunction per curve over its candidates, an end dummy node reached at zero cost (or the
  travel on to the fixed end), PATH_CHEAPEST_ARC then guided local search with a time limit.

Peers get integer arc costs (micrometres, coarser only if LKH's int range demands it); every tour
is decoded into a candidate order and re-scored with float Euclidean distances
(``Group.path_cost``), the same measure as gatesopt's objective.

Group instances are built as ``gatesopt.ordering.layers.solve`` builds them, except that each
group starts where the *slicer's* order left the previous group (so the instances do not depend on
any solver); ``end_xy`` is set when the next group is fixed. Identical instances are counted once.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from _markdown import publish  # bench/_markdown.py

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
INSTANCES = ROOT.parent / "shared" / "instances"
DEFAULT_OUT = ROOT / "bench" / "ordering-peers.jsonl"
DEFAULT_FILES = ("cura413_cyl_grid20.gcode.gz,real_prusa261_benchy.gcode.gz,"
                 "real_orca230_arcs.gcode.gz,real_ideamaker514.gcode.gz,real_cura591.gcode.gz,"
                 "real_kisslicer206.gcode.gz,slic3r13_star_honey20.gcode.gz")
EQ_TOL_MM = 1e-3      # |a - b| within this counts as equal (gatesopt's OPTIMAL_ABS_TOL)
LKH_INT_MAX = 2 ** 31 - 1
LKH_PRECISION = 100   # LKH's default: internal costs are PRECISION * c


# ---------------------------------------------------------------- instances

def group_instances(problem, min_curves, max_curves):
    """Non-fixed groups with min..max curves, as solver instances (deduplicated)."""
    out, seen = [], set()
    pos = np.asarray(problem.origin_xy, float)
    for g in range(problem.n_groups):
        curves = problem.group_curves(g)
        end = None
        if g + 1 < problem.n_groups and problem.group_fixed[g + 1]:
            end = problem.curve_start_xy[problem.group_curve_start[g + 1]]
        n = len(curves)
        if not problem.group_fixed[g] and min_curves <= n <= max_curves:
            grp = problem.group(g, pos, end)
            k = grp.key()
            if k not in seen:
                seen.add(k)
                out.append((g, grp))
        if n:
            pos = problem.curve_end_xy[curves[-1]]      # the slicer's order
    return out


def group_to_json(grp) -> dict:
    return {"start": grp.start_xy.tolist(), "curve": grp.cand_curve.tolist(),
            "entry": grp.cand_entry_xy.tolist(), "exit": grp.cand_exit_xy.tolist(),
            "end": None if grp.end_xy is None else grp.end_xy.tolist(), "n": grp.n_curves}


# ---------------------------------------------------------------- costs

def _scale(grp, n_arcs_bound):
    """Integer units per mm: 1000 (micrometres) unless LKH's int range needs coarser."""
    pts = np.vstack([grp.start_xy[None], grp.cand_entry_xy, grp.cand_exit_xy]
                    + ([] if grp.end_xy is None else [grp.end_xy[None]]))
    diam = float(np.hypot(*(pts.max(0) - pts.min(0)))) + 1.0
    # arc cost <= M + diam with M ~ (n_arcs_bound + 1) * diam; keep PRECISION * 2 * that in int
    lim = LKH_INT_MAX / LKH_PRECISION / 2.5 / ((n_arcs_bound + 3) * diam)
    return min(1000.0, lim)


def int_costs(grp, scale):
    """Integer (m,m) cand->cand, (m,) start->cand, (m,) cand->end costs (inf on same curve)."""
    arc = grp.arc_cost()
    same = ~np.isfinite(arc)
    arc = np.rint(np.where(same, 0, arc) * scale).astype(np.int64)
    start = np.rint(grp.start_cost() * scale).astype(np.int64)
    end = np.rint(grp.end_cost() * scale).astype(np.int64)
    return arc, same, start, end


# ---------------------------------------------------------------- LKH-3 (elkai), Noon-Bean

def atsp_matrix(grp):
    """Noon-Bean ATSP over 1 + m nodes (node 0 = depot, node 1 + k = candidate k)."""
    m = grp.n_cands
    scale = _scale(grp, grp.n_curves + 1)
    arc, same, start, end = int_costs(grp, scale)
    clusters = [np.flatnonzero(grp.cand_curve == c) for c in range(grp.n_curves)]
    succ = np.arange(m)
    for cl in clusters:                      # cycle k0 -> k1 -> ... -> k0 inside each cluster
        succ[cl] = np.roll(cl, -1)
    big = int(max(arc.max(initial=0), start.max(initial=0), end.max(initial=0)) + 1) * (grp.n_curves + 2)
    forbid = 2 * big
    n = m + 1
    D = np.full((n, n), forbid, np.int64)
    np.fill_diagonal(D, 0)
    # cand x -> cand y in another cluster: leave as succ(x) (the candidate entered), M added
    D[1:, 1:] = big + arc[succ]
    D[1:, 1:][same[succ]] = forbid
    for cl in clusters:
        for a, b in zip(cl, np.roll(cl, -1)):
            if a != b:
                D[1 + a, 1 + b] = 0
    D[0, 1:] = big + start
    D[1:, 0] = big + end[succ]
    return D, succ, scale, big


def elkai_solve_json(payload: dict) -> dict:
    """Worker side (runs in a subprocess)."""
    import elkai
    from gatesopt.ordering.problem import Group
    g = payload["group"]
    cc = np.asarray(g["curve"], np.int64)
    grp = Group(np.asarray(g["start"], float), cc, np.asarray(g["entry"], float).reshape(-1, 2),
                np.asarray(g["exit"], float).reshape(-1, 2), np.arange(len(cc)), int(g["n"]),
                end_xy=None if g["end"] is None else np.asarray(g["end"], float))
    D, succ, scale, big = atsp_matrix(grp)
    t0 = time.perf_counter()
    tour = elkai.DistanceMatrix(D.tolist()).solve_tsp(runs=int(payload["runs"]))
    solve_s = time.perf_counter() - t0
    tour = tour[:-1]
    i = tour.index(0)
    tour = tour[i:] + tour[:i]
    cand = [v - 1 for v in tour[1:]]
    # decode: the first candidate met in each cluster is the one entered (Noon-Bean)
    order, seen, blocks, prev = [], set(), 0, -1
    for k in cand:
        c = int(cc[k])
        if c != prev:
            blocks += 1
            prev = c
        if c not in seen:
            seen.add(c)
            order.append(k)
    return {"order": order, "solve_s": solve_s, "contiguous": blocks == grp.n_curves,
            "scale": scale, "atsp_cost": int(sum(D[a, b] for a, b in zip(tour, tour[1:] + tour[:1])))}


def run_elkai(grp, runs, timeout_s):
    payload = json.dumps({"group": group_to_json(grp), "runs": runs})
    t0 = time.perf_counter()
    try:
        p = subprocess.run([sys.executable, __file__, "_elkai_worker"], input=payload, text=True,
                           capture_output=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return {"error": f"timeout {timeout_s} s", "wall_s": time.perf_counter() - t0}
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        return {"error": f"exit {p.returncode}: {p.stderr.strip()[-300:]}", "wall_s": wall}
    r = json.loads(p.stdout.strip().splitlines()[-1])
    r["wall_s"] = wall
    return r


# ---------------------------------------------------------------- OR-Tools routing

def run_ortools(grp, time_s):
    from ortools.constraint_solver import pywrapcp, routing_enums_pb2
    m = grp.n_cands
    scale = 1000.0
    arc, same, start, end = int_costs(grp, scale)
    forbid = int(arc.max(initial=0) + start.max(initial=0) + 1) * (grp.n_curves + 2)
    arc = np.where(same, forbid, arc)
    n = m + 2                                    # 0 depot, 1..m candidates, m+1 end dummy
    C = np.zeros((n, n), np.int64)
    C[0, 1:m + 1] = start
    C[1:m + 1, 1:m + 1] = arc
    C[1:m + 1, m + 1] = end
    if grp.end_xy is not None:
        C[0, m + 1] = int(round(float(np.hypot(*(grp.end_xy - grp.start_xy))) * scale))
    np.fill_diagonal(C, 0)
    Cl = C.tolist()
    t0 = time.perf_counter()
    man = pywrapcp.RoutingIndexManager(n, 1, [0], [m + 1])
    routing = pywrapcp.RoutingModel(man)

    def cost(i, j):
        return Cl[man.IndexToNode(i)][man.IndexToNode(j)]

    cb = routing.RegisterTransitCallback(cost)
    routing.SetArcCostEvaluatorOfAllVehicles(cb)
    for c in range(grp.n_curves):
        idx = [man.NodeToIndex(1 + int(k)) for k in np.flatnonzero(grp.cand_curve == c)]
        routing.AddDisjunction(idx)              # no penalty: mandatory, exactly one
    prm = pywrapcp.DefaultRoutingSearchParameters()
    prm.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PATH_CHEAPEST_ARC
    prm.local_search_metaheuristic = routing_enums_pb2.LocalSearchMetaheuristic.GUIDED_LOCAL_SEARCH
    prm.time_limit.FromMilliseconds(int(time_s * 1000))
    sol = routing.SolveWithParameters(prm)
    solve_s = time.perf_counter() - t0
    if sol is None:
        return {"error": "no solution", "solve_s": solve_s}
    order, i = [], routing.Start(0)
    while not routing.IsEnd(i):
        node = man.IndexToNode(i)
        if node != 0:
            order.append(node - 1)
        i = sol.Value(routing.NextVar(i))
    return {"order": order, "solve_s": solve_s}


# ---------------------------------------------------------------- run / report

def score(grp, order):
    order = np.asarray(order, np.int64)
    try:
        grp.check_order(order)
    except ValueError as e:
        return None, str(e)
    return grp.path_cost(order), None


def run(args) -> None:
    import gatesopt
    from gatesopt.ordering import OrderingOptions, build
    from gatesopt.ordering.formulations import group_solver
    exact_fn = group_solver(args.formulation)
    files = [f for f in args.files.split(",") if f]
    todo = []
    for name in files:
        prog = gatesopt.parse(INSTANCES / name)
        for mode in args.modes.split(","):
            prob = build(prog, OrderingOptions(mode=mode))
            for g, grp in group_instances(prob, args.min_curves, args.max_curves):
                todo.append((name, mode, g, grp))
    # per file at most --per-file groups, spread over sizes; then at most --max-groups in all
    pick = []
    for name in files:
        rows = sorted((r for r in todo if r[0] == name), key=lambda r: (r[3].n_curves, r[1], r[2]))
        if len(rows) > args.per_file:
            idx = np.unique(np.linspace(0, len(rows) - 1, args.per_file).round().astype(int))
            rows = [rows[i] for i in idx]
        pick += rows
    pick = pick[:args.max_groups]
    if args.only:                            # e.g. "real_cura591.gcode.gz:safe:17,..."
        want = {tuple(x.split(":")) for x in args.only.split(",")}
        pick = [r for r in todo if (r[0], r[1], str(r[2])) in want]
    print(f"{len(pick)} groups from {len(files)} files (of {len(todo)} candidates)", flush=True)
    out = Path(args.out)
    run_id = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    for name, mode, g, grp in pick:
        t0 = time.perf_counter()
        ex = exact_fn(grp, time_limit_s=args.time_limit)
        ex_s = time.perf_counter() - t0
        ex_obj, err = score(grp, ex.order)
        lk = run_elkai(grp, args.elkai_runs, args.elkai_timeout)
        lk_obj, lk_err = (None, lk.get("error")) if "order" not in lk else score(grp, lk["order"])
        ot = run_ortools(grp, args.ortools_s)
        ot_obj, ot_err = (None, ot.get("error")) if "order" not in ot else score(grp, ot["order"])
        row = {"run": run_id, "file": name, "mode": mode, "group": int(g), "label": grp.label,
               "curves": grp.n_curves, "cands": grp.n_cands, "has_end": grp.end_xy is not None,
               "exact": {"travel_mm": ex_obj, "status": ex.status, "bound": ex.bound,
                         "gap": ex.gap, "method": ex.formulation, "solve_s": ex_s, "error": err},
               "lkh": {"travel_mm": lk_obj, "solve_s": lk.get("solve_s"), "wall_s": lk.get("wall_s"),
                       "contiguous": lk.get("contiguous"), "scale": lk.get("scale"), "error": lk_err},
               "ortools": {"travel_mm": ot_obj, "solve_s": ot.get("solve_s"), "error": ot_err},
               "params": {"time_limit_s": args.time_limit, "formulation": args.formulation,
                          "elkai_runs": args.elkai_runs, "ortools_s": args.ortools_s,
                          "min_curves": args.min_curves, "max_curves": args.max_curves,
                          "per_file": args.per_file, "max_groups": args.max_groups}}
        with open(out, "a") as f:
            f.write(json.dumps(row, default=float) + "\n")
        f3 = lambda v: "-" if v is None else f"{v:.3f}"
        print(f"{name} {mode} g{g} n={grp.n_curves}: exact {f3(ex_obj)} ({ex.status}, {ex_s:.2f} s) "
              f"lkh {f3(lk_obj)} ({f3(lk.get('solve_s'))} s{'' if lk_err is None else ' ' + lk_err}) "
              f"ortools {f3(ot_obj)} ({f3(ot.get('solve_s'))} s)", flush=True)


def _cmp(ex, peer):
    if peer is None or ex is None:
        return None
    if ex < peer - EQ_TOL_MM:
        return "better"
    if ex > peer + EQ_TOL_MM:
        return "worse"
    return "equal"


def report(args) -> str:
    rows = [json.loads(l) for l in open(args.out) if l.strip()]
    if not rows:
        return "no rows"
    last = rows[-1]["run"]
    rows = [r for r in rows if r["run"] == last]
    p = rows[0]["params"]
    files = sorted({r["file"] for r in rows})
    modes = sorted({r["mode"] for r in rows})
    n = len(rows)
    st = {s: sum(r["exact"]["status"] == s for r in rows) for s in ("optimal", "feasible", "fallback")}
    # a run on groups above the default size range gets its own section (both are kept)
    large = p.get("min_curves", 8) > 80
    sizes = "".join(f" --{k.replace('_', '-')} {p[k]}" for k, d in (
        ("min_curves", 8), ("max_curves", 80), ("per_file", 25), ("max_groups", 150))
        if p.get(k, d) != d)
    out_arg = "" if Path(args.out) == DEFAULT_OUT else f" --out bench/{Path(args.out).name}"
    lines = ["## Curve ordering: peers" + (" on large groups" if large else "")
             + " (LKH-3 via elkai, OR-Tools routing)", "",
             "Command (from the repository root; `pip install elkai` into the venv first — elkai is "
             "non-commercial, a benchmark peer only, not a dependency; 2 cores shared with other jobs):",
             "", "```",
             f"python bench/ordering_peers.py run --files {','.join(files)} --modes {','.join(modes)} "
             f"--formulation {p['formulation']} --time-limit {p['time_limit_s']:g} "
             f"--elkai-runs {p['elkai_runs']} --ortools-s {p['ortools_s']:g}{sizes}{out_arg}",
             f"python bench/ordering_peers.py report{out_arg} --write docs/RESULTS.md", "```", "",
             f"{n} distinct re-orderable groups of {min(r['curves'] for r in rows)}-"
             f"{max(r['curves'] for r in rows)} curves ({', '.join(modes)} mode) from {len(files)} files, "
             "each group starting where the slicer's order left the previous one (ending at the next "
             "group's entry where that group is fixed). *exact* = gatesopt "
             f"`{p['formulation']}` with {p['time_limit_s']:g} s per group "
             f"(status: {st['optimal']} optimal, {st['feasible']} feasible at the limit, "
             f"{st['fallback']} fallback). *LKH* = elkai {p['elkai_runs']} runs on the Noon-Bean ATSP "
             "(two oriented nodes per open curve, depot with zero-cost return), one subprocess per "
             f"group. *OR-Tools* = routing with one disjunction per curve, guided local search for "
             f"{p['ortools_s']:g} s. Peers optimise integer micrometres; every tour is re-scored with "
             "float Euclidean travel. better/equal/worse = exact vs the peer (equal: within 0.001 mm). "
             "Times: solve only (LKH: inside its subprocess; the process spawn is the extra wall time).", ""]
    ex = np.array([r["exact"]["travel_mm"] for r in rows], float)
    ext = np.array([r["exact"]["solve_s"] for r in rows], float)
    lines += ["| peer | groups solved | exact better | equal | exact worse | travel sum exact mm | "
              "travel sum peer mm | peer/exact (sum) | peer/exact median | min | max | time peer/exact (sum) | "
              "median time exact s | median time peer s | exact worse where exact proven optimal |",
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    worst = {}
    for key, nm in (("lkh", "LKH-3 (elkai)"), ("ortools", "OR-Tools routing")):
        pv = np.array([np.nan if r[key]["travel_mm"] is None else r[key]["travel_mm"] for r in rows])
        pt = np.array([np.nan if r[key]["solve_s"] is None else r[key]["solve_s"] for r in rows])
        ok = np.isfinite(pv)
        c = [_cmp(r["exact"]["travel_mm"], r[key]["travel_mm"]) for r in rows]
        ratio = np.where(ex[ok] > 0, pv[ok] / np.where(ex[ok] > 0, ex[ok], 1), 1.0)
        tr = np.nansum(pt[ok]) / ext[ok].sum() if ext[ok].sum() > 0 else float("nan")
        lines.append(f"| {nm} | {ok.sum()} of {n} | {c.count('better')} | {c.count('equal')} | "
                     f"{c.count('worse')} | {ex[ok].sum():,.1f} | {pv[ok].sum():,.1f} | "
                     f"{pv[ok].sum() / ex[ok].sum():.4f} | {np.median(ratio):.4f} | {ratio.min():.4f} | "
                     f"{ratio.max():.4f} | {tr:.2f} | {np.median(ext[ok]):.3f} | {np.nanmedian(pt[ok]):.3f} | "
                     f"{sum(cc == 'worse' and r['exact']['status'] == 'optimal' for r, cc in zip(rows, c))} |")
        worst[key] = [r for r, cc in zip(rows, c) if cc == "worse"]
    errs = {k: [r for r in rows if r[k]["error"]] for k in ("lkh", "ortools")}
    nonc = sum(r["lkh"]["contiguous"] is False for r in rows)
    lines += ["", f"Peer failures: LKH {len(errs['lkh'])}, OR-Tools {len(errs['ortools'])}; LKH tours "
              f"whose clusters were not contiguous (decoded by first visit): {nonc}.", ""]
    for key, nm in (("lkh", "LKH-3"), ("ortools", "OR-Tools")):
        w = worst[key]
        if w:
            lines.append(f"**Exact worse than {nm} on {len(w)} group(s):** " + "; ".join(
                f"{r['file']} {r['mode']} group {r['group']} ({r['curves']} curves, exact "
                f"{r['exact']['status']} {r['exact']['travel_mm']:.3f} mm vs {r[key]['travel_mm']:.3f} mm)"
                for r in w) + ".")
        else:
            lines.append(f"Exact was never worse than {nm} (within 0.001 mm).")
    lines += ["", "Groups where a peer came closest to or beat exact (largest peer/exact ratio is "
              "the peer losing most; listed: the 10 smallest min(peer)/exact ratios):", "",
              "| file | mode | group | curves | exact status | exact mm | LKH mm | OR-Tools mm | "
              "exact s | LKH s | OR-Tools s |", "|---|---|---:|---:|---|---:|---:|---:|---:|---:|---:|"]

    def minratio(r):
        e = r["exact"]["travel_mm"]
        ps = [r[k]["travel_mm"] for k in ("lkh", "ortools") if r[k]["travel_mm"] is not None]
        return min(ps) / e if ps and e else 1.0
    f3 = lambda v: "-" if v is None else f"{v:.3f}"
    for r in sorted(rows, key=minratio)[:10]:
        lines.append(f"| {r['file']} | {r['mode']} | {r['group']} | {r['curves']} | "
                     f"{r['exact']['status']} | {f3(r['exact']['travel_mm'])} | {f3(r['lkh']['travel_mm'])} | "
                     f"{f3(r['ortools']['travel_mm'])} | {r['exact']['solve_s']:.2f} | "
                     f"{f3(r['lkh']['solve_s'])} | {f3(r['ortools']['solve_s'])} |")
    lines += ["", "Largest peer/exact ratios (where the peers lose most):", "",
              "| file | mode | group | curves | exact mm | LKH/exact | OR-Tools/exact |",
              "|---|---|---:|---:|---:|---:|---:|"]

    def maxratio(r):
        e = r["exact"]["travel_mm"]
        ps = [r[k]["travel_mm"] for k in ("lkh", "ortools") if r[k]["travel_mm"] is not None]
        return max(ps) / e if ps and e else 1.0
    for r in sorted(rows, key=maxratio, reverse=True)[:5]:
        e = r["exact"]["travel_mm"]
        rr = lambda k: "-" if r[k]["travel_mm"] is None or not e else f"{r[k]['travel_mm'] / e:.4f}"
        lines.append(f"| {r['file']} | {r['mode']} | {r['group']} | {r['curves']} | {e:.3f} | "
                     f"{rr('lkh')} | {rr('ortools')} |")
    if getattr(args, "rerun", None):
        rr = [json.loads(l) for l in open(args.rerun) if l.strip()]
        if rr:
            rr = [r for r in rr if r["run"] == rr[-1]["run"]]
            q = rr[0]["params"]
            lines += ["", f"Re-run of the groups exact left unproven, exact at {q['time_limit_s']:g} s per "
                      f"group (`run --only FILE:MODE:GROUP,... --time-limit {q['time_limit_s']:g} "
                      f"--out {Path(args.rerun).name}`; peers as above, re-run too):", "",
                      "| file | mode | group | curves | exact status | exact mm | bound mm | gap | exact s | "
                      "LKH mm | OR-Tools mm |", "|---|---|---:|---:|---|---:|---:|---:|---:|---:|---:|"]
            for r in rr:
                e = r["exact"]
                lines.append(f"| {r['file']} | {r['mode']} | {r['group']} | {r['curves']} | {e['status']} | "
                             f"{f3(e['travel_mm'])} | {e['bound']:.3f} | {100 * e['gap']:.1f} % | "
                             f"{e['solve_s']:.2f} | {f3(r['lkh']['travel_mm'])} | {f3(r['ortools']['travel_mm'])} |")
    lines.append("")
    return "\n".join(lines)


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "_elkai_worker":
        print(json.dumps(elkai_solve_json(json.loads(sys.stdin.read())), default=float))
        return
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--files", default=DEFAULT_FILES)
    r.add_argument("--modes", default="safe,free")
    r.add_argument("--min-curves", type=int, default=8)
    r.add_argument("--max-curves", type=int, default=80)
    r.add_argument("--per-file", type=int, default=25)
    r.add_argument("--max-groups", type=int, default=150)
    r.add_argument("--formulation", default="auto")
    r.add_argument("--time-limit", type=float, default=2.0)
    r.add_argument("--elkai-runs", type=int, default=10)
    r.add_argument("--elkai-timeout", type=float, default=30.0)
    r.add_argument("--ortools-s", type=float, default=1.0)
    r.add_argument("--only", default="", help="FILE:MODE:GROUP,... re-run just these groups")
    r.add_argument("--out", default=str(DEFAULT_OUT))
    p = sub.add_parser("report")
    p.add_argument("--out", default=str(DEFAULT_OUT))
    p.add_argument("--write", metavar="RESULTS.md")
    p.add_argument("--rerun", metavar="JSONL", help="also tabulate a --only re-run (e.g. longer limit)")
    a = ap.parse_args()
    if a.cmd == "run":
        if not INSTANCES.exists():
            sys.exit(f"bench/ordering_peers.py: {INSTANCES} not found")
        run(a)
    else:
        publish(report(a), a.write)


if __name__ == "__main__":
    main()
