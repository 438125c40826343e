"""The ordering verifier's per-layer sort (``verify.ordering._by_layer``): layer and row hash in
one uint64 key sorted once, against the two-key ``np.lexsort`` it replaced, on real files, in
one run (best of ``--repeat``, wall seconds on the same machine and hour).

    python bench/verify_sort.py [FILE ...] [--repeat 5] [--write]

Per file: the moves' keys as ``check`` makes them (``_move_keys``; the value columns
``_moves_keep`` adds are the key's first three columns again, as wide as its widest call), both
sorts of them, and ``_layers_differing`` of the file against itself with each (the same answer
required), and the whole ``check`` of the file against itself for scale.
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

from _markdown import publish  # bench/_markdown.py

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SHARED = ROOT.parent / "shared" / "instances"
SECTION = "## Verifier: the per-layer sort in one key"
DEFAULT_FILES = ["prusa25_xend_honey25_acp.gcode.gz", "cura413_bunny_cubic10_mk3.gcode.gz",
                 "prusa25_bunny_triangles15_lh01.gcode.gz", "cura413_xend_zigzag100.gcode.gz"]


def lexsort_by_layer(layer, q):
    """The sort before: by layer, then by the row's full 64-bit hash (two keys)."""
    from gatesopt.verify.ordering import _row_hash
    rows = np.column_stack([layer, q]).astype(np.int64, copy=False)
    return rows[np.lexsort((_row_hash(q), layer))]


def best(fn, repeat):
    out, t = None, np.inf
    for _ in range(repeat):
        w = time.perf_counter()
        out = fn()
        t = min(t, time.perf_counter() - w)
    return t, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", default=DEFAULT_FILES)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--write", action="store_true")
    a = ap.parse_args()
    import gatesopt
    import gatesopt.verify.ordering as v
    rows = []
    for name in a.files:
        prog = gatesopt.parse(SHARED / name if not Path(name).exists() else Path(name))
        ra, qa, _ = v._move_keys(prog, 1e-4)
        layer = prog.layer[ra]
        q = np.column_stack([qa, qa[:, :3]])
        t_new, s_new = best(lambda: v._by_layer(layer, q), a.repeat)
        t_old, s_old = best(lambda: lexsort_by_layer(layer, q), a.repeat)
        d_new = v._layers_differing(layer, q, layer[::-1].copy(), q[::-1].copy())
        orig = v._by_layer
        v._by_layer = lexsort_by_layer
        try:
            d_old = v._layers_differing(layer, q, layer[::-1].copy(), q[::-1].copy())
        finally:
            v._by_layer = orig
        if not np.array_equal(d_new, d_old) or len(d_new):
            sys.exit(f"{name}: the two sorts disagree or find a difference in the file itself")
        t_check, found = best(lambda: list(v.check(prog, prog)), 2)   # (the first loads kernels)
        rows.append((name, len(q), t_old, t_new, t_check, len(found)))
        print(f"{name}: {len(q):,} moves, lexsort {1e3 * t_old:.1f} ms, one key {1e3 * t_new:.1f} ms "
              f"({t_new / t_old:.2f}x), check {t_check:.2f} s", flush=True)
    cmd = "python bench/verify_sort.py " + " ".join(x for x in sys.argv[1:] if x != "--write")
    lines = [SECTION, "",
             f"Command: `{cmd}` ({platform.machine()}, {time.strftime('%Y-%m-%d')}, a shared "
             f"2-core machine; best of {a.repeat}, wall ms). *lexsort*: the sort before (layer, "
             "then the row's 64-bit hash, two keys); *one key*: `verify.ordering._by_layer` "
             "(layer and the hash's top `KEY_HASH_BITS` bits in one uint64); both give the same "
             "`_layers_differing` on the file against itself reversed (none). The verifier calls "
             "the sort 6 times per check (two files, three checks); *check*: one whole "
             "`verify.ordering.check` of the file against itself, best of 2 (the first loads numba kernels), for scale.", "",
             "| file | moves | lexsort ms | one key ms | ratio | x 6 saved per check ms | check s |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for name, n, t_old, t_new, t_check, _ in rows:
        lines.append(f"| {name} | {n:,} | {1e3 * t_old:.1f} | {1e3 * t_new:.1f} | "
                     f"{t_new / t_old:.2f} | {6e3 * (t_old - t_new):.0f} | {t_check:.2f} |")
    publish("\n".join(lines) + "\n", str(ROOT / "docs" / "BENCHMARKS.md") if a.write else None)


if __name__ == "__main__":
    main()
