"""The reduced-cost search after the exact model's roots (``ordering.rc_search``): the exact step
of ``auto`` on real groups with the search and without it, in one run (thread CPU seconds, best
of two per group and setting, interleaved), and what the search proves by group size.

    python bench/rc_search.py [FILE:MODE ...] [--max-groups 80] [--limit 1.0] [--write]

Per file: the groups ``auto`` gets (``bench/ordering_proof_rate.py``'s ``file_groups``: not
fixed, more than 12 curves, each geometry once, started where the greedy path of the group
before it ended), of fewer than 80 curves, the first ``--max-groups``; each solved by
``auto.solve`` with ``--limit`` seconds, ``rc_search.ENABLED`` on and off. Reported: CPU with /
without (their ratio), groups proven with / without, the largest difference of the objectives
of groups both prove (must be within ``OPTIMAL_ABS_TOL``), and per size band the search's calls
and proofs (both roots).
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from collections import defaultdict
from pathlib import Path

from _interleaved import best_of_two  # bench/_interleaved.py
from _markdown import publish  # bench/_markdown.py

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
SECTION = "## Reduced-cost search"
DEFAULT_SPECS = ["prusa25_bunny_triangles15_lh01.gcode.gz:free",
                 "prusa25_xend_honey25_acp.gcode.gz:free",
                 "prusa25_ymotor_grid30_zhop.gcode.gz:free",
                 "cura413_xend_zigzag100.gcode.gz:free",
                 "cura413_ymotor_gyroid15_rel.gcode.gz:safe",
                 "cura413_bunny_cubic10_mk3.gcode.gz:safe"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("specs", nargs="*", default=DEFAULT_SPECS)
    ap.add_argument("--max-groups", type=int, default=80)
    ap.add_argument("--limit", type=float, default=1.0)
    ap.add_argument("--write", action="store_true", help="into docs/BENCHMARKS.md")
    a = ap.parse_args()
    import ordering_proof_rate as opr
    from gatesopt.ordering import auto, rc_search
    from gatesopt.ordering.problem import OPTIMAL_ABS_TOL
    calls = defaultdict(lambda: [0, 0])         # (size band) -> [calls, proven]
    search = rc_search.search

    def counted(model, order, obj, nodes):
        got = search(model, order, obj, nodes)
        if nodes > 0 and model.group.n_curves <= rc_search.MAX_CURVES:
            band = calls[min(model.group.n_curves // 10 * 10, 20)]
            band[0] += 1
            band[1] += bool(got[3])
        return got
    rc_search.search = counted
    auto.warm_up()
    rows = []
    worst_diff = 0.0

    def enabled(on):
        def put():
            rc_search.ENABLED = on
        return put
    for spec in a.specs:
        file, mode = spec.split(":")
        groups = [g for _, g in opr.file_groups(file, mode, 13) if g.n_curves < 80][:a.max_groups]
        cpu, proven, diff = best_of_two(groups, {True: enabled(True), False: enabled(False)},
                                        lambda grp: auto.solve(grp, time_limit_s=a.limit))
        worst_diff = max(worst_diff, diff)
        rc_search.ENABLED = True
        rows.append((file, mode, len(groups), cpu[True], cpu[False], proven[True], proven[False]))
        print(rows[-1], flush=True)
    cmd = "python bench/rc_search.py " + " ".join(a.specs) + f" --max-groups {a.max_groups} --limit {a.limit}"
    lines = [SECTION, "",
             f"Command: `{cmd}` ({platform.python_version()}, {platform.machine()}, 2 cores; "
             f"{time.strftime('%Y-%m-%d')}).", "",
             "The exact step of `auto` (`auto.solve`, the limit per group above) on each file's "
             "groups of 13-79 curves, with the reduced-cost search after the roots and without it "
             "(`rc_search.ENABLED`), thread CPU seconds, best of two per group and setting, "
             "interleaved.", "",
             "| file | mode | groups | CPU s with | without | ratio | proven with | without |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    for file, mode, n, on, off, p_on, p_off in rows:
        lines.append(f"| {file} | {mode} | {n} | {on:.2f} | {off:.2f} | {on / off:.2f} | "
                     f"{p_on} | {p_off} |")
    t_on, t_off = sum(r[3] for r in rows), sum(r[4] for r in rows)
    lines += ["", f"**All: {t_on:.2f} s with the search, {t_off:.2f} s without ({t_on / t_off:.2f}x); "
              f"proven {sum(r[5] for r in rows)} vs {sum(r[6] for r in rows)}; objectives of groups "
              f"proven both ways differ by at most {worst_diff:.2e} (tolerance "
              f"{OPTIMAL_ABS_TOL:g}).**", "",
              "Search calls (after the symmetric root and after the directed one, groups of at "
              f"most {rc_search.MAX_CURVES} curves) and how many proved the group:", "",
              "| curves | calls | proven |", "|---|---:|---:|"]
    for band in sorted(calls):
        c, p = calls[band]
        label = f"{band}-{band + 9}" if band < 20 else f"20-{rc_search.MAX_CURVES}"
        lines.append(f"| {label} | {c} | {p} |")
    publish("\n".join(lines) + "\n", str(ROOT / "docs" / "BENCHMARKS.md") if a.write else None)


if __name__ == "__main__":
    main()
