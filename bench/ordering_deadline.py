"""Does the curve ordering's solve end within its budget? (issue 37: deadlines passed down)

    python bench/ordering_deadline.py FILE BUDGET_S [WORKERS]

Parses FILE, builds its ordering problem (safe mode, time objective: the defaults), and runs
``ordering.layers.solve`` with ``budget_s=BUDGET_S`` (auto, WORKERS processes, default 1) in this
process; prints the solve's wall time and its ratio to the budget, the main process's CPU seconds,
how many groups ran out of time (the slicer's order kept) and the groups whose solve overran its
limit most. Parse and build are outside the budget here (``gatesopt solve`` counts them: its
budget is the whole run's).
"""
from __future__ import annotations

import os
import sys
import time

from gatesopt.ordering import layers, runner
from gatesopt.ordering.groups import build
from gatesopt.ordering.problem import OrderingOptions
from gatesopt.parse import parse


def main() -> int:
    path, budget = sys.argv[1], float(sys.argv[2])
    workers = int(sys.argv[3]) if len(sys.argv) > 3 else 1
    t = time.perf_counter()
    program = parse(path)
    problem = build(program, OrderingOptions())
    print(f"parse + build {time.perf_counter() - t:.2f} s: {problem.n_curves:,} curves in "
          f"{problem.n_groups:,} groups; load {os.getloadavg()[0]:.1f}")
    seen = []
    run = runner.GroupRunner.run

    def timed(self, g, grp):            # the limit each group got, and what its solve took
        fn, got = self.fn, {}

        def solve(grp, time_limit_s, **kw):
            got["limit"], t1 = time_limit_s, time.perf_counter()
            try:
                return fn(grp, time_limit_s=time_limit_s, **kw)
            finally:
                got["took"] = time.perf_counter() - t1
        self.fn = solve
        try:
            gs = run(self, g, grp)
        finally:
            self.fn = fn
        seen.append((g, grp.n_curves, got.get("limit"), got.get("took", 0.0), gs.formulation))
        return gs
    runner.GroupRunner.run = timed
    t, c = time.perf_counter(), time.process_time()
    sol = layers.solve(problem, "auto", time_limit_s=2.0, budget_s=budget, workers=workers)
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    late = sum(gs.formulation.startswith(runner.OUT_OF_TIME) for gs in sol.groups)
    print(f"solve wall {wall:.2f} s, budget {budget:g} s, ratio {wall / budget:.2f}; main CPU {cpu:.2f} s; "
          f"groups out of time {late:,} (main process: {sum(s[2] is None for s in seen):,} of {len(seen):,})")
    over = sorted((s for s in seen if s[2] is not None), key=lambda s: s[2] - s[3])[:10]    # most over first
    for g, n, limit, took, form in over:
        print(f"  group {g} ({n} curves): limit {limit:.3f} s, took {took:.3f} s, {form}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
