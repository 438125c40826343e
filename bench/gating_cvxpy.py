"""The gating problem through cvxpy (``gating.cvxpy_model``) against ``milp`` (HiGHS directly).

For each file: ``milp`` whole (dp warm start, model, HiGHS), then ``to_cvxpy`` (import of cvxpy
apart), cvxpy's compilation and HiGHS through cvxpy, with ``milp``'s HiGHS options and with
HiGHS's defaults (``--defaults``); the energies must agree. One run each.

    python bench/gating_cvxpy.py FILE [FILE ...] [--firmware marlin] [--max-added-time-pct 1]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gatesopt import parse  # noqa: E402
from gatesopt.gating import GatingOptions, build, cvxpy_model, solve  # noqa: E402
from gatesopt.gating.milp import highs_options  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--firmware", default="marlin")
    ap.add_argument("--max-added-time-pct", type=float, default=None)
    ap.add_argument("--defaults", action="store_true", help="also solve with HiGHS's default options")
    a = ap.parse_args()
    t = time.perf_counter()
    import cvxpy  # noqa: F401
    print(f"import cvxpy: {time.perf_counter() - t:.2f} s")
    print("| file | lines | x / z / w variables | milp s | to_cvxpy s | compile s | HiGHS s "
          "| HiGHS defaults s | energy milp J | energy cvxpy J |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for f in a.files:
        prog = parse(f)
        p = build(prog, GatingOptions.for_firmware(a.firmware, rotate="none",
                                                  max_added_time_pct=a.max_added_time_pct))
        t = time.perf_counter()
        m = solve(p, "milp")
        t_milp = time.perf_counter() - t
        t = time.perf_counter()
        cm = cvxpy_model.to_cvxpy(p)
        t_build = time.perf_counter() - t
        cm.problem.solve(solver="HIGHS", **highs_options(p, None))
        c = cm.solution()
        compile_s, solver_s = cm.problem.compilation_time, cm.problem.solver_stats.solve_time
        default_s = "-"
        if a.defaults:
            cd = cvxpy_model.to_cvxpy(p)
            cd.problem.solve(solver="HIGHS")
            default_s = f"{cd.problem.solver_stats.solve_time:.2f}"
            assert abs(cd.solution().energy_j - m.energy_j) <= 1e-6 * abs(m.energy_j)
        mod = cm.model
        print(f"| {Path(f).name} | {prog.n_lines:,} | {mod.nx:,} / {len(mod.z_members):,} / "
              f"{len(mod.w_members):,} | {t_milp:.2f} | {t_build:.2f} | {compile_s:.2f} | {solver_s:.2f} "
              f"| {default_s} | {m.energy_j:.3f} | {c.energy_j:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
