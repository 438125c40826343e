"""Curve ordering: what exact blossom separation adds to the root LP (formulations/ordering.md,
"milp, symmetric model", step 2).

    python bench/ordering_roots.py measure [--groups FILE:MODE:MIN:MAX:SAMPLE ...] [--seed 3]
        [--time-limit 2] [--out bench/ordering-roots.jsonl]
    python bench/ordering_roots.py report [--out ...] [--write docs/RESULTS.md]

Per sampled group of the symmetric model, in the same run: the complete root with the fast
separators only (components, exact subtour cuts, the odd-component blossom heuristic) and the
complete root that also separates blossoms exactly (``_blossoms_exact``, no time share: the
root runs until nothing is violated), each against the best path known (``auto.solve`` with
``--time-limit`` seconds; "optimal" when it proved it). The gap is (best path - root) / best path.
Also, per group, ``auto.solve`` with 1 s as the ordering bench runs it, once without exact
blossoms and once with them (the shipped ``EXACT_BLOSSOM_SHARE``): proven or not, and its gap.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from _markdown import publish  # bench/_markdown.py
from ordering_gaps import _pct  # gap in % of the best path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
DEFAULT_OUT = ROOT / "bench" / "ordering-roots.jsonl"
DEFAULT_GROUPS = [
    "cura413_bunny_cubic10_mk3.gcode.gz:free:60:300:30",
    "cura413_xend_zigzag100.gcode.gz:free:30:300:12",
    "cura413_ymotor_gyroid15_rel.gcode.gz:free:30:300:12",
    "real_kirimoto30.gcode.gz:safe:30:300:8",
    "cura413_star_triangles20.gcode.gz:free:30:300:8",
    "real_cura591.gcode.gz:free:30:400:8",
    "cura413_cyl_grid20.gcode.gz:free:30:300:8",
]


def measure(args) -> None:
    from gatesopt.ordering import auto, greedy, symmetric
    from ordering_gaps import _groups
    auto.warm_up()
    share = symmetric.EXACT_BLOSSOM_SHARE
    with open(args.out, "a") as out:
        for spec in args.groups:
            file, mode, lo, hi, k = spec.split(":")
            gs = [(g, grp) for g, grp in _groups(file, mode, int(lo), int(hi))]
            rng = np.random.default_rng(args.seed)
            for i in sorted(rng.choice(len(gs), min(int(k), len(gs)), replace=False)):
                g, grp = gs[i]
                start = greedy.solve(grp).order
                row = {"file": file, "mode": mode, "group": int(g), "n": grp.n_curves,
                       "spec": spec, "seed": args.seed, "time_limit_s": args.time_limit}
                for name, seconds in (("fast", 0.0), ("exact", 600.0)):
                    model = symmetric.SymmetricModel(grp, start)
                    t = time.perf_counter()
                    row[f"root_{name}_mm"] = model.root(time.perf_counter() + 600.0,
                                                        exact_blossoms_s=seconds)
                    row[f"root_{name}_s"] = time.perf_counter() - t
                    row[f"root_{name}_cuts"] = len(model.cut_inside)
                for name, s in (("fast", 0.0), ("exact", share)):
                    symmetric.EXACT_BLOSSOM_SHARE = s
                    try:
                        one = auto.solve(grp, time_limit_s=1.0)
                    finally:
                        symmetric.EXACT_BLOSSOM_SHARE = share
                    row[f"at1_{name}_status"] = one.status
                    row[f"at1_{name}_gap_pct"] = _pct(one.objective, one.bound)
                    row[f"at1_{name}_mm"] = one.objective
                best = auto.solve(grp, time_limit_s=args.time_limit)
                row.update(best_mm=min(best.objective, row["at1_fast_mm"], row["at1_exact_mm"]),
                           best_status=best.status, share=share)
                out.write(json.dumps(row) + "\n")
                out.flush()
                print(json.dumps(row), flush=True)


def report(args) -> str:
    rows = [json.loads(x) for x in Path(args.out).read_text().splitlines() if x.strip()]
    lines = ["## Curve ordering: exact blossom separation at the root", "",
             "Command (from the repository root, with ../shared/instances beside it; 2 cores shared with other jobs):", "",
             "```"]
    specs = []
    for r in rows:
        if r["spec"] not in specs:
            specs.append(r["spec"])
    tl = rows[0]["time_limit_s"] if rows else 2.0
    lines.append("python bench/ordering_roots.py measure --groups " + " ".join(specs)
                 + f" --seed {rows[0]['seed'] if rows else 3} --time-limit {tl:g}")
    lines += ["python bench/ordering_roots.py report --write docs/RESULTS.md", "```", ""]
    if not rows:
        return "\n".join(lines + ["(no rows)"]) + "\n"
    gf = np.array([_pct(r["best_mm"], r["root_fast_mm"]) for r in rows])
    ge = np.array([_pct(r["best_mm"], r["root_exact_mm"]) for r in rows])
    closed = 100.0 * (gf.sum() - ge.sum()) / gf.sum() if gf.sum() > 0 else 0.0
    tf = np.array([r["root_fast_s"] for r in rows])
    te = np.array([r["root_exact_s"] for r in rows])
    raised = int(np.sum(ge < gf - 1e-6))
    lines += [f"**{len(rows)} sampled groups of {min(r['n'] for r in rows)}-{max(r['n'] for r in rows)} curves "
              f"({sum(r['best_status'] == 'optimal' for r in rows)} of their best paths proven optimal in {tl:g} s). "
              f"Complete root, gap to the best path: median {np.median(gf):.2f} % -> {np.median(ge):.2f} %, "
              f"mean {gf.mean():.2f} % -> {ge.mean():.2f} %; exact blossoms raise the root on {raised} groups and close "
              f"{closed:.1f} % of the summed gap. Root time: median {np.median(tf) * 1e3:.0f} -> {np.median(te) * 1e3:.0f} ms, "
              f"max {tf.max():.2f} -> {te.max():.2f} s.**", ""]
    pf = sum(r["at1_fast_status"] == "optimal" for r in rows)
    pe = sum(r["at1_exact_status"] == "optimal" for r in rows)
    wf = sum(r["at1_fast_gap_pct"] <= 2.0 for r in rows)
    we = sum(r["at1_exact_gap_pct"] <= 2.0 for r in rows)
    lines += [f"`auto` with 1 s per group (as the ordering bench), without / with exact blossoms in the first "
              f"{rows[0]['share']:.0%} of the group's time: proven {pf} / {pe} of {len(rows)}; gap <= 2 % (proven included) "
              f"{wf} / {we}; median gap {np.median([r['at1_fast_gap_pct'] for r in rows]):.2f} % / "
              f"{np.median([r['at1_exact_gap_pct'] for r in rows]):.2f} %. One run each on a shared machine: a group "
              "near its limit can tip either way between runs.", "",
              "| file | mode | groups | curves | root gap, fast (median %) | with exact blossoms | root ms, fast (median) | with exact | proven at 1 s, fast | with exact |",
              "|---|---|---:|---|---:|---:|---:|---:|---:|---:|"]
    for spec in specs:
        rs = [r for r in rows if r["spec"] == spec]
        a = [_pct(r["best_mm"], r["root_fast_mm"]) for r in rs]
        b = [_pct(r["best_mm"], r["root_exact_mm"]) for r in rs]
        lines.append(f"| {rs[0]['file']} | {rs[0]['mode']} | {len(rs)} | {min(r['n'] for r in rs)}-{max(r['n'] for r in rs)} | "
                     f"{np.median(a):.2f} | {np.median(b):.2f} | {np.median([r['root_fast_s'] for r in rs]) * 1e3:.0f} | "
                     f"{np.median([r['root_exact_s'] for r in rs]) * 1e3:.0f} | "
                     f"{sum(r['at1_fast_status'] == 'optimal' for r in rs)} | {sum(r['at1_exact_status'] == 'optimal' for r in rs)} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    m = sub.add_parser("measure")
    m.add_argument("--groups", nargs="+", default=DEFAULT_GROUPS,
                   help="FILE:MODE:MIN_CURVES:MAX_CURVES:SAMPLE")
    m.add_argument("--seed", type=int, default=3)
    m.add_argument("--time-limit", type=float, default=2.0)
    m.add_argument("--out", default=str(DEFAULT_OUT))
    r = sub.add_parser("report")
    r.add_argument("--out", default=str(DEFAULT_OUT))
    r.add_argument("--write", default=None)
    a = ap.parse_args()
    if a.cmd == "measure":
        measure(a)
    else:
        publish(report(a), a.write)


if __name__ == "__main__":
    main()
