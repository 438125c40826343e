"""The greedy pass with one worker and two (``layers.solve_greedy``), no budget: wall and
main-process CPU time, matrices kept and handed over by the matrix helper, and whether the two
answers are the same (docs/RESULTS.md, "Greedy's answer independent of the workers").

    python bench/greedy_workers.py FILE [safe|free]
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import gatesopt  # noqa: E402
from gatesopt.ordering import layers  # noqa: E402
from gatesopt.ordering.groups import build  # noqa: E402
from gatesopt.ordering.problem import OrderingOptions  # noqa: E402


def main() -> None:
    path, mode = sys.argv[1], (sys.argv[2] if len(sys.argv) > 2 else "safe")
    t = time.perf_counter()
    prob = build(gatesopt.parse(path), OrderingOptions(mode=mode))
    print(f"parse+build {time.perf_counter() - t:.2f} s, groups {prob.n_groups}", flush=True)
    first = {}
    for w in (1, 2, 1, 2):
        t, c = time.perf_counter(), time.process_time()
        gp = layers.solve_greedy(prob, workers=w)
        wall, cpu = time.perf_counter() - t, time.process_time() - c
        kept = [m for m in gp.matrices if m is not None]
        print(f"workers {w}: wall {wall:.2f} s, main-process cpu {cpu:.2f} s, matrices {len(kept)} "
              f"({sum(m.nbytes for m in kept) / 1e6:.0f} MB), handed over {len(gp.handed)}",
              flush=True)
        first.setdefault(w, gp.solution)
    a, b = first[1], first[2]
    same = (np.array_equal(a.curve_order, b.curve_order)
            and np.array_equal(a.curve_reversed, b.curve_reversed)
            and np.array_equal(a.curve_seam, b.curve_seam))
    print("same answer:", same)


if __name__ == "__main__":
    main()
