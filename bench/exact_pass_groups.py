"""The exact pass's passing of a file's groups after the greedy pass: with greedy's planned groups
taken where the exact chain starts and ends alike (``layers.GreedyPass.planned_at``) against
every group built again, the same run.

    python bench/exact_pass_groups.py FILE:MODE [FILE:MODE ...] [--repeat 3] [--write docs/BENCHMARKS.md]

Per file: the problem built and the greedy pass run once (no budget, one worker); then the exact
solve with a budget of 0 s (every group passed and answered with greedy's path, no search: what
passing the groups costs, the part an exact pass pays before any proof) with greedy's planned
groups and without them (``planned=()``), alternating, ``--repeat`` times each; the least wall
time of each, their ratio, how many groups were taken as planned, and whether the two solutions
are the same (curve order, directions, per-group objectives).
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from _markdown import replace_section  # noqa: E402  (bench/_markdown.py)

from gatesopt.ordering import layers  # noqa: E402
from gatesopt.ordering.groups import build  # noqa: E402
from gatesopt.ordering.problem import OrderingOptions  # noqa: E402
from gatesopt.parse import parse  # noqa: E402

SECTION = "Exact pass: greedy's planned groups taken again"


def measure(path: str, mode: str, repeat: int) -> dict:
    prob = build(parse(path), OrderingOptions(mode=mode))
    gp = layers.solve_greedy(prob)
    without = dataclasses.replace(gp, planned=())
    best = {"with": np.inf, "without": np.inf}
    sols = {}
    layers.solve(prob, "auto", budget_s=0.0, greedy=gp)          # warm-up (kernels, imports)
    for _ in range(repeat):
        for name, g in (("without", without), ("with", gp)):
            chain = []          # the exact chain's (Group, start, end) per group
            t = time.perf_counter()
            sols[name] = layers.solve(prob, "auto", budget_s=0.0, greedy=g, planned=chain)
            best[name] = min(best[name], time.perf_counter() - t)
            if name == "with":
                n_taken = sum(grp is p[0] for (grp, _, _), p in zip(chain, gp.planned))
    a, b = sols["with"], sols["without"]
    same = (np.array_equal(a.curve_order, b.curve_order)
            and np.array_equal(a.curve_reversed, b.curve_reversed)
            and [gs.objective for gs in a.groups] == [gs.objective for gs in b.groups])
    return dict(file=Path(path).name, mode=mode, groups=prob.n_groups, taken=n_taken,
                without_s=best["without"], with_s=best["with"], same=same)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+", help="FILE:MODE (mode safe or free)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--write", help="replace this script's section of a markdown file")
    a = ap.parse_args()
    rows = []
    for spec in a.files:
        path, mode = spec.rsplit(":", 1)
        r = measure(path, mode, a.repeat)
        rows.append(r)
        print(f"{r['file']} {r['mode']}: {r['taken']} of {r['groups']} groups taken as planned; "
              f"pass {r['without_s']:.3f} s -> {r['with_s']:.3f} s "
              f"({r['with_s'] / r['without_s']:.2f}x); same answer: {r['same']}", flush=True)
    if a.write:
        lines = [f"## {SECTION}", "",
                 "The exact pass after the greedy pass passes every group again; a group it enters "
                 "where greedy's chain did, and leaves to the same end, is now the Group greedy "
                 "planned (`layers.GreedyPass.planned_at`) instead of one built again (its "
                 "candidates, its start and end links). Measured with a budget of 0 s (every "
                 "group passed and answered with greedy's path: what passing costs before any "
                 "proof), least of "
                 f"{a.repeat} alternating runs each, one process:", "",
                 "| file | mode | groups | taken as planned | pass, all built (s) | pass, planned taken (s) | ratio | same answer |",
                 "|---|---|---:|---:|---:|---:|---:|---|"]
        for r in rows:
            lines.append(f"| {r['file']} | {r['mode']} | {r['groups']:,} | {r['taken']:,} | "
                         f"{r['without_s']:.3f} | {r['with_s']:.3f} | "
                         f"{r['with_s'] / r['without_s']:.2f}x | {'yes' if r['same'] else 'NO'} |")
        lines += ["", "Command: `python bench/exact_pass_groups.py " + " ".join(a.files)
                  + f" --repeat {a.repeat} --write docs/BENCHMARKS.md`", ""]
        replace_section(Path(a.write), "\n".join(lines))
    return 0 if all(r["same"] for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
