"""Curve ordering: why groups end unproven, at a fixed per-group limit (issue 36, ">= 90 % of
groups proven optimal under the default 10 s budget, on the time objective").

    python bench/ordering_proof_rate.py measure FILE:MODE [FILE:MODE ...] [--limit 0.5]
        [--min-curves 13] [--max-groups 400] [--out bench/ordering-proof-rate.jsonl] [--tag main]
    python bench/ordering_proof_rate.py report [--out ...] [--tags main new]

Per file, the groups a solve would hand to ``auto`` (not fixed, more than ``--min-curves``
curves, each geometry once: the runner caches exact repeats), each started where the previous
group's greedy path ended (the start anchor as ``layers.solve`` builds it, greedy standing for
the exact answer) and solved by ``auto.solve`` with the same fixed ``--limit`` (independent of
the load and of the budget's plan; ``--limit exact``: each group its ``budget.exact_time_s``, the
least the plan gives a group it wants proven). Per group: status, formulation, CPU seconds,
and, where it ended unproven, the cause, from the symmetric model's steps as they ran (recorded
by wrapping ``SymmetricModel.root`` / ``branch``, which ``DirectedModel`` inherits):

- ``directed``: several candidates per curve (no symmetric model; the directed MILP's loop);
- ``root open``: the root LP did not finish (cuts or pricing) within the limit;
- ``wide root``: the root finished but reduced-cost fixing left too many columns to branch on
  (``MAX_BRANCH_COLUMNS_PER_NODE``);
- ``b&c limit``: branch-and-cut ran out of time;
- ``asym``: the symmetric model's bound meets the path's price in the model (each travel edge
  priced the cheaper way round) but not its true price: the relaxation of direction-dependent
  link costs, not the search, is what is missing (never where the last model that ran was
  ``DirectedModel``, which prices each direction: there its causes are the root's and the
  branch's; rows written before ``model`` was recorded may count such groups here);
- ``no exact``: the limit was below ``budget.exact_time_s`` (ILS only).
"""
from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
INSTANCES = ROOT.parent / "shared" / "instances"
if not INSTANCES.exists():
    INSTANCES = Path("/work/shared/instances")
DEFAULT_OUT = ROOT / "bench" / "ordering-proof-rate.jsonl"


def cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def file_groups(file: str, mode: str, min_curves: int):
    """(g, Group) of the groups ``auto`` gets, each started where the greedy path of the group
    before it ended; repeated geometry (``Group.key``) once."""
    import gatesopt
    from gatesopt.ordering import OrderingOptions, build, greedy
    from gatesopt.ordering.problem import Anchor
    prob = build(gatesopt.parse(str(INSTANCES / file)), OrderingOptions(mode=mode))
    pos = Anchor.of(prob.origin_xy)
    seen = set()
    out = []
    for g in range(prob.n_groups):
        nxt = g + 1
        end = None
        if nxt < prob.n_groups and prob.group_fixed[nxt]:
            end = prob.curve_start_xy[prob.group_curve_start[nxt]]
        grp = prob.group(g, pos, end)
        if grp.n_curves == 0:
            continue
        if prob.group_fixed[g]:
            order = np.arange(grp.n_cands)
        else:
            order = greedy.solve(grp).order
            if grp.n_curves >= min_curves:
                k = grp.key()
                if k not in seen:
                    seen.add(k)
                    out.append((g, grp))
        pos = prob.exit_anchor(g, grp, order)
    return out


class Recorder:
    """Wraps ``SymmetricModel.root`` / ``branch`` to record what the last solve did."""

    def __init__(self):
        from gatesopt.ordering import symmetric
        self.sym = symmetric
        self.reset()
        orig_root, orig_branch = symmetric.SymmetricModel.root, symmetric.SymmetricModel.branch
        rec = self

        def root(model, deadline, *a, **k):
            t = time.perf_counter()
            b = orig_root(model, deadline, *a, **k)
            rec.log.update(root_s=time.perf_counter() - t, root_complete=model.complete,
                           root_bound=b, n_nodes=model.N, model=type(model).__name__)
            return b

        def branch(model, best, best_obj, bound, deadline, *a, **k):
            t = time.perf_counter()
            rc = model.rc
            open_gap = best_obj - bound + 1e-6
            miss = np.triu(~model.present & np.isfinite(rc) & (rc <= open_gap), 1).sum()
            rec.log.update(branch_cols=int(len(model.eu) + miss),
                           branch_cap=int(symmetric.MAX_BRANCH_COLUMNS_PER_NODE * model.N),
                           branch_gap=float(best_obj - bound))
            out = orig_branch(model, best, best_obj, bound, deadline, *a, **k)
            rec.log.update(branch_s=time.perf_counter() - t, branch_proven=bool(out[3]),
                           branch_bound=float(out[2]))
            return out

        symmetric.SymmetricModel.root = root
        symmetric.SymmetricModel.branch = branch

    def reset(self):
        self.log = {}


def sym_price(grp, order) -> float:
    """The path's price in the symmetric model (each travel edge the cheaper way round)."""
    from gatesopt.ordering import symmetric_graph
    from gatesopt.ordering.symmetric import SymmetricModel
    _, _, _, C, curve_nodes, first_cand = symmetric_graph.travel_graph(grp)
    # the tour's travel edges as SymmetricModel.tour_edges makes them (no LP needed)
    model = SymmetricModel.__new__(SymmetricModel)
    model.group, model.curve_nodes, model.first_cand = grp, curve_nodes, first_cand
    e = model.tour_edges(np.asarray(order))
    fixed = 0.0
    return float(C[e[:, 0], e[:, 1]].sum() + fixed)


def cause(row) -> str:
    if row["status"] == "optimal":
        return "proven"
    if not row["sym"]:
        return "directed"
    if row["limit"] < row["exact_s"]:
        return "no exact"
    if (row.get("model") != "DirectedModel" and row.get("sym_price") is not None
            and row["sym_price"] - row["bound"] <= 1e-3):
        return "asym"
    if "root_complete" not in row:
        return "no model"
    if not row["root_complete"]:
        return "root open"
    if "branch_cols" in row and row["branch_cols"] > row["branch_cap"]:
        return "wide root"
    if "branch_s" in row:
        return "b&c limit"
    return "other"


def measure(args) -> None:
    from gatesopt.ordering import auto, symmetric_graph
    from gatesopt.ordering.budget import exact_time_s
    import importlib
    for item in args.set:
        name, value = item.split("=")
        mod, attr = name.rsplit(".", 1)
        setattr(importlib.import_module("gatesopt.ordering." + mod), attr, type(
            getattr(importlib.import_module("gatesopt.ordering." + mod), attr))(float(value)))
    auto.warm_up()
    rec = Recorder()
    with open(args.out, "a") as out:
        for spec in args.files:
            file, mode = spec.split(":")
            t = time.perf_counter()
            groups = file_groups(file, mode, args.min_curves)
            print(f"{file} {mode}: {len(groups)} groups ({time.perf_counter() - t:.1f} s to build)",
                  flush=True)
            if args.max_groups and len(groups) > args.max_groups:
                rng = np.random.default_rng(args.seed)
                keep = sorted(rng.choice(len(groups), args.max_groups, replace=False))
                groups = [groups[i] for i in keep]
            for g, grp in groups:
                rec.reset()
                c0, t0 = cpu_s(), time.perf_counter()
                limit = (float(exact_time_s(grp.n_curves)) if args.limit == "exact"
                         else float(args.limit))
                gs = auto.solve(grp, time_limit_s=limit)
                row = {"tag": args.tag, "limit_arg": args.limit, "file": file, "mode": mode,
                       "group": int(g), "n": int(grp.n_curves), "m": int(grp.n_cands), "limit": limit,
                       "status": str(gs.status.value if hasattr(gs.status, "value") else gs.status),
                       "formulation": gs.formulation, "objective": float(gs.objective),
                       "bound": float(gs.bound), "wall_s": time.perf_counter() - t0,
                       "cpu_s": cpu_s() - c0, "sym": bool(symmetric_graph.applies(grp)),
                       "exact_s": float(exact_time_s(grp.n_curves))}
                row.update(rec.log)
                if row["status"] != "optimal" and row["sym"]:
                    row["sym_price"] = sym_price(grp, gs.order)
                row["cause"] = cause(row)
                out.write(json.dumps(row) + "\n")
                out.flush()
            print(summary([json.loads(x) for x in open(args.out)
                           if json.loads(x)["file"] == file and json.loads(x)["tag"] == args.tag
                           and json.loads(x)["mode"] == mode]),
                  flush=True)


def summary(rows) -> str:
    c = Counter(r["cause"] for r in rows)
    cpu = sum(r["cpu_s"] for r in rows)
    return (f"  {len(rows)} groups, proven {c['proven']}, cpu {cpu:.1f} s; "
            + ", ".join(f"{k} {v}" for k, v in c.most_common() if k != "proven"))


def report(args) -> None:
    rows = [json.loads(x) for x in open(args.out)]
    by = defaultdict(list)
    for r in rows:
        if args.tags and r["tag"] not in args.tags:
            continue
        by[(r["file"], r["mode"], str(r.get("limit_arg", r["limit"])), r["tag"])].append(r)
    causes = ["proven", "no exact", "directed", "root open", "wide root", "b&c limit", "asym",
              "no model", "other"]
    print("| file | mode | limit s | tag | groups | " + " | ".join(causes) + " | CPU s |")
    print("|---|---|---:|---|---:|" + "---:|" * len(causes) + "---:|")
    tot = defaultdict(Counter)
    for (f, m, lim, tag), rs in sorted(by.items()):
        c = Counter(r["cause"] for r in rs)
        cpu = sum(r["cpu_s"] for r in rs)
        tot[tag].update(c)
        tot[tag]["cpu"] += cpu
        tot[tag]["groups"] += len(rs)
        print(f"| {f} | {m} | {lim} | {tag} | {len(rs)} | "
              + " | ".join(str(c[k]) for k in causes) + f" | {cpu:.1f} |")
    for tag, c in tot.items():
        print(f"| all | | | {tag} | {c['groups']} | " + " | ".join(str(c[k]) for k in causes)
              + f" | {c['cpu']:.1f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    m = sub.add_parser("measure")
    m.add_argument("files", nargs="+")
    m.add_argument("--limit", default="0.5",
                   help="seconds per group, or 'exact': budget.exact_time_s of its size, the "
                        "least limit the budget's plan gives a group it wants proven")
    m.add_argument("--min-curves", type=int, default=13)
    m.add_argument("--max-groups", type=int, default=400)
    m.add_argument("--seed", type=int, default=0)
    m.add_argument("--tag", default="main")
    m.add_argument("--set", nargs="*", default=[],
                   help="module constants to try, e.g. symmetric.DIRECTED_FIRST=1")
    m.add_argument("--out", default=str(DEFAULT_OUT))
    r = sub.add_parser("report")
    r.add_argument("--out", default=str(DEFAULT_OUT))
    r.add_argument("--tags", nargs="*")
    args = ap.parse_args()
    measure(args) if args.cmd == "measure" else report(args)


if __name__ == "__main__":
    main()
