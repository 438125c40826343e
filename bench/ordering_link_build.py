"""What passing a file's groups and making their time-objective link matrices cost (issue 36,
proof rate; docs/BENCHMARKS.md, "Link-cost build"). CPU seconds (``time.process_time``), so a
loaded machine inflates them less than wall time.

    python bench/ordering_link_build.py FILE [FILE ...] [--modes safe,free]
    python bench/ordering_link_build.py --before /path/to/other/checkout FILE [...] [--write]


Per file and mode: ``pass``: every group built from where the slicer's order of the one before
ends and its slicer's order priced, as ``layers.solve`` passes a group the budget leaves
unsearched (best of 2); ``matrices``: every re-orderable group's link matrix on top
(``cost._dense``, each same-height link and its mirror priced once); ``reference``: the same
matrices with every link priced itself (``mirror=False``), checked equal (bit for bit where
the mirror is unjoined, within 1e-9 ms where it is joined: Klipper, ``cost._mirrorable``).

``--before``: the same measure in another checkout (a git worktree, its own process, its kernels
compiled or loaded by a first untimed pass), both sides run twice alternately, the best of each
kept: matrices CPU seconds before and after, their ratio, and whether every matrix is the same bit
for bit (a digest of all of them); ``--write`` puts the table into docs/BENCHMARKS.md ("Link-cost
build against the previous checkout").
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: the checkout measured: this one, or the one a ``--before`` run hands its worker process
CHECKOUT = Path(os.environ.get("GATESOPT_BENCH_CHECKOUT", ROOT))
sys.path.insert(0, str(CHECKOUT))
INSTANCES = ROOT.parent / "shared" / "instances"
SECTION = "Link-cost build against the previous checkout"


def measure(path: Path, mode: str, check: bool = True) -> dict:
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
    digest = hashlib.sha1()
    for g, grp, arc in mats:
        digest.update(np.ascontiguousarray(arc).tobytes())
    if not check:
        return {"file": path.name, "mode": mode, "matrices": len(mats),
                "links": sum(arc.size for _, _, arc in mats), "matrices_s": made_s - pass_s,
                "digest": digest.hexdigest()}
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


def _side(checkout: Path, path: Path, mode: str) -> dict:
    """``measure`` (without the reference matrices) in ``checkout``, in a process of its own."""
    env = dict(os.environ, GATESOPT_BENCH_CHECKOUT=str(checkout), PYTHONPATH=str(checkout))
    p = subprocess.run([sys.executable, __file__, "--worker", str(path), "--modes", mode],
                       env=env, capture_output=True, text=True, check=True)
    return json.loads(p.stdout.strip().splitlines()[-1])


def compare(args) -> None:
    """``--before``: this checkout against another, alternately, best of ``--repeat``."""
    sides = {"before": Path(args.before).resolve(), "after": CHECKOUT}
    rows = []
    for name in args.files:
        path = Path(name) if Path(name).exists() else INSTANCES / name
        for mode in args.modes.split(","):
            for side in sides.values():         # kernels compiled or loaded, untimed
                _side(side, path, mode)
            best: dict = {}
            for _ in range(args.repeat):
                for key, side in sides.items():
                    r = _side(side, path, mode)
                    if key not in best or r["matrices_s"] < best[key]["matrices_s"]:
                        best[key] = r
            b, a = best["before"], best["after"]
            same = b["digest"] == a["digest"]
            rows.append((path.name, mode, a["matrices"], a["links"], b["matrices_s"],
                         a["matrices_s"], same))
            print(f"{path.name} {mode}: {a['matrices']:,} matrices, {a['links'] / 1e6:.1f} M links: "
                  f"{b['matrices_s']:.2f} -> {a['matrices_s']:.2f} s CPU "
                  f"({a['matrices_s'] / b['matrices_s']:.2f}x), same matrices: {same}", flush=True)
    lines = [f"## {SECTION}", "", "```",
             f"python bench/ordering_link_build.py --before <checkout> {' '.join(args.files)}"
             f" --modes {args.modes} --repeat {args.repeat}", "```", "",
             "CPU seconds of making every re-orderable group's time-objective link matrix "
             "(`cost._dense`), best of the alternating runs; same: every matrix equal bit for bit.",
             "", "| file | mode | matrices | links (M) | before s | after s | after / before | same |",
             "|---|---|---:|---:|---:|---:|---:|---|"]
    for f, mode, n, links, b, a, same in rows:
        lines.append(f"| {f} | {mode} | {n:,} | {links / 1e6:.1f} | {b:.2f} | {a:.2f} | "
                     f"{a / b:.2f} | {'yes' if same else 'NO'} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.write:
        sys.path.insert(0, str(ROOT / "bench"))
        from _markdown import replace_section
        replace_section(ROOT / "docs" / "BENCHMARKS.md", text)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="+")
    ap.add_argument("--modes", default="safe,free")
    ap.add_argument("--before", help="another checkout to compare with (a git worktree)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--write", action="store_true", help="write the --before table into docs/BENCHMARKS.md")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        print(json.dumps(measure(Path(args.files[0]), args.modes, check=False)))
        return
    if args.before:
        compare(args)
        return
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
