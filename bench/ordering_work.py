"""Calibrate the greedy pass's work units (``budget.greedy_work_s``: deterministic seconds, issue 36):
per group the CPU seconds of each step of the greedy chain against the counts the work model
charges, and the least-squares constants that turn counts into seconds on this machine.

    python bench/ordering_work.py FILE [FILE...] [--modes safe,free]

For every group the greedy chain solves (not fixed, >= 2 curves) of each FILE and mode (time
objective, the default), started at the file's origin, it measures with ``time.thread_time``
(this thread's CPU seconds: the numba kernels run in it; the machine's load does not count):
building the group (every group, the chain's pass), making its link matrix (``LinkCosts.matrix``:
m^2 links for m candidates), greedy (nearest neighbour, local search, orientation DP, cheap
bound: ``greedy.solve``), the subset DP where ``greedy_pass.dp_first`` takes it, and the matching step
where ``greedy_pass.matching_applies`` takes it, and on every tenth group ILS with a fixed number
of kicks (safe mode's block orders). Then it fits each step's constants (non-negative least
squares) and prints, per step, the fitted constants, the measured and modelled totals, and the
spread of measured / modelled over the groups above 1 ms. The constants in ``budget.py``
(``WORK_*``) come from its output (docs/BENCHMARKS.md, "Greedy pass work units").
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import nnls

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import gatesopt  # noqa: E402
from gatesopt.ordering import dp, greedy, greedy_pass, ils  # noqa: E402
from gatesopt.ordering.chain import end_of  # noqa: E402
from gatesopt.ordering.groups import build  # noqa: E402
from gatesopt.ordering.problem import Anchor, OrderingOptions  # noqa: E402


def cpu(fn):
    t = time.thread_time()
    out = fn()
    return out, time.thread_time() - t


def measure(path: str, mode: str, rows: dict) -> None:
    prob = build(gatesopt.parse(path), OrderingOptions(mode=mode))
    origin = Anchor.of(prob.origin_xy)
    pass_s, pass_curves = 0.0, 0
    for g in range(prob.n_groups):
        grp, t_b = cpu(lambda: prob.group(g, origin, end_of(prob, g)))
        pass_s += t_b
        pass_curves += grp.n_curves
        if prob.group_fixed[g] or grp.n_curves < 2:
            continue
        n, m = grp.n_curves, grp.n_cands
        if grp.costs is not None and grp.costs.make_arc is not None:
            _, t_m = cpu(grp.costs.matrix)
            rows["matrix"].append((n, m, t_m))
        if greedy_pass.dp_first(grp):
            _, t_d = cpu(lambda: dp.solve(grp))
            rows["dp"].append((n, m, t_d))
            continue
        gs, t_g = cpu(lambda: greedy.solve(grp))
        rows["greedy"].append((n, m, t_g))
        if gs.status.value != "optimal" and greedy_pass.matching_applies(grp):
            got, t_x = cpu(lambda: greedy_pass.matching_path(grp, gs))
            rows["matching"].append((n, m, t_x))
            rows["matching_sizes"].append((mode, n, t_x, got.status.value == "optimal"))
        if g % 10 == 0 and 4 <= n <= 200:
            # a fixed number of ILS kicks (safe mode's block orders: ``blocks.BLOCK_KICKS_PER_BLOCK``)
            kicks = ils.KICKS_PER_CURVE * n
            _, t_i = cpu(lambda: ils.improve_ils(grp, gs.order, kicks=kicks, local_optimum=True))
            rows["ils"].append((n, kicks, t_i))
    rows["pass"].append((pass_curves, 0, pass_s))
    print(f"{Path(path).name} {mode}: {prob.n_groups} groups, {pass_curves} curves, "
          f"pass {pass_s:.2f} s CPU", flush=True)


FEATURES = {
    # step: (names, features of (n, m))
    "matrix": (("s_per_link",), lambda n, m: [m * m]),
    "greedy": (("s_per_link", "s_per_curve", "s_per_group"), lambda n, m: [m * m, n, 1.0]),
    "dp": (("s_per_state", "s_per_group"), lambda n, m: [2.0 ** n * m * m, 1.0]),
    "matching": (("s_per_curve3", "s_per_link", "s_per_group"),
                 lambda n, m: [float(n) ** 3, m * m, 1.0]),
    "pass": (("s_per_curve",), lambda n, m: [n]),
    # (n, kicks): per kick and curve
    "ils": (("s_per_kick_curve", "s_per_group"), lambda n, k: [k * n, 1.0]),
}


def fit(step: str, rows) -> None:
    names, feat = FEATURES[step]
    n = np.array([r[0] for r in rows], float)
    m = np.array([r[1] for r in rows], float)
    y = np.array([r[2] for r in rows])
    X = np.array([feat(a, b) for a, b in zip(n, m)], float)
    # relative least squares (each group weighs by its own time: the large ones decide the
    # total, the small ones the count; 1 ms floor against timer noise)
    w = 1.0 / np.maximum(y, 1e-3)
    coef, _ = nnls(X * w[:, None], y * w)
    pred = X @ coef
    big = y > 1e-3
    ratio = y[big] / np.maximum(pred[big], 1e-12)
    q = np.quantile(ratio, [0.1, 0.5, 0.9]) if big.any() else [np.nan] * 3
    consts = ", ".join(f"{k} {v:.3g}" for k, v in zip(names, coef))
    print(f"{step:9s} {len(rows):5d} groups: {consts}; measured {y.sum():.2f} s, modelled "
          f"{pred.sum():.2f} s; measured/modelled over {int(big.sum())} groups > 1 ms: "
          f"p10 {q[0]:.2f} p50 {q[1]:.2f} p90 {q[2]:.2f}")


def matching_sizes(rows) -> None:
    """The matching step by group size: groups, CPU seconds, groups it proved."""
    for mode in sorted({r[0] for r in rows}):
        for lo, hi in ((13, 20), (21, 40), (41, 80), (81, 200)):
            r = [x for x in rows if x[0] == mode and lo <= x[1] <= hi]
            print(f"matching {mode} {lo}-{hi} curves: {len(r)} groups, {sum(x[2] for x in r):.2f} s "
                  f"CPU, {sum(x[3] for x in r)} proven")


def block_ils(path: str) -> None:
    """Safe mode's block orders (``blocks._solve``): every ILS call the build makes, its
    blocks, kicks and CPU seconds, and the fitted seconds per kick and block."""
    from gatesopt.ordering import blocks
    real = ils.improve_ils
    rec = []

    def timed(grp, order, **kw):
        t = time.thread_time()
        out = real(grp, order, **kw)
        rec.append((grp.n_curves, kw.get("kicks"), time.thread_time() - t))
        return out

    ils.improve_ils = timed
    try:
        build(gatesopt.parse(path), OrderingOptions(mode="safe"))
    finally:
        ils.improve_ils = real
    if not rec:
        print(f"{Path(path).name}: no block ILS (kicks per block {blocks.BLOCK_KICKS_PER_BLOCK})")
        return
    warm = rec[1:] or rec           # the first call loads (or compiles) the kernel
    units = sum(n * k for n, k, _ in warm)
    cpu_s = sum(t for _, _, t in warm)
    print(f"{Path(path).name}: {len(rec)} block ILS calls, {rec[0][0]} blocks, {rec[0][1]} kicks "
          f"first; after the first ({rec[0][2]:.2f} s) {cpu_s:.2f} s CPU: {cpu_s / units:.3g} s per "
          "kick and block")


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("files", nargs="+")
    ap.add_argument("--modes", default="safe,free")
    ap.add_argument("--matching-max-curves", type=int, default=None,
                    help="measure the matching step up to this many curves (default: "
                         "greedy_pass.MATCHING_MAX_CURVES)")
    ap.add_argument("--blocks", action="store_true",
                    help="only measure safe mode's block ILS on the files (block_ils)")
    args = ap.parse_args()
    if args.blocks:
        for path in args.files:
            block_ils(path)
        return 0
    if args.matching_max_curves is not None:
        greedy_pass.MATCHING_MAX_CURVES = args.matching_max_curves
    rows = {k: [] for k in FEATURES}
    rows["matching_sizes"] = []
    for path in args.files:
        for mode in args.modes.split(","):
            measure(path, mode, rows)
    for step, r in rows.items():
        if r and step in FEATURES:
            fit(step, r)
    matching_sizes(rows["matching_sizes"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
