"""The exact step's LPs run without HiGHS's interrupt callbacks (``_native.run_lp``) against the
run with them (``_native.run_highs``, as the symmetric model ran its LPs before): ``auto``'s exact
step on real groups, thread CPU seconds, best of two per group and setting, interleaved.

    python bench/lp_runs.py [FILE:MODE ...] [--max-groups 60] [--limit 1.0] [--write]

Per file: the groups ``auto`` gets (``bench/ordering_proof_rate.py``'s ``file_groups``), of 13-79
curves, the first ``--max-groups``; each solved by ``auto.solve`` with ``--limit`` seconds, the
symmetric model's LPs run by ``run_lp`` and by ``run_highs``. Reported: CPU of each, their ratio,
groups proven each way, and the largest difference of the objectives of groups both prove.
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

from _interleaved import best_of_two  # bench/_interleaved.py
from _markdown import publish  # bench/_markdown.py

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
SECTION = "## LP runs without callbacks"
DEFAULT_SPECS = ["prusa25_bunny_triangles15_lh01.gcode.gz:free",
                 "prusa25_xend_honey25_acp.gcode.gz:free",
                 "cura413_xend_zigzag100.gcode.gz:free",
                 "cura413_bunny_cubic10_mk3.gcode.gz:safe"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("specs", nargs="*", default=DEFAULT_SPECS)
    ap.add_argument("--max-groups", type=int, default=60)
    ap.add_argument("--limit", type=float, default=1.0)
    ap.add_argument("--write", action="store_true", help="into docs/BENCHMARKS.md")
    a = ap.parse_args()
    import ordering_proof_rate as opr
    from gatesopt._native import run_highs, run_lp
    from gatesopt.ordering import auto, symmetric

    def with_callbacks(h, deadline=None):
        return run_highs(h, deadline)
    runners = {"run_lp": run_lp, "run_highs": with_callbacks}

    def runner(name):
        def put():
            symmetric.run_lp = runners[name]
        return put
    auto.warm_up()
    rows, worst_diff = [], 0.0
    for spec in a.specs:
        file, mode = spec.split(":")
        groups = [g for _, g in opr.file_groups(file, mode, 13) if g.n_curves < 80][:a.max_groups]
        cpu, proven, diff = best_of_two(groups, {name: runner(name) for name in runners},
                                        lambda grp: auto.solve(grp, time_limit_s=a.limit))
        worst_diff = max(worst_diff, diff)
        symmetric.run_lp = run_lp
        rows.append((file, mode, len(groups), cpu["run_lp"], cpu["run_highs"], proven["run_lp"],
                     proven["run_highs"]))
        print(rows[-1], flush=True)
    cmd = "python bench/lp_runs.py " + " ".join(a.specs) + f" --max-groups {a.max_groups} --limit {a.limit}"
    lines = [SECTION, "",
             f"Command: `{cmd}` ({platform.python_version()}, {platform.machine()}, 2 cores; "
             f"{time.strftime('%Y-%m-%d')}).", "",
             "The exact step of `auto` (`auto.solve`, the limit per group above) on each file's "
             "groups of 13-79 curves, the symmetric model's LPs run by `_native.run_lp` (no "
             "interrupt callbacks; a stop request looked at before each run) and by "
             "`_native.run_highs` (HiGHS's simplex and MIP interrupt callbacks subscribed per "
             "run), thread CPU seconds, best of two per group and setting, interleaved.", "",
             "| file | mode | groups | CPU s run_lp | run_highs | ratio | proven run_lp | run_highs |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    for file, mode, n, lean, full, p_lean, p_full in rows:
        lines.append(f"| {file} | {mode} | {n} | {lean:.2f} | {full:.2f} | {lean / full:.2f} | "
                     f"{p_lean} | {p_full} |")
    t_lean, t_full = sum(r[3] for r in rows), sum(r[4] for r in rows)
    lines += ["", f"**All: {t_lean:.2f} s with run_lp, {t_full:.2f} s with run_highs "
              f"({t_lean / t_full:.2f}x); proven {sum(r[5] for r in rows)} vs "
              f"{sum(r[6] for r in rows)}; objectives of groups proven both ways differ by at most "
              f"{worst_diff:.2e}.**"]
    publish("\n".join(lines) + "\n", str(ROOT / "docs" / "BENCHMARKS.md") if a.write else None)


if __name__ == "__main__":
    main()
