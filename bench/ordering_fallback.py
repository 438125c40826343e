"""Curve ordering: what a budget's fallback group costs, and what ILS buys there (issue 4).

    python bench/ordering_fallback.py [--file F] [--mode safe] [--min-curves 40] [--max-curves 400]
        [--sample 60] [--seed 0] [--repeats 3] [--write docs/BENCHMARKS.md]

Under a budget most groups of a large file get no exact step: ``auto.solve`` gives them the
greedy path, the matching's bound and patched path, and (if at least
``auto.MIN_FALLBACK_ILS_S_PER_CURVE`` per curve is left of their limit) ILS. This samples such
groups (``ordering_peers.group_instances``: each starts where the slicer's order left the previous
one) and runs ``auto.solve`` on each with limits of 0 to 400 us per curve, once as auto does and
once with ILS forced on (the threshold set to 0), in the same process: per limit, time per curve
(best of ``--repeats``), the travel of all paths, and their median gap to their bound. The ratio
column is time over the same groups' time at limit 0, so machine speed cancels out.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from _markdown import publish  # bench/_markdown.py

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
LIMITS_US = (0, 40, 80, 160, 400)


def _groups(file: str, mode: str, lo: int, hi: int, sample: int, seed: int):
    from ordering_gaps import _groups as symmetric_groups     # the symmetric model's groups
    groups = [grp for _, grp in symmetric_groups(file, mode, lo, hi)]
    pick = np.random.default_rng(seed).choice(len(groups), min(sample, len(groups)), replace=False)
    return [groups[i] for i in sorted(pick)]


def _run(groups, limit_us: float, repeats: int):
    from gatesopt.ordering import auto
    best_s = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        sols = [auto.solve(g, time_limit_s=limit_us * 1e-6 * g.n_curves) for g in groups]
        best_s = min(best_s, time.perf_counter() - t)
    travel = sum(s.objective for s in sols)
    gaps = [(s.objective - s.bound) / s.objective for s in sols if s.objective > 0]
    return best_s, travel, float(np.median(gaps)), float(np.mean(np.asarray(gaps) <= 0.02))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--file", default="cura413_bunny_cubic10_mk3.gcode.gz")
    ap.add_argument("--mode", default="safe")
    ap.add_argument("--min-curves", type=int, default=40)
    ap.add_argument("--max-curves", type=int, default=400)
    ap.add_argument("--sample", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--write")
    args = ap.parse_args()
    from gatesopt.ordering import auto
    groups = _groups(args.file, args.mode, args.min_curves, args.max_curves, args.sample, args.seed)
    n = sum(g.n_curves for g in groups)
    auto.warm_up()
    default = auto.MIN_FALLBACK_ILS_S_PER_CURVE
    rows, base = [], None
    for forced in (False, True):
        auto.MIN_FALLBACK_ILS_S_PER_CURVE = 0.0 if forced else default
        for lim in LIMITS_US:
            s, travel, gap, within = _run(groups, lim, args.repeats)
            base = s if base is None else base
            rows.append((("ILS forced" if forced else "auto"), lim, s, travel, gap, within))
    auto.MIN_FALLBACK_ILS_S_PER_CURVE = default
    cmd = (f"python bench/ordering_fallback.py --file {args.file} --mode {args.mode} --min-curves "
           f"{args.min_curves} --max-curves {args.max_curves} --sample {args.sample} --seed "
           f"{args.seed} --repeats {args.repeats}" + (f" --write {args.write}" if args.write else ""))
    lines = ["## Curve-ordering fallback groups: the cost of a group without an exact step", "",
             f"Command: `{cmd}`", "",
             f"{len(groups)} groups of {args.min_curves}-{args.max_curves} curves ({n} curves) of "
             f"{args.file}, {args.mode} mode, each solved by `auto.solve` with the limit per curve "
             "below and no exact step (every limit is below `auto.exact_time_s`). *auto*: ILS only "
             f"if {default * 1e6:.0f} us per curve are left after the greedy path and the matching "
             "(`auto.MIN_FALLBACK_ILS_S_PER_CURVE`); *ILS forced*: the threshold set to 0, as before "
             f"session 20. Time: best of {args.repeats}, per curve; ratio: to the same groups at limit "
             "0 in the same run. Gap: (path - bound) / path per group.", "",
             "| path | limit (us/curve) | time (us/curve) | time ratio | travel (mm) | median gap | gap <= 2 % |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for name, lim, s, travel, gap, within in rows:
        lines.append(f"| {name} | {lim} | {s / n * 1e6:.1f} | {s / base:.2f} | {travel:,.1f} | "
                     f"{100 * gap:.2f} % | {100 * within:.0f} % |")
    publish("\n".join(lines) + "\n", args.write)


if __name__ == "__main__":
    main()
