"""What proving a file's groups costs against what a whole-run budget leaves for it (issue 36:
">= 90 % of groups proven optimal under the 10 s budget").

    python bench/proof_budget.py measure FILE:MODE [FILE:MODE ...] [--out bench/proof-budget.jsonl]
    python bench/proof_budget.py report [--out ...] [--corpus-json J] [--write docs/RESULTS.md]

``measure`` runs ``order`` on each file as the bench of issue 36 does (auto, 2 s per group) but
with no budget and one process, so every re-orderable group gets its exact pass, and times each
stage of the run the way a budgeted run spends it: reading the file, building the problem, the
greedy pass, the exact pass, the time guard (its emits, parses and planner runs), the check. Per
group it keeps the size, the solve's seconds and whether it was proven; from those, "cheapest
first": how many seconds of exact solving the cheapest groups need to reach a share of the file's
groups proven, each group's solve as this run measured it (a budgeted run's plan funds the
smallest groups first, ``ordering.budget``; a group's solve includes auto's own warm start).

``report`` writes the table; with ``--corpus-json`` (rows of ``bench/ordering_as_printed.py``) it
adds, per measured file and mode, the corpus-wide proven share that file's best case would give:
the corpus's groups proven as that bench measured them, with the file's count replaced by the
share its cheapest groups reach in the seconds a 10 s run has left after the stages measured
here (none left: its greedy pass's proofs only), and in the whole 10 s (no reading, building,
greedy pass or guard at all: a bound no budgeted run reaches).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from _markdown import publish  # noqa: E402  (bench/_markdown.py)

INSTANCES = ROOT.parent / "shared" / "instances"
DEFAULT_OUT = ROOT / "bench" / "proof-budget.jsonl"
SECTION = "## Curve ordering: what proving the largest files costs against a 10 s budget"
SHARES = (0.5, 0.8, 0.9)
BUDGET_S = 10.0


def _timed(mod, name: str, spent: dict) -> None:
    """Wrap ``mod.name`` so that its wall seconds add up in ``spent[name]``."""
    f = getattr(mod, name)

    def g(*a, **k):
        t = time.perf_counter()
        try:
            return f(*a, **k)
        finally:
            spent[name] = spent.get(name, 0.0) + time.perf_counter() - t
    setattr(mod, name, g)


def measure_one(path: str, mode: str) -> dict:
    import gatesopt.rewrite.order as order_mod
    from gatesopt.cli.files import read_program
    from gatesopt.ordering import OrderingOptions
    from gatesopt.solvers import Status
    spent: dict = {}
    for name in ("build", "solve_greedy", "solve", "emit_guarded", "repair_pass"):
        _timed(order_mod, name, spent)
    t0 = time.perf_counter()
    program = read_program(path)
    read_s = time.perf_counter() - t0
    t1 = time.perf_counter()
    res = order_mod.order_program(program, OrderingOptions(mode=mode), formulation="auto",
                                  time_limit_s=2.0, budget_s=None, workers=1)
    run_s = time.perf_counter() - t1
    problem, sol = res.problem, res.solution
    sizes, secs, proven = [], [], []
    for g, gs in enumerate(sol.groups):
        if not problem.group_reorderable[g]:
            continue
        sizes.append(int(problem.group_curve_start[g + 1] - problem.group_curve_start[g]))
        secs.append(float(gs.solve_s))
        proven.append(gs.status == Status.OPTIMAL)
    return {"file": Path(path).name, "mode": mode, "lines": int(program.n_lines), "read_s": read_s,
            "build_s": spent.get("build", 0.0), "greedy_s": spent.get("solve_greedy", 0.0),
            "exact_s": spent.get("solve", 0.0), "guard_s": spent.get("emit_guarded", 0.0),
            "repair_s": spent.get("repair_pass", 0.0), "run_s": run_s,
            "groups": len(sizes), "proven": int(sum(proven)), "sizes": sizes, "solve_s": secs,
            "proven_mask": [bool(p) for p in proven], "verified": res.ok}


def cheapest_first(row: dict) -> dict:
    """Seconds of exact solving the cheapest groups need to reach each share of the file's groups
    proven (None: not reached even with every group solved)."""
    secs = np.asarray(row["solve_s"], float)
    ok = np.asarray(row["proven_mask"], bool)
    order = np.argsort(secs, kind="stable")
    cum_s = np.cumsum(secs[order])
    cum_p = np.cumsum(ok[order])
    out = {}
    for share in SHARES:
        need = int(np.ceil(share * len(secs)))
        k = int(np.searchsorted(cum_p, need))
        out[share] = float(cum_s[k]) if k < len(secs) else None
    return out


def measure(args) -> None:
    out = Path(args.out)
    for spec in args.files:
        name, _, mode = spec.partition(":")
        path = str(INSTANCES / name) if not Path(name).exists() else name
        row = measure_one(path, mode or "safe")
        row["date"] = time.strftime("%Y-%m-%d %H:%M")
        with out.open("a") as fh:
            fh.write(json.dumps(row) + "\n")
        cf = cheapest_first(row)
        print(f"{row['file']} {row['mode']}: {row['proven']}/{row['groups']} proven, read "
              f"{row['read_s']:.2f} build {row['build_s']:.2f} greedy {row['greedy_s']:.2f} exact "
              f"{row['exact_s']:.2f} guard {row['guard_s']:.2f} s; cheapest first: "
              + ", ".join(f"{int(k * 100)} % {v:.1f} s" if v is not None else f"{int(k * 100)} % never"
                          for k, v in cf.items()), flush=True)


def report(args) -> None:
    rows = {}
    for line in Path(args.out).read_text().splitlines():
        r = json.loads(line)
        rows[(r["file"], r["mode"])] = r
    corpus = None
    if args.corpus_json:
        corpus = [json.loads(x) for x in Path(args.corpus_json).read_text().splitlines() if x.strip()]
        corpus = [r for r in corpus if r.get("formulation") == "auto" and r.get("folder") == "instances"]
    lines = [SECTION, "",
             "Command (from the repository root): `python bench/proof_budget.py measure "
             + " ".join(f"{f}:{m}" for f, m in rows) + "`, then `python bench/proof_budget.py "
             "report" + (f" --corpus-json {args.corpus_json}" if args.corpus_json else "")
             + " --write docs/RESULTS.md`.", "",
             "Each file ordered as the issue-36 bench orders it (auto, 2 s per group) with no budget "
             "and one process, so that every re-orderable group gets its exact pass; the stages "
             "timed as a budgeted run spends them (*read*: parsing; *build*: the ordering problem, "
             "safe mode's island blocks included; *greedy*: the greedy pass; *exact*: the exact pass; "
             "*guard*: the time guard's emits, parses and planner runs). *cheapest first*: the "
             "seconds of solving the cheapest groups took, in this run, to reach that share of the "
             "file's groups proven (a budgeted run's plan funds the smallest groups first).", "",
             "| file | mode | lines | groups | proven (no budget) | read s | build s | greedy s "
             "| exact s | guard s | 50 % | 80 % | 90 % |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for (f, m), r in rows.items():
        cf = cheapest_first(r)
        cells = [f"{cf[k]:.1f}" if cf[k] is not None else "never" for k in SHARES]
        lines.append(f"| {f} | {m} | {r['lines']:,} | {r['groups']:,} | {r['proven']:,} | "
                     f"{r['read_s']:.2f} | {r['build_s']:.2f} | {r['greedy_s']:.2f} | "
                     f"{r['exact_s']:.2f} | {r['guard_s']:.2f} | " + " | ".join(cells) + " |")
    if corpus:
        lines += ["", "Corpus-wide proven share under the 10 s budget (the rows of "
                  f"`{args.corpus_json}`, bench/ordering_as_printed.py), and what it would be if "
                  "each file above proved, on top of the others as measured, the groups its "
                  "cheapest-first curve reaches in the seconds a 10 s run has left after its read, "
                  "build, greedy pass and guard as measured here (the check and the imports not "
                  "even counted):", "",
                  "| mode | proven as measured | exact seconds left (file) | proven then | proven "
                  "with the whole 10 s each file's exact pass's |",
                  "|---|---:|---|---:|---:|"]
        for mode in ("safe", "free"):
            cr = [r for r in corpus if r["order_mode"] == mode]
            if not cr:
                continue
            tot = sum(r["groups_reordered"] for r in cr)
            opt = sum(r["groups_optimal"] for r in cr)
            best, whole, left_txt = opt, opt, []
            for (f, m), r in rows.items():
                if m != mode:
                    continue
                left = max(0.0, BUDGET_S - r["read_s"] - r["build_s"] - r["greedy_s"] - r["guard_s"])
                secs = np.asarray(r["solve_s"], float)
                ok = np.asarray(r["proven_mask"], bool)
                o = np.argsort(secs, kind="stable")
                cum = np.cumsum(secs[o])
                reach = int(ok[o][:int(np.searchsorted(cum, left, side="right"))].sum())
                all_in = int(ok[o][:int(np.searchsorted(cum, BUDGET_S, side="right"))].sum())
                measured = next((x["groups_optimal"] for x in cr if x["file"] == f), None)
                if measured is None:
                    continue
                best += max(reach, measured) - measured
                whole += max(all_in, measured) - measured
                left_txt.append(f"{f} {left:.1f} s")
            lines.append(f"| {mode} | {opt:,} of {tot:,} ({100 * opt / tot:.1f} %) | "
                         f"{'; '.join(left_txt) or '-'} | {best:,} ({100 * best / tot:.1f} %) | "
                         f"{whole:,} ({100 * whole / tot:.1f} %) |")
    publish("\n".join(lines) + "\n", args.write)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    m = sub.add_parser("measure")
    m.add_argument("files", nargs="+", help="FILE:MODE (a name in ../shared/instances or a path)")
    m.add_argument("--out", default=str(DEFAULT_OUT))
    r = sub.add_parser("report")
    r.add_argument("--out", default=str(DEFAULT_OUT))
    r.add_argument("--corpus-json", default=None)
    r.add_argument("--write", nargs="?", const=str(ROOT / "docs" / "RESULTS.md"), default=None)
    args = ap.parse_args()
    measure(args) if args.cmd == "measure" else report(args)


if __name__ == "__main__":
    main()
