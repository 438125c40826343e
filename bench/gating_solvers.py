"""Gating solvers: dp against the parser on the largest instance, and milp with budgets.

On ../shared/instances/prusa25_xend_honey25_acp.gcode.gz (decompressed to a temp dir first, as
bench/parse_profile.py does), best of ``--repeat`` runs after a warm-up:

* parse (``gatesopt.parse``), ``gating.build`` with ``--rotate auto`` and ``none``, ``dp`` solve;
  issue #3 target: dp within 2x the parse time;
* ``milp`` and ``cpsat`` (on ``--cpsat-files``) with budgets (Marlin and Klipper cost models, 1 % added time and/or 5 %
  added lines), and Marlin without a budget (its shared stalls couple the gaps), on
  ``--budget-files``, one run each with ``--time-limit``; issue #3 target: proven (gap <= 0.1 %)
  within 60 s per file.

    python bench/gating_solvers.py                 # print the tables
    python bench/gating_solvers.py --write         # replace "## Gating solvers" in docs/BENCHMARKS.md
"""
from __future__ import annotations

import argparse
import gzip
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SHARED = ROOT.parent / "shared" / "instances"
SECTION = "## Gating solvers"
LARGEST = "prusa25_xend_honey25_acp.gcode.gz"
BUDGET_FILES = ("real_slic3r131_stars.gcode", "prusa25_star_rect15_m82.gcode.gz", LARGEST)

import gatesopt  # noqa: E402
from gatesopt.gating import GatingOptions, build, solve  # noqa: E402


def decompressed(name: str, tmp: Path) -> Path:
    src = SHARED / name
    if name.endswith(".gz"):
        dst = tmp / name[:-3]
        with gzip.open(src, "rb") as f, open(dst, "wb") as g:
            shutil.copyfileobj(f, g)
        return dst
    return src


def best_of(fn, repeat):
    fn()                                    # warm-up (numba cache, imports)
    times = []
    out = None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def speed(tmp: Path, repeat: int) -> list[str]:
    path = decompressed(LARGEST, tmp)
    t_parse, program = best_of(lambda: gatesopt.parse(path), repeat)
    rows = []
    for rotate in ("none", "auto"):
        opts = GatingOptions(rotate=rotate)
        t_build, problem = best_of(lambda: build(program, opts), repeat)
        t_dp, sol = best_of(lambda: solve(problem, "dp"), repeat)
        t_gr, gsol = best_of(lambda: solve(problem, "greedy"), repeat)
        rows.append(f"| {rotate} | {program.n_lines:,} | {problem.n_angles} | {problem.n_idle_intervals:,} | "
                    f"{t_parse:.3f} | {t_build:.3f} | {t_dp:.3f} | {t_build + t_dp:.3f} | "
                    f"{(t_build + t_dp) / t_parse:.1f}x | {t_dp / t_parse:.1f}x | {t_gr:.3f} | "
                    f"{sol.saving_pct:.2f} % @ {sol.rotation_deg:.3f}° | {gsol.saving_pct:.2f} % @ {gsol.rotation_deg:.0f}° |")
        print(rows[-1], flush=True)
    return rows


def budgets(tmp: Path, files, cpsat_files, time_limit: float, mip_gap: float) -> list[str]:
    cases = [("marlin", dict(max_added_time_pct=1.0)),
             ("marlin", dict(max_added_time_pct=1.0, max_added_lines_pct=5.0)),
             ("klipper", dict(max_added_time_pct=1.0)),
             ("3dgates", dict(max_added_lines_pct=5.0)),
             # no budget, but Marlin's shared M18 stalls couple the gaps: dp is a heuristic here,
             # and before the share bound (formulations/gating.md §3) milp could not bound it on
             # large files
             ("marlin", dict())]
    rows = []
    for name in files:
        if not (SHARED / name).exists():
            continue
        program = gatesopt.parse(decompressed(name, tmp))
        for fw, budget in cases:
            opts = GatingOptions.for_firmware(fw, mip_rel_gap=mip_gap, **budget)
            t = time.perf_counter()
            problem = build(program, opts)
            t_build = time.perf_counter() - t
            d = solve(problem, "dp")
            for f in ("milp", "cpsat") if name in cpsat_files else ("milp",):
                s = solve(problem, f, time_limit_s=time_limit)
                b = ", ".join(f"{k.split('_')[2]} {v:g} %" for k, v in budget.items()) or "none"
                rows.append(f"| {name.replace('.gz', '')} | {fw} | {b} | {f} | {problem.n_idle_intervals:,} | {t_build:.2f} | "
                            f"{s.solve_s:.2f} | {s.status} | {100 * s.gap:.4f} % | {s.saving_pct:.3f} % | "
                            f"{d.saving_pct:.3f} % | {s.lines_added:,} | {s.added_time_s:.2f} |")
                print(rows[-1], flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--time-limit", type=float, default=60.0)
    ap.add_argument("--mip-gap", type=float, default=1e-3, help="relative gap at which milp/cpsat stop (0.1 %%)")
    ap.add_argument("--budget-files", nargs="*", default=list(BUDGET_FILES))
    ap.add_argument("--cpsat-files", nargs="*", default=list(BUDGET_FILES),
                    help="files on which cpsat runs too")
    ap.add_argument("--no-budgets", action="store_true")
    ap.add_argument("--write", action="store_true", help=f"replace the '{SECTION}' section of docs/BENCHMARKS.md")
    args = ap.parse_args(argv)
    if not SHARED.exists():
        print(f"{SHARED} not found", file=sys.stderr)
        return 2
    cmd = "python bench/gating_solvers.py " + " ".join(a for a in (argv or sys.argv[1:]))
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        sp = speed(tmp, args.repeat)
        bu = [] if args.no_budgets else budgets(tmp, args.budget_files, args.cpsat_files, args.time_limit, args.mip_gap)
    lines = [SECTION, "", "Command (from the repository root, with ../shared/instances beside it):", "",
             "```", cmd.strip(), "```", "",
             f"Machine: {platform.machine()}, Python {platform.python_version()}, "
             f"{time.strftime('%Y-%m-%d')}; 2 cores shared with other jobs, so times vary run to run. "
             f"Best of {args.repeat} after a warm-up; the file decompressed to a temp dir first. "
             "build = `gating.build` (energy coefficients, rotation candidates, gaps for the candidates the bound keeps); "
             "dp = `solve(problem, 'dp')` including the re-scoring of its solution with the energy model. "
             "Paper profile, 3dgates firmware, motors X Y.", "",
             "| rotate | lines | angles | gaps | parse s | build s | dp s | build+dp s | (build+dp)/parse | dp/parse | greedy s | dp saving | greedy saving |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|", *sp, "",
             "Target (issue #3): dp within 2x the parse time. Read the dp/parse column for the dp "
             "solve itself; building the problem (energy coefficients, rotation candidates, the gap "
             "table, all numba/numpy) is a separate step and is the larger cost, so build + dp is "
             "reported as well. Under rotate auto the build evaluates every candidate angle's step "
             "masks and bounds, and builds gaps only for the angles the bound cannot exclude "
             "(formulations/gating.md §6)."]
    if bu:
        lines += ["", f"Budgeted problems, one run each, time limit {args.time_limit:g} s, rotate auto, "
                  f"solvers stop at a relative gap of {args.mip_gap:g} (status optimal = proven within it). "
                  "gap = (energy - bound) / energy as reported by the solver; dp = the dp's own answer "
                  "(budget-repaired, the warm start). Target (issue #3): milp proven (gap <= 0.1 %) within 60 s.", "",
                  "| file | firmware | budget | formulation | gaps | build s | solve s | status | gap | saving | dp saving | lines added | time added s |",
                  "|---|---|---|---|---:|---:|---:|---|---:|---:|---:|---:|---:|", *bu, "",
                  "solve s includes the dp warm start and the model build; cpsat runs with "
                  "options.num_workers = 2 (subsolvers max_lp + default_lp, formulations/gating.md §4)."]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.write:
        doc = ROOT / "docs" / "BENCHMARKS.md"
        old = doc.read_text() if doc.exists() else "# Benchmarks\n"
        start = old.find(SECTION + "\n")
        if start >= 0:
            end = old.find("\n## ", start + len(SECTION))
            new = old[:start] + text + (old[end + 1:] if end >= 0 else "")
        else:
            new = old.rstrip("\n") + "\n\n" + text
        doc.write_text(new)
    return 0


if __name__ == "__main__":
    sys.exit(main())
