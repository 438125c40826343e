"""One exact step timed two ways on the same groups: each group solved under each setting twice,
interleaved (a, b, a, b), the best thread CPU of the two kept (bench/rc_search.py,
bench/lp_runs.py)."""
from __future__ import annotations

import time


def best_of_two(groups, settings: dict, solve):
    """``settings``: name -> a function that puts that setting in place; ``solve(grp)`` -> the
    group's answer (a ``GroupSolution``). Each group's link matrix is made before any timing.
    Returns (CPU seconds per setting, groups proven per setting, the largest difference of the
    objectives of groups every setting proved)."""
    from gatesopt.solvers import Status
    cpu = dict.fromkeys(settings, 0.0)
    proven = dict.fromkeys(settings, 0)
    worst_diff = 0.0
    for grp in groups:
        grp.arc_cost()
        got = {}
        for name in list(settings) * 2:
            settings[name]()
            t = time.thread_time()
            gs = solve(grp)
            took = time.thread_time() - t
            prev = got.get(name)
            got[name] = (min(took, prev[0]) if prev else took, gs)
        for name in settings:
            cpu[name] += got[name][0]
            proven[name] += got[name][1].status == Status.OPTIMAL
        objs = [gs.objective for _, gs in got.values() if gs.status == Status.OPTIMAL]
        if len(objs) == len(settings):
            worst_diff = max(worst_diff, max(objs) - min(objs))
    return cpu, proven, worst_diff
