"""What passing a file's groups and making their time-objective link matrices cost (issue 36,
proof rate; docs/BENCHMARKS.md, "Link-cost build"). CPU seconds (``time.process_time``), so a
loaded machine inflates them less than wall time.

    python bench/ordering_link_build.py FILE [FILE ...] [--modes safe,free]

Per file and mode: ``pass``: every group built from where the slicer's order of the one before
ends and its slicer's order priced, as ``layers.solve`` passes a group the budget leaves
unsearched (best of 2); ``matrices``: every re-orderable group's link matrix on top
(``cost._dense``, each same-height link and its mirror priced once); ``reference``: the same
matrices with every link priced itself (``mirror=False``), checked equal (bit for bit where
the mirror is unjoined, within 1e-9 ms where it is joined: Klipper, ``cost._mirrorable``).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
INSTANCES = ROOT.parent / "shared" / "instances"


def measure(path: Path, mode: str) -> dict:
    import gatesopt
    from gatesopt.ordering import OrderingOptions, build
    from gatesopt.ordering.chain import end_of
    from gatesopt.ordering.problem import Anchor
    prob = build(gatesopt.parse(path), OrderingOptions(mode=mode))
    pr = prob.pricer

    def walk(make: bool):
        pos, out = Anchor.of(prob.origin_xy), []
        t = time.process_time()
        for g in range(prob.n_groups):
            grp = prob.group(g, pos, end_of(prob, g))
            ident = np.flatnonzero(~grp.cand_reversed & (grp.cand_seam == 0))
            grp.path_cost(ident)
            if make and prob.group_reorderable[g] and grp.dense:
                out.append((g, grp, grp.arc_cost()))
            pos = prob.exit_anchor(g, grp, ident) if grp.n_curves else pos
        return time.process_time() - t, out

    walk(False)                                 # kernels loaded
    pass_s = min(walk(False)[0] for _ in range(2))
    made_s, mats = walk(True)
    t = time.process_time()
    links = 0
    for g, grp, arc in mats:
        gc = prob.source_curves(prob.group_curves(g))[grp.cand_curve]
        changed = np.asarray(grp.cand_reversed) | (np.asarray(grp.cand_seam) != 0)
        ref = pr.dense(grp, gc, changed, mirror=False)
        # bit for bit where the mirror is a link's own moves the other way (unjoined); within
        # rounding where it is the link run backwards (joined, Klipper: ``cost._mirrorable``)
        fin = np.isfinite(ref)
        if not (np.array_equal(fin, np.isfinite(arc))
                and np.allclose(ref[fin], arc[fin], rtol=0, atol=1e-9)):
            raise AssertionError(f"{path.name} {mode} group {g}: mirrored matrix differs")
        links += arc.size
    ref_s = time.process_time() - t
    return {"file": path.name, "mode": mode, "groups": prob.n_groups, "curves": prob.n_curves,
            "matrices": len(mats), "links": links, "pass_s": pass_s,
            "matrices_s": made_s - pass_s, "reference_s": ref_s}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="+")
    ap.add_argument("--modes", default="safe,free")
    args = ap.parse_args()
    for name in args.files:
        path = Path(name) if Path(name).exists() else INSTANCES / name
        for mode in args.modes.split(","):
            r = measure(path, mode)
            print(f"{r['file']} {mode}: {r['groups']:,} groups, {r['curves']:,} curves: pass "
                  f"{r['pass_s']:.2f} s CPU; {r['matrices']:,} matrices, {r['links'] / 1e6:.1f} M "
                  f"links: {r['matrices_s']:.2f} s mirrored, {r['reference_s']:.2f} s every link "
                  f"(equal)", flush=True)


if __name__ == "__main__":
    main()
