"""Wall time of `gatesopt solve IN -o OUT` with every default, one file at a time (issue 37: "within
10 s on 2 cores").

    python bench/default_solve.py run [--files GLOB ...] [--over S] [--out bench/default-solve.jsonl] [-- EXTRA ARGS]
    python bench/default_solve.py report [--out ...] [--write docs/BENCHMARKS.md]

``run`` starts the installed command (``python -m gatesopt solve IN -o OUT --json J``) in a fresh
process per file, one after the other, and appends one JSON line per file: the wall time measured
outside the process (interpreter start-up and imports included, what a user waits for), its ratio
to the 10 s limit, the CPU seconds of the process and its children (the ordering's helper process
included: less sensitive to other work on the machine than the wall time, though the CPU time of
a loaded machine grows too), the 1-minute load average before and after (other work on the
machine inflates every figure: the report says so), and the run's own report (``times``: read,
ordering, gating, verify, report; saving, status). ``--over S`` runs again only the files whose
latest wall time was over S seconds (e.g. after a run on a loaded machine). ``report`` turns the
latest line of each file into the section "## Default solve: wall time" of docs/BENCHMARKS.md.
Default files: every file of ../shared/instances and of ../fresh (fresh slicer output the project
had not seen, bench/fresh_slices.py).
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _markdown import publish  # bench/_markdown.py

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_GLOBS = (str(ROOT.parent / "shared" / "instances" / "*.gcode*"), str(ROOT.parent / "fresh" / "*.gcode"))
DEFAULT_OUT = ROOT / "bench" / "default-solve.jsonl"
TARGET_S = 10.0
SECTION = "## Default solve: wall time"


def _load() -> float:
    return os.getloadavg()[0]


def _commit() -> str:
    """The checkout's commit (with "+changes" where the work tree differs from it)."""
    def git(*a):
        return subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    return git("rev-parse", "--short", "HEAD") + ("+changes" if git("status", "--porcelain", "--untracked-files=no") else "")


def run(files, out: Path, extra: list[str]) -> None:
    commit = _commit()
    with tempfile.TemporaryDirectory(prefix="gatesopt-bench-") as tmp:
        for f in files:
            name = Path(f).name
            o, j = Path(tmp) / "out.gcode", Path(tmp) / "out.json"
            for p in (o, j):
                if p.exists():
                    p.unlink()
            load0 = _load()
            cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            t = time.perf_counter()
            r = subprocess.run([sys.executable, "-m", "gatesopt", "solve", f, "-o", str(o), "--json", str(j)]
                               + extra, capture_output=True, text=True)
            wall = time.perf_counter() - t
            cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
            row = {"file": name, "rc": r.returncode, "wall_s": wall, "ratio": wall / TARGET_S,
                   "cpu_s": cpu, "load_before": load0,
                   "load_after": _load(), "args": extra, "commit": commit, "date": time.strftime("%Y-%m-%d %H:%M")}
            if j.exists():
                s = json.loads(j.read_text())
                row.update({k: s.get(k) for k in ("verified", "saving_pct", "status", "stopped", "rotation_deg",
                                                  "print_time_change_pct", "travel_change_pct", "wall_s",
                                                  "solve_s", "times", "slowdown", "lines_before", "notes")})
                row["report_wall_s"] = s.get("wall_s")
                o = s.get("ordering") or {}
                # what the budget left the ordering's solve, and how many groups it had no time for
                row["order"] = {k: o.get(k) for k in ("solve_budget_s", "solve_s", "groups_reordered",
                                                      "groups_optimal", "groups_fallback",
                                                      "groups_out_of_time")}
                row["wall_s"] = wall
            else:
                row["error"] = (r.stderr or r.stdout).strip()[-300:]
            with open(out, "a") as fh:
                fh.write(json.dumps(row) + "\n")
            print(f"{name:45s} rc {r.returncode} wall {wall:6.2f} s ({wall / TARGET_S:.2f} of the limit) "
                  f"cpu {cpu:6.2f} s load {load0:.1f}"
                  + (f" saving {row.get('saving_pct', 0):.2f} %" if "saving_pct" in row else ""), flush=True)


def latest(out: Path) -> dict:
    """The latest row of each file in ``out``."""
    last = {}
    if out.exists():
        for line in out.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                last[r["file"]] = r
    return last


def _median(v):
    v = sorted(v)
    return v[len(v) // 2] if v else float("nan")


def report(out: Path) -> str:
    rows = sorted(latest(out).values(), key=lambda r: -(r.get("lines_before") or 0))
    walls = [r["wall_s"] for r in rows]
    over = [r for r in rows if r["wall_s"] > TARGET_S]
    loads = [r["load_before"] for r in rows]
    quiet = [r for r in rows if r["load_before"] <= 2.5]
    args = " ".join(rows[0].get("args") or []) if rows else ""
    dates = sorted(r["date"] for r in rows)
    commits = sorted({r.get("commit", "?") for r in rows})
    md = [SECTION, "",
          f"Command: `python bench/default_solve.py run{' -- ' + args if args else ''}` (then `run --over 10` "
          "for the files over the limit, at a quieter moment) and `python bench/default_solve.py report "
          "--write docs/BENCHMARKS.md`: `gatesopt solve IN -o OUT --json J` with every default, one file at a "
          f"time, in a fresh process ({platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, {dates[0] if dates else ''} to {dates[-1] if dates else ''} UTC, commit "
          f"{', '.join(commits)}), on "
          "every corpus file (../shared/instances) and fresh slice (../fresh). Wall: measured outside the "
          "process (start-up and imports included), and its ratio to the 10 s limit; CPU: user + system "
          "seconds of the process and its helper. Load: the 1-minute load average before each file: other "
          "helpers shared the 2 cores, and every wall time here is inflated by that load (a row at load 4 "
          "had about half the machine).",
          "",
          f"{len(rows)} files: {sum(1 for r in rows if r.get('rc') == 0 and r.get('verified'))} verified; wall "
          f"median {_median(walls):.2f} s, max {max(walls):.2f} s (ratio {max(walls) / TARGET_S:.2f}); over "
          f"{TARGET_S:g} s: {len(over)}"
          + (" (" + ", ".join(f"{r['file']} {r['wall_s']:.1f} s at load {r['load_before']:.1f}" for r in over) + ")"
             if over else "")
          + f"; load average {min(loads):.1f} to {max(loads):.1f} (median {_median(loads):.1f}); "
          + (f"{len(quiet)} files measured at load <= 2.5, their wall max {max(r['wall_s'] for r in quiet):.2f} s."
             if quiet else "no file measured at load <= 2.5 (the machine was never quiet).")
          + f" CPU seconds: median {_median([r.get('cpu_s', 0) for r in rows]):.2f}, max "
          f"{max(r.get('cpu_s', 0) for r in rows):.2f}.", "",
          "| file | lines | wall s | ratio | CPU s | load | slow x | read | ordering (solve) | solve budget, out of time | gating (solve) | rotate | verify | report | saving % | rot deg | print time % | travel % |",
          "|---|---:|---:|---:|---:|---:|---:|---:|---|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        t = r.get("times") or {}
        g = t.get("gating_build_s", 0) + t.get("gating_solve_s", 0) + t.get("rotate_s", 0) + t.get("emit_s", 0)
        head = (f"| {r['file']} | {r.get('lines_before') or 0:,} | {r['wall_s']:.2f} | {r['wall_s'] / TARGET_S:.2f} | "
                f"{r.get('cpu_s', float('nan')):.2f} | {r['load_before']:.1f} | {r.get('slowdown') or 1.0:.2f} | ")
        if r.get("rc") != 0:
            md.append(head + f"error: {r.get('error', '')[:80]} | | | | | | | | | | |")
            continue
        o = r.get("order") or {}
        ob = ("-" if o.get("solve_budget_s") is None else
              f"{o['solve_budget_s']:.2f} s, {o.get('groups_out_of_time') or 0} of {o.get('groups_reordered') or 0}")
        md.append(head + f"{t.get('read_s', 0):.2f} | {t.get('ordering_s', 0):.2f} ({t.get('ordering_solve_s', 0):.2f}) | "
                  f"{ob} | {g:.2f} ({t.get('gating_solve_s', 0):.2f}) | {t.get('rotate_s', 0):.2f} | "
                  f"{t.get('verify_s', 0):.2f} | {t.get('report_s', 0):.2f} | {r.get('saving_pct', 0):.2f} | "
                  f"{r.get('rotation_deg') or 0:g} | {r.get('print_time_change_pct') or 0:+.2f} | "
                  f"{r.get('travel_change_pct') or 0:+.1f} |")
    md += ["", "slow x: the run's own measure of the machine's load before its ordering (wall / CPU seconds "
           "so far, `rewrite.budget.slowdown_factor`): the stages after the ordering are estimated that many "
           "times slower, and the ordering gets that much less. Columns: seconds per stage from the run's own report (`--json` `times`): read = start-up, "
           "imports and reading the file; ordering = the curve ordering's build, solve and emit (its "
           "solve in brackets: it gets what the 10 s budget leaves after an estimate of the other stages, "
           "`rewrite/budget.py`); solve budget, out of time: what the budget left the ordering's solve "
           "(its groups' searches, and passing every group) and how many of its re-orderable groups it "
           "had no time for (they keep the slicer's order, status fallback: `ordering/runner.py`), '-' "
           "where the ordering was skipped (a note says why); gating = build, solve (both solves: the rotation search and the solve "
           "again on the rotated text), rotating the text and emitting; rotate = rendering and "
           "re-parsing the rotated text (part of gating); verify = parsing the output and every "
           "check; report = the print times (planner) and travel of both files. print time %: the "
           "planner model's; travel %: measured on the files."]
    return "\n".join(md)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--files", nargs="*", default=list(DEFAULT_GLOBS))
    r.add_argument("--out", default=str(DEFAULT_OUT))
    r.add_argument("--over", type=float, metavar="S",
                   help="only the files whose latest run in --out took more than S seconds")
    r.add_argument("extra", nargs=argparse.REMAINDER)
    p = sub.add_parser("report")
    p.add_argument("--out", default=str(DEFAULT_OUT))
    p.add_argument("--write", metavar="MD")
    a = ap.parse_args()
    if a.cmd == "run":
        files = sorted({f for g in a.files for f in glob.glob(g)})
        if a.over is not None:
            last = latest(Path(a.out))
            files = [f for f in files if Path(f).name in last and last[Path(f).name]["wall_s"] > a.over]
        extra = [x for x in a.extra if x != "--"]
        run(files, Path(a.out), extra)
        return 0
    publish(report(Path(a.out)), a.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
