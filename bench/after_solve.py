"""The curve ordering's work after the solve -- the time guard (its emits, re-parses and planner
runs), the verifier (``verify.ordering.check``) and the report (``order_summary``) -- before and
after a change, in one run (issue 36: what it takes is what the solve does not get).

For each file and mode the parent process solves once (the greedy pass, then ``auto`` with the
greedy warm start under ``--solve-budget``) and pickles both solutions; then a child process per
code version -- ``--ref`` (default ``main``, exported with ``git archive`` to a temporary
directory: its numba kernels compile there on first use, not timed) and this checkout -- loads
them and times, best of ``--repeat``, CPU seconds (``time.process_time``: the machine is shared)
and wall seconds, each of: ``emit_guarded`` (two stages: greedy, then the exact answer; with the
time spent in ``emit``, ``parse`` and ``planner.plan`` inside it), ``check``, ``order_summary``
(as ``rewrite.order.order_program`` calls them in that version). Both versions must give the
same text, guard states and report figures; the table gives each stage's time and the ratio
after / before.

    python bench/after_solve.py run --files cura413_bunny_cubic10_mk3.gcode.gz prusa25_xend_honey25_acp.gcode.gz
    python bench/after_solve.py run ... --write     # replace the section in docs/BENCHMARKS.md
    python bench/after_solve.py run ... --may-differ  # a guard change: print times compared
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import pickle
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "instances"
SECTION = "## Curve ordering: the work after the solve, before and after"
STAGES = ("guard", "emit", "parse", "plan", "check", "summary")
#: with --may-differ, the guarded print may not take longer than before by more than this (s)
PRINT_TOL_S = 1e-3


def child(pkl: str, path: str, mode: str, repeat: int) -> dict:
    """Runs in the version under test (its ``gatesopt`` first on sys.path)."""
    import collections
    import inspect

    import numpy as np

    import gatesopt
    import gatesopt.rewrite.guard as guard
    from gatesopt.ordering import OrderingOptions
    from gatesopt.ordering.groups import build
    from gatesopt.rewrite.order import order_summary
    from gatesopt.verify.ordering import check

    inner = collections.defaultdict(float)

    def timed(name):
        fn = getattr(guard, name)

        def run(*a, **k):
            c = time.process_time()
            try:
                return fn(*a, **k)
            finally:
                inner[name] += time.process_time() - c
        setattr(guard, name, run)
    for name in ("emit", "parse", "plan", "planned_durations_s"):
        if hasattr(guard, name):
            timed(name)
    new_check = "original_layout" in inspect.signature(check).parameters
    new_summary = "planned_s" in inspect.signature(order_summary).parameters
    prog = gatesopt.parse(path)
    opts = OrderingOptions(mode=mode)
    problem = build(prog, opts)
    with open(pkl, "rb") as f:
        greedy, exact = pickle.load(f)

    def once():
        inner.clear()
        t = {}
        w, c = time.perf_counter(), time.process_time()
        gd = guard.emit_guarded(prog, problem, exact, True, greedy=greedy)
        t["guard"] = (time.process_time() - c, time.perf_counter() - w)
        w, c = time.perf_counter(), time.process_time()
        found = (check(prog, gd.output, problem.program_problem.layout) if new_check
                 else check(prog, gd.output))
        t["check"] = (time.process_time() - c, time.perf_counter() - w)
        w, c = time.perf_counter(), time.process_time()
        extra = {"planned_s": gd.planned_s} if new_summary else {}
        s = order_summary(prog, gd.output, problem, gd.solution, opts, gd.kept, found,
                          formulation="auto", time_limit_s=2.0, budget_s=10.0, solve_budget_s=1.0,
                          workers=1, wall_s=0.0, **extra)
        t["summary"] = (time.process_time() - c, time.perf_counter() - w)
        for name, v in inner.items():     # (the planner's entry point the guard calls: "plan")
            t["plan" if name == "planned_durations_s" else name] = (v, float("nan"))
        return gd, found, s, t

    best: dict = {}
    for _ in range(repeat):
        gd, found, s, t = once()
        for k, v in t.items():
            best[k] = min(best.get(k, (np.inf, np.inf)), v, key=lambda x: x[0])
    figs = {k: s[k] for k in sorted(s) if k.startswith(("print_time", "travel", "retractions"))}
    return {"lines": prog.n_lines, "curves": problem.n_curves, "times": best,
            "text": hashlib.sha256(gd.text.encode("utf-8", "surrogateescape")).hexdigest(),
            "kept": gd.kept.tolist(), "source": np.asarray(gd.source).tolist(), "figures": figs,
            "findings": [str(f) for f in found], "layers_greedy": gd.greedy_layers}


def solve_once(path: Path, mode: str, budget_s: float, out: Path) -> None:
    import gatesopt
    from gatesopt.ordering import OrderingOptions
    from gatesopt.ordering.groups import build
    from gatesopt.ordering.layers import solve, solve_greedy
    prog = gatesopt.parse(path)
    problem = build(prog, OrderingOptions(mode=mode))
    g = solve_greedy(problem, budget_s=budget_s)
    x = solve(problem, "auto", budget_s=budget_s, greedy=g)
    with open(out, "wb") as f:
        pickle.dump((g.solution, x), f)


def export(ref: str) -> Path:
    """``ref``'s gatesopt package in a directory of its own (kept between runs: its numba cache)."""
    sha = subprocess.run(["git", "rev-parse", ref], cwd=ROOT, capture_output=True, text=True,
                         check=True).stdout.strip()
    d = Path(tempfile.gettempdir()) / f"gatesopt-bench-{sha[:12]}"
    if not (d / "gatesopt").is_dir():
        d.mkdir(parents=True, exist_ok=True)
        tar = subprocess.run(["git", "archive", sha, "gatesopt"], cwd=ROOT, capture_output=True,
                             check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(d)], input=tar, check=True)
    return d


def run_child(src: Path, pkl: Path, path: Path, mode: str, repeat: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    code = (f"import sys, json; sys.path.insert(0, {str(src)!r}); sys.path.insert(1, {str(ROOT / 'bench')!r});"
            f"import after_solve as a; print(json.dumps(a.child({str(pkl)!r}, {str(path)!r}, "
            f"{mode!r}, {repeat})))")
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    if r.returncode:
        sys.exit(f"bench/after_solve.py: child in {src} failed:\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def cmd_run(a) -> None:
    before_src = export(a.ref)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in a.files:
            path = SHARED / name
            for mode in a.modes.split(","):
                pkl = Path(tmp) / f"{name}.{mode}.pkl"
                solve_once(path, mode, a.solve_budget, pkl)
                # warm both versions (numba kernels compile on a version's first run), then measure
                run_child(before_src, pkl, path, mode, 1)
                run_child(ROOT, pkl, path, mode, 1)
                b = run_child(before_src, pkl, path, mode, a.repeat)
                n = run_child(ROOT, pkl, path, mode, a.repeat)
                same = all(b[k] == n[k] for k in ("text", "kept", "source", "figures", "findings",
                                                  "layers_greedy"))
                rows.append({"file": name, "mode": mode, "lines": n["lines"], "curves": n["curves"],
                             "before": b["times"], "after": n["times"], "same": same,
                             "print_s": (b["figures"].get("print_time_after_s"),
                                         n["figures"].get("print_time_after_s")),
                             "findings": (len(b["findings"]), len(n["findings"]))})
                r = rows[-1]
                print(name, mode, "same" if same else "DIFFERENT",
                      {k: (round(r["before"][k][0], 3), round(r["after"][k][0], 3)) for k in STAGES},
                      flush=True)
    with open(a.out, "w") as f:
        json.dump({"ref": a.ref, "rows": rows, "argv": sys.argv[1:]}, f, indent=1)
    text = markdown(rows, a)
    print(text)
    if a.write:
        sys.path.insert(0, str(ROOT / "bench"))
        from _markdown import replace_section
        replace_section(ROOT / "docs" / "BENCHMARKS.md", text)
    if a.may_differ:
        # a guard that may pick other states: never a slower print, never a finding
        bad = [r for r in rows if r["findings"][1]
               or r["print_s"][1] > r["print_s"][0] + PRINT_TOL_S]
        if bad:
            sys.exit("bench/after_solve.py: slower or unverified with this checkout: "
                     + ", ".join(f"{r['file']} {r['mode']}" for r in bad))
    elif not all(r["same"] for r in rows):
        sys.exit("bench/after_solve.py: the two versions gave different outputs")


def markdown(rows, a) -> str:
    cmd = "python bench/after_solve.py " + " ".join(x for x in sys.argv[1:] if x != "--write")
    lines = [SECTION, "",
             f"Command: `{cmd}` ({platform.machine()}, {time.strftime('%Y-%m-%d')}, a shared 2-core "
             f"machine; best of {a.repeat}, CPU seconds). Before: `{a.ref}`; after: this checkout; "
             "the same pickled greedy and exact solutions (solved once, "
             f"{a.solve_budget:g} s budget each). guard: `rewrite.guard.emit_guarded` with the greedy "
             "stage (emit, parse, plan: its parts); check: `verify.ordering.check`; summary: "
             "`order_summary` (the report's print times and travel). Same: the text, guard states, "
             "report figures and findings are identical in both versions"
             + ("; where not (`--may-differ`: a change to which orders the guard weighs), the "
                "print time of the guarded output (planner model) before / after, never longer"
                if a.may_differ else "") + ".", "",
             "| file | mode | lines | " + " | ".join(f"{s} before / after s" for s in STAGES)
             + " | guard+check+summary before / after s | ratio | same |"
             + (" print s before / after |" if a.may_differ else ""),
             "|---|---|---:|" + "---:|" * len(STAGES) + "---:|---:|---|"
             + ("---:|" if a.may_differ else "")]
    for r in rows:
        b, n = r["before"], r["after"]
        tb = sum(b[k][0] for k in ("guard", "check", "summary"))
        tn = sum(n[k][0] for k in ("guard", "check", "summary"))
        cells = " | ".join(f"{b[k][0]:.2f} / {n[k][0]:.2f}" for k in STAGES)
        lines.append(f"| {r['file']} | {r['mode']} | {r['lines']:,} | {cells} | {tb:.2f} / {tn:.2f} | "
                     f"{tn / tb:.2f} | {r['same']} |"
                     + (f" {r['print_s'][0]:,.2f} / {r['print_s'][1]:,.2f} |" if a.may_differ else ""))
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--files", nargs="+", default=["cura413_bunny_cubic10_mk3.gcode.gz"])
    r.add_argument("--modes", default="safe,free")
    r.add_argument("--ref", default="main", help="the version before (a git ref)")
    r.add_argument("--repeat", type=int, default=3)
    r.add_argument("--solve-budget", type=float, default=6.0)
    r.add_argument("--out", default=str(Path(tempfile.gettempdir()) / "after_solve.json"))
    r.add_argument("--write", action="store_true")
    r.add_argument("--may-differ", action="store_true",
                   help="the change may make the guard pick other orders: report the print "
                        "times instead of requiring the same text (never slower, never a finding)")
    a = ap.parse_args()
    if not SHARED.is_dir():
        sys.exit(f"bench/after_solve.py: {SHARED} not found")
    cmd_run(a)


if __name__ == "__main__":
    main()
