"""The default `gatesopt solve` on large files: this checkout against another one, the same run.

    python bench/large_solve.py --before /path/to/other/checkout FILE [FILE ...]
        [--repeat 2] [--write docs/BENCHMARKS.md]

Per file and checkout: one warm-up run (numba compiles a checkout's kernels on its first run),
then ``--repeat`` runs of ``python -m gatesopt solve FILE -o OUT`` (defaults) in a fresh process
each, alternating the two checkouts; the fastest wall time of each, its stage times (the report's
"time spent" line), the ratio after / before, and whether both wrote the same bytes.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _markdown import replace_section  # bench/_markdown.py

ROOT = Path(__file__).resolve().parents[1]
SECTION = "Default solve on large files: against the previous checkout"


def run_once(checkout: Path, path: str, out: Path) -> tuple[float, str]:
    """(wall s, the report's "time spent" line) of one solve in a fresh process."""
    if out.exists():
        out.unlink()
    env = dict(os.environ, PYTHONPATH=str(checkout))
    t = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "gatesopt", "solve", path, "-o", str(out)],
                       cwd=checkout, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if p.returncode != 0:
        raise SystemExit(f"{checkout}: solve {path} failed:\n{p.stderr[-2000:]}")
    m = re.search(r"^time spent\s+(.*)$", p.stdout, re.M)
    return wall, m.group(1).strip() if m else ""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="+")
    ap.add_argument("--before", required=True, help="the other checkout (a git worktree)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--write", help="replace this script's section of a markdown file")
    a = ap.parse_args()
    sides = {"before": Path(a.before).resolve(), "after": ROOT}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for f in a.files:
            outs = {k: Path(tmp) / f"{k}.gcode" for k in sides}
            for k, co in sides.items():          # warm-up: compile each checkout's kernels
                run_once(co, f, outs[k])
            best = {k: (float("inf"), "") for k in sides}
            for _ in range(a.repeat):
                for k, co in sides.items():
                    got = run_once(co, f, outs[k])
                    best[k] = min(best[k], got)
            same = outs["before"].read_bytes() == outs["after"].read_bytes()
            size = os.path.getsize(f) / 1e6
            rows.append((Path(f).name, size, best["before"], best["after"], same))
            print(f"{Path(f).name}: {best['before'][0]:.1f} -> {best['after'][0]:.1f} s "
                  f"({best['after'][0] / best['before'][0]:.2f}x), same output: {same}", flush=True)
    load = os.getloadavg()[0]
    lines = [f"## {SECTION}", "", "```", f"python bench/large_solve.py --before <checkout> {' '.join(a.files)} "
             f"--repeat {a.repeat}", "```", "",
             f"Fastest of {a.repeat} runs each (after one warm-up run), one process at a time, "
             f"load (1 min) at the end {load:.1f}.", "",
             "| file | MB | wall before s | wall after s | after / before | same output | time spent before | time spent after |",
             "|---|---:|---:|---:|---:|---|---|---|"]
    for name, mb, (wb, sb), (wa, sa), same in rows:
        lines.append(f"| {name} | {mb:.1f} | {wb:.1f} | {wa:.1f} | {wa / wb:.2f} | "
                     f"{'yes' if same else 'NO'} | {sb} | {sa} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if a.write:
        replace_section(Path(a.write), text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
