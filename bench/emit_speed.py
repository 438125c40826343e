"""Curve-ordering emit speed against a peer in the same run: the parse of the text it writes.

On the ``--files`` largest instances of ../shared/instances (by line count), in each of
``--modes``: the greedy order (``solve(problem, "greedy")``, ``budget_s=3`` above 100,000 lines:
its budget is in work units, so every run orders the same way) and the slicer's own order
(``rewrite.guard.keep_layers`` of every layer), CPU seconds (``time.process_time``: the machine
is shared), best of ``--repeat``, of

- ``gatesopt.parse`` of the emitted text (the peer: the same lines, read instead of written),
- ``ordering.emit`` fresh (what the time guard's first emit of a run pays: the per-program lists
  made too),
- ``ordering.emit`` with the per-program part of the memo kept (``memo`` holding only what every
  emit of the program shares: the guard's later emits, before their per-layer reuse),

and the ratios emit / parse. Old against new: export the old version and run this script with
``--code DIR`` (its ``gatesopt`` imported instead of this checkout's), back to back.

    python bench/emit_speed.py
    python bench/emit_speed.py --code /tmp/main_export     # git archive main | tar -x -C /tmp/main_export
    python bench/emit_speed.py --write                     # replace "## Emit speed" in docs/BENCHMARKS.md
"""
from __future__ import annotations

import argparse
import csv
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "instances"
SECTION = "## Emit speed"


def best_cpu(fn, repeat: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t)
    return best, out


def largest(n: int) -> list[Path]:
    with open(SHARED / "MANIFEST.tsv", newline="") as f:
        rows = list(csv.DictReader(f, delimiter="\t"))
    rows.sort(key=lambda r: -int(r["lines"]))
    return [SHARED / r["file"] for r in rows[:n]]


def measure(path: Path, mode: str, repeat: int) -> list[dict]:
    import numpy as np

    import gatesopt
    from gatesopt.ordering import OrderingOptions, build, emit, solve
    from gatesopt.rewrite.guard import keep_layers
    prog = gatesopt.parse(path)
    prob = build(prog, OrderingOptions(mode=mode))
    greedy = solve(prob, "greedy", budget_s=3 if prog.n_lines > 100_000 else None)
    n_layers = int(prob.program_problem.curve_layer.max()) + 1
    rows = []
    for name, sol in (("greedy", greedy), ("slicer", keep_layers(prob, greedy, np.arange(n_layers)))):
        t_fresh, text = best_cpu(lambda: emit(prog, prob, sol), repeat)
        memo: dict = {}
        emit(prog, prob, sol, memo)
        shared = {k: v for k, v in memo.items() if isinstance(k, str)}   # the per-program part
        t_kept, again = best_cpu(lambda: emit(prog, prob, sol, dict(shared)), repeat)
        t_parse, _ = best_cpu(lambda: gatesopt.parse(text), repeat)
        rows.append({"file": path.name, "lines": prog.n_lines, "mode": mode, "order": name,
                     "parse_s": t_parse, "fresh_s": t_fresh, "kept_s": t_kept,
                     "same": again == text})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", type=int, default=4, help="how many of the largest instances")
    ap.add_argument("--modes", default="safe,free")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--code", help="a checkout whose gatesopt to time (default: this one)")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    sys.path.insert(0, str(Path(args.code).resolve() if args.code else ROOT))
    import gatesopt
    if not SHARED.is_dir():
        sys.exit(f"bench/emit_speed.py: {SHARED} not found")
    rows = []
    for path in largest(args.files):
        for mode in args.modes.split(","):
            for r in measure(path, mode, args.repeat):
                rows.append(r)
                print(f"{r['file']} {mode} {r['order']}: {r['lines']:,} lines, parse {r['parse_s']:.3f} s, "
                      f"emit {r['fresh_s']:.3f} s ({r['fresh_s'] / r['parse_s']:.1f}x parse), "
                      f"per-program part kept {r['kept_s']:.3f} s ({r['kept_s'] / r['parse_s']:.1f}x), "
                      f"same text {r['same']}", flush=True)
    cmd = "python bench/emit_speed.py" + "".join(f" {a}" for a in sys.argv[1:] if a != "--write")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    lines = [SECTION, "",
             f"Command: `{cmd}` (code: `{os.path.dirname(os.path.dirname(gatesopt.__file__))}`; "
             f"{platform.processor() or platform.machine()}, {time.strftime('%Y-%m-%d')}, "
             f"load {load:.1f} at the end on 2 cores; CPU seconds, best of {args.repeat}). "
             "Peer: the parse of the emitted text. Fresh: the time guard's first emit (the "
             "per-program lists made too); kept: with the per-program part of the memo, as its "
             "later emits (before their per-layer reuse). Greedy order (budget 3 s of work above "
             "100,000 lines) and the slicer's own order.",
             "", "| file | lines | mode | order | parse s | emit fresh s | fresh / parse | "
             "emit kept s | kept / parse | same text |",
             "|---|---:|---|---|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        lines.append(f"| {r['file']} | {r['lines']:,} | {r['mode']} | {r['order']} | "
                     f"{r['parse_s']:.3f} | {r['fresh_s']:.3f} | {r['fresh_s'] / r['parse_s']:.1f} | "
                     f"{r['kept_s']:.3f} | {r['kept_s'] / r['parse_s']:.1f} | {r['same']} |")
    text = "\n".join(lines) + "\n"
    print()
    print(text)
    if args.write:
        sys.path.insert(0, str(ROOT / "bench"))
        from _markdown import replace_section
        replace_section(ROOT / "docs" / "BENCHMARKS.md", text)
    if not all(r["same"] for r in rows):
        sys.exit("bench/emit_speed.py: the memo changed the text")


if __name__ == "__main__":
    main()
