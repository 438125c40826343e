"""Curve ordering priced as printed (issue 36, "Done when"): per file, safe and free mode, auto and
greedy, the default budget, the print time under the planner model and the criteria of the issue.

    python bench/ordering_as_printed.py all [--write docs/RESULTS.md]
    python bench/ordering_as_printed.py run [--files GLOB] [--extra DIR | --no-extra]
        [--extra-files GLOB] [--modes safe,free] [--formulations auto,greedy] [--budget 10]
        [--workers 1] [--out bench/ordering-as-printed.jsonl]
    python bench/ordering_as_printed.py report [--out ...] [--write docs/RESULTS.md]

``all``: the whole bench in one command -- a fresh jsonl (``--out``, emptied first) of every
corpus file and every fresh slice (``--extra``, default ../fresh: bench/fresh_slices.py's 40
real slicer outputs, the pin plates and object plates among them), both modes, auto and greedy,
then ``report`` into ``--write``: one table per set and mode, and the criteria lines per set.

``run`` appends one JSON line per (file, mode, formulation): ``rewrite.order.order_program`` (build
-> solve within the budget -> emit with the time guard -> re-parse -> verify), the whole run
counted from before the parse as ``gatesopt order --budget`` counts it. Besides the report's keys
it keeps the layers the time guard put back and how many groups proven optimal lay in them
(a "proven optimal group reverted"). ``--extra DIR`` (default ../fresh where it exists,
``--no-extra``: the corpus only) adds files from another folder (the fresh slices of
bench/fresh_slices.py) under ``--extra-files`` (default: the ``--files`` glob).

``report`` writes the section "## Curve ordering priced as printed" of docs/RESULTS.md: per file
and mode the print time before, after (auto) and greedy's, travel, layers kept slower of the
re-orderable layers, proven groups reverted, safe mode's islands moved, groups proven, verified;
then the criteria of issue 36 counted over the rows.

    python bench/ordering_as_printed.py objects --before BEFORE.jsonl --after AFTER.jsonl
        [--write docs/RESULTS.md]

``objects`` writes the section "## Labelled objects re-ordered as blocks": the files whose
layers hold runs of >= 3 labelled objects (``AFTER``'s rows), safe mode: the slicer's print
time, auto's and greedy's before (``BEFORE``: a run of the code where objects were barriers) and
after, travel, the objects' runs moved, and free mode's print time (``BEFORE``'s: free mode keeps
objects in place, as before).
"""
from __future__ import annotations

import argparse
import fnmatch
import json
import os
import sys
import time
from pathlib import Path

from _markdown import publish  # bench/_markdown.py

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
INSTANCES = ROOT.parent / "shared" / "instances"
#: bench/fresh_slices.py's real slicer outputs (manifest.tsv beside them)
FRESH = ROOT.parent / "fresh"
DEFAULT_OUT = ROOT / "bench" / "ordering-as-printed.jsonl"
HEADING = "## Curve ordering priced as printed"
#: issue 36: layers the time guard keeps because re-ordered they were slower, of re-orderable ones
KEPT_SLOWER_MAX_SHARE = 0.02
#: and the share of groups proven optimal under the budget
PROVEN_MIN_SHARE = 0.90
#: a print time counts as not longer up to this (s): the guard's own tolerance per layer
TIME_TOL_S = 1e-3


def _files(args) -> list[Path]:
    names = sorted(p for p in INSTANCES.iterdir()
                   if p.name.endswith((".gcode", ".gcode.gz")) and fnmatch.fnmatch(p.name, args.files))
    if args.extra and not args.no_extra:
        names += sorted(p for p in Path(args.extra).iterdir()
                        if p.name.endswith((".gcode", ".gcode.gz"))
                        and fnmatch.fnmatch(p.name, args.extra_files or args.files))
    return names


def _row(res, path: Path, form: str, parse_s: float, run_s: float) -> dict:
    from gatesopt.rewrite.order import KEPT_SLOWER
    s = dict(res.summary)
    kept = sorted(r["layer"] for r in s["per_layer"] if r.get("kept_why") == KEPT_SLOWER)
    problem, sol = res.problem, res.solution
    reorderable = problem.group_reorderable
    kept_set = set(kept)
    # reported proven optimal in a layer put back, and not printed as reported (the guard
    # reports a put-back layer's groups with the path printed: ``guard.put_back_answer``)
    from gatesopt.ordering.chain import entry_positions
    from gatesopt.verify.proofs import printed_as_answered
    first = entry_positions(problem, sol)
    reverted = sum(1 for g, gs in enumerate(sol.groups)
                   if reorderable[g] and gs.status == "optimal"
                   and int(problem.group_layer[g]) in kept_set
                   and not printed_as_answered(problem, sol, g, problem.group(g, problem.origin_xy),
                                               first))
    s.pop("per_layer", None)
    from gatesopt.verify.proofs import audit_proofs
    audited, audit_failed = audit_proofs(problem, sol)
    s.update(file=path.name, folder=path.parent.name, formulation=form, parse_s=parse_s,
             run_s=run_s, kept_slower_layers=kept, optimal_reverted=reverted,
             proofs_put_back=s.get("groups_proofs_put_back", 0),
             proofs_audited=audited, proofs_audit_failed=audit_failed,
             load_1min=os.getloadavg()[0])
    return s


def _warm_up(args) -> None:
    """Each formulation and mode once on a small project instance, no row written: the rows of
    one process then all run warm (modules imported, numba kernels loaded from their cache, the
    solver backends started). Without it the first row of the process paid those first-use costs
    inside its budget and the rows after it did not: auto, run first, reached fewer groups than
    greedy on the Cura bunny for that alone (18 of 1,070 in one run). A ``gatesopt order`` run
    pays them in its own process, alike for every formulation."""
    import gatesopt
    from gatesopt.ordering import OrderingOptions
    from gatesopt.rewrite.order import order_program
    prog = gatesopt.parse(ROOT / "instances" / "cyl_grid.gcode")
    for mode in args.modes.split(","):
        for form in args.formulations.split(","):
            order_program(prog, OrderingOptions(mode=mode), formulation=form,
                          time_limit_s=args.time_limit, budget_s=args.budget, workers=args.workers)


def run(args) -> None:
    import gatesopt
    from gatesopt.ordering import OrderingOptions
    from gatesopt.rewrite.budget import slowdown_factor
    from gatesopt.rewrite.order import order_program
    out = Path(args.out)
    _warm_up(args)
    for path in _files(args):
        t, cpu = time.perf_counter(), time.process_time()
        prog = gatesopt.parse(path)
        parse_s, parse_cpu_s = time.perf_counter() - t, time.process_time() - cpu
        for mode in args.modes.split(","):
            for form in args.formulations.split(","):
                # counted from before the parse, CPU too (the load measure ``order`` takes)
                t = time.perf_counter() - parse_s
                try:
                    res = order_program(prog, OrderingOptions(mode=mode), formulation=form,
                                        time_limit_s=args.time_limit, budget_s=args.budget,
                                        workers=args.workers, started_s=t,
                                        slow=slowdown_factor(t, time.process_time() - parse_cpu_s))
                except Exception as e:  # noqa: BLE001 -- a bench row says what failed
                    row = {"file": path.name, "folder": path.parent.name, "order_mode": mode,
                           "formulation": form, "error": f"{type(e).__name__}: {e}"}
                else:
                    row = _row(res, path, form, parse_s, time.perf_counter() - t)
                with open(out, "a") as f:
                    f.write(json.dumps(row, default=float) + "\n")
                if "error" in row:
                    print(f"{path.name} {mode} {form}: ERROR {row['error']}", flush=True)
                    continue
                print(f"{path.name} {mode} {form}: print {row['print_time_before_s']:.1f} -> "
                      f"{row['print_time_after_s']:.1f} s "
                      f"({row['print_time_change_pct']:+.2f} %), travel "
                      f"{row['travel_change_pct']:+.1f} %, kept slower "
                      f"{row['layers_kept_slower']}/{row['layers_reorderable']}, optimal "
                      f"{row['groups_optimal']}/{row['groups_reordered']}, blocks moved "
                      f"{row.get('block_segments_moved', 0)}/{row.get('block_segments', 0)}, objects "
                      f"moved {row.get('object_runs_moved', 0)}/{row.get('object_runs', 0)}, run "
                      f"{row['run_s']:.1f} s, verified {row['verified']}", flush=True)


def _load(path: Path) -> dict:
    rows = {}
    for line in path.read_text().splitlines():
        r = json.loads(line)
        for old in ("before_s", "after_s", "change_pct"):
            # rows written before the report's keys were renamed (one print-time figure: G3)
            if f"print_time_planner_{old}" in r:
                r[f"print_time_{old}"] = r.pop(f"print_time_planner_{old}")
        rows[(r["folder"], r["file"], r["order_mode"], r["formulation"])] = r  # the last run wins
    return rows


def _pct(a, b) -> str:
    return f"{100.0 * (a / b - 1.0):+.2f} %" if b else "n/a"


def changed_layers(r: dict) -> int:
    """Layers with something decided in them: a group of >= 2 curves, islands moved, or a
    one-curve group turned (those count as decided layers in the report; a layer the time guard
    put back changed first, so it is one of them)."""
    decided = (r["layers_optimal"] + r["layers_feasible"] + r["layers_fallback"]
               + r["layers_kept_slower"])
    return max(decided, r["layers_reorderable"])


def _table(rows: dict, folder: str, files: list, mode: str) -> tuple[list[str], dict]:
    lines = ["| file | print s before | auto after | greedy after | travel auto | travel greedy | "
             "kept slower / re-orderable layers | greedy layers | optimal reverted | groups optimal | "
             "worst gap | islands moved (runs, layers) | free mode: print, travel | run s | verified |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    tally = {"files": 0, "not_faster_than_before": [], "slower_than_greedy": [], "kept": 0,
             "reorderable": 0, "reverted": 0, "put_back": 0, "optimal": 0, "groups": 0, "unverified": [],
             "errors": [], "block_files": 0, "block_moved_files": 0, "audited": 0,
             "audit_failed": []}
    for name in files:
        a = rows.get((folder, name, mode, "auto"))
        g = rows.get((folder, name, mode, "greedy"))
        fr = rows.get((folder, name, "free", "auto"))
        if a is None:
            continue
        if "error" in a:
            tally["errors"].append(name)
            lines.append(f"| {name} | error: {a['error'][:80]} |" + " |" * 13)
            continue
        tally["files"] += 1
        b, after = a["print_time_before_s"], a["print_time_after_s"]
        gafter = g["print_time_after_s"] if g and "error" not in g else None
        if after > b + TIME_TOL_S:
            tally["not_faster_than_before"].append(name)
        if gafter is not None and after > gafter + TIME_TOL_S:
            tally["slower_than_greedy"].append(f"{name} (+{after - gafter:.2f} s)")
        tally["kept"] += a["layers_kept_slower"]
        tally["reorderable"] += changed_layers(a)
        tally["reverted"] += a["optimal_reverted"]
        tally["put_back"] += a.get("proofs_put_back", 0)
        tally["audited"] += a.get("proofs_audited", 0)
        if a.get("proofs_audit_failed"):
            tally["audit_failed"].append(f"{name} ({a['proofs_audit_failed']})")
        tally["optimal"] += a["groups_optimal"] + a.get("block_orders_optimal", 0)
        tally["groups"] += a["groups_reordered"] + a.get("block_segments", 0)
        if not a["verified"] or (g and not g.get("verified", False)):
            tally["unverified"].append(name)
        if a.get("block_segments"):
            tally["block_files"] += 1
            tally["block_moved_files"] += bool(a.get("block_segments_moved"))
        n_groups = a["groups_reordered"] + a.get("block_segments", 0)
        n_opt = a["groups_optimal"] + a.get("block_orders_optimal", 0)
        islands = (f"{a['block_segments_moved']}/{a['block_segments']}, {a['block_layers_moved']}"
                   if a.get("block_segments") else "-")
        free = (f"{fr['print_time_after_s']:,.1f} ({_pct(fr['print_time_after_s'], b)}), "
                f"{fr['travel_change_pct']:+.1f} %" if mode == "safe" and fr and "error" not in fr
                else "")
        tally.setdefault("loads", []).append(a.get("load_1min"))
        lines.append(
            f"| {name} | {b:,.1f} | {after:,.1f} ({_pct(after, b)}) | "
            + (f"{gafter:,.1f} ({_pct(gafter, b)})" if gafter is not None else "-") + " | "
            f"{a['travel_change_pct']:+.1f} % | "
            + (f"{g['travel_change_pct']:+.1f} %" if gafter is not None else "-") + " | "
            f"{a['layers_kept_slower']} / {changed_layers(a)} | {a.get('layers_greedy', '-')} | "
            f"{a['optimal_reverted']} | "
            f"{n_opt} / {n_groups} | {100 * a['worst_gap']:.2f} % | {islands} | {free} | {a['run_s']:.1f} | "
            f"{'yes' if a['verified'] else 'NO'}"
            + ("" if not g or g.get("verified", True) else " (greedy: NO)") + " |")
    return lines, tally


def _criteria(mode: str, t: dict) -> list[str]:
    share = t["kept"] / t["reorderable"] if t["reorderable"] else 0.0
    proven = t["optimal"] / t["groups"] if t["groups"] else 1.0

    def names(xs):
        return ", ".join(xs) if xs else "none"
    out = [f"- {mode} mode, {t['files']} files: print time after > before: "
           f"{len(t['not_faster_than_before'])} ({names(t['not_faster_than_before'])}); "
           f"after > greedy's: {len(t['slower_than_greedy'])} ({names(t['slower_than_greedy'])}); "
           f"layers kept slower {t['kept']:,} of {t['reorderable']:,} re-orderable = "
           f"{100 * share:.2f} % (target <= {100 * KEPT_SLOWER_MAX_SHARE:.0f} %: "
           f"{'met' if share <= KEPT_SLOWER_MAX_SHARE else 'NOT met'}); proven optimal groups "
           f"reverted: {t['reverted']} (proofs on the model's costs the planner overruled after "
           f"the repair pass, reported with the slicer's path printed: {t['put_back']}); "
           f"groups proven optimal {t['optimal']:,} of {t['groups']:,} = "
           f"{100 * proven:.1f} % (target >= {100 * PROVEN_MIN_SHARE:.0f} %: "
           f"{'met' if proven >= PROVEN_MIN_SHARE else 'NOT met'}); proofs audited against the "
           f"subset DP where it prints them ({t['audited']:,} groups): failed in "
           f"{names(t['audit_failed'])}; not verified: "
           f"{names(t['unverified'])}; errors: {names(t['errors'])}"]
    loads = [x for x in t.get("loads", []) if x is not None]
    if loads:
        out[-1] += f"; load average (1 min) over the auto runs {min(loads):.1f}-{max(loads):.1f}"
    if mode == "safe":
        out[-1] += (f"; files with runs of >= 3 islands: {t['block_files']}, islands re-ordered in "
                    f"{t['block_moved_files']}")
    return out


def report(args) -> None:
    rows = _load(Path(args.out))
    folders: dict = {}
    for (folder, name, _, _) in rows:
        folders.setdefault(folder, set()).add(name)
    cmd = args.command_line or "python bench/ordering_as_printed.py all --write docs/RESULTS.md"
    sec = [HEADING, "",
           "Command (from the repository root, one process, 2 cores shared with other jobs; `all` "
           "= `run` over the corpus and the fresh slices of ../fresh, both modes, auto and greedy, "
           "into a fresh jsonl, then `report`):", "",
           "```", cmd, "```", "",
           "Print time = the planner model (`planner.plan`: acceleration, junction speeds, the "
           "file's limits) from the first layer on, measured on the parsed input and the parsed, "
           "verified output; objective: time (the default). *auto after* / *greedy after*: the "
           "same run with `--formulation auto` / `greedy` (the block order of safe mode is "
           "chosen by auto in both). *kept slower*: layers the time guard put back because "
           "re-ordered they printed slower, of the layers with something decided (a group of >= 2 "
           "curves, islands moved, or a single curve printed from its other end). *optimal "
           "reverted*: groups reported proven optimal lying in such a layer, not printed as reported (a "
           "layer put back reports its groups with the slicer's path it prints, "
           "`guard.put_back_answer`: proven only where that path is an optimum itself). "
           "*groups optimal*: groups of "
           ">= 2 curves proven optimal, plus safe mode's block orders proven optimal, of all "
           "of them. *islands moved*: safe mode's runs of >= 3 islands whose order changed, of all "
           "such runs, and in how many layers. *free-mode print*: the same file in free mode "
           "(auto), print time against the slicer's, travel change. *greedy layers*: layers the "
           "time guard printed in the greedy order (auto's run: the exact solve left them "
           "unproven, or a proven order printed slower than greedy's under the planner model; "
           "their groups count as proven only where greedy proved them for the start they print "
           "from, `guard.same_entry_groups`; a solver's group printed from another start than it "
           "was proven from counts as not proven either). *run s*: parse to verified output.", ""]
    crit = []
    for folder in sorted(folders):
        files = sorted(folders[folder])
        crit.append(f"{folder} ({len(files)} files):")
        for mode in ("safe", "free"):
            lines, tally = _table(rows, folder, files, mode)
            if tally["files"] == 0 and not tally["errors"]:
                crit.append(f"- {mode} mode: no rows")
                continue
            sec += [f"### {folder}, {mode} mode", ""] + lines + [""]
            crit += _criteria(mode, tally)
    for missing, where in (("instances", INSTANCES), ("fresh", FRESH)):
        if missing not in folders and where.exists():
            crit.append(f"{missing}: not in this jsonl (run `all`, or `run` with its folder)")
    sec += ["### Issue 36 criteria, counted over the rows above", ""] + crit + [""]
    publish("\n".join(sec), args.write)


OBJECTS_HEADING = "## Labelled objects re-ordered as blocks"


def objects(args) -> None:
    """The section OBJECTS_HEADING (module docstring)."""
    before, after = _load(Path(args.before)), _load(Path(args.after))
    files = sorted({(f, n) for (f, n, m, _), r in after.items() if r.get("object_runs")})
    cmd = args.command_line or "bench/ordering_as_printed.py run ... --out AFTER.jsonl"
    sec = [OBJECTS_HEADING, "",
           "Commands (from the repository root, one process at nice 10, 2 cores shared with 6 "
           "other jobs; BEFORE: the same runs of the code before objects moved, where labels "
           "were barriers):", "", "```", cmd,
           "python bench/ordering_as_printed.py objects --before BEFORE.jsonl --after AFTER.jsonl "
           "--write docs/RESULTS.md", "```", "",
           "Files whose layers hold runs of >= 3 labelled objects (`; printing object`, M486, "
           "EXCLUDE_OBJECT, `;MESH:`), default budget 10 s, objective time. Print time: the "
           "planner model of the parsed, verified output, against the slicer's order (*slicer*). "
           "*objects moved*: runs of >= 3 objects whose order changed, of all such runs; the "
           "first object of each run stays first. *free mode*: BEFORE's free-mode run (free mode "
           "keeps objects in place; moving them there measured worse: plate__cura_mk3 -4.16 % -> "
           "-3.75 %, plate__prusa_mk3s -2.91 % -> -2.80 %). Safe mode, every row verified "
           "(`check_objects`: each object's extrusion inside its own labels, the label lines of "
           "each layer kept). Wall times here are under a load of ~14 on 2 cores.", "",
           "| file | slicer print s | auto before | auto after | greedy before | greedy after "
           "| travel auto before / after | objects moved | free mode (auto) | verified |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for folder, name in files:
        for mode in ("safe",):
            a, g = after.get((folder, name, mode, "auto")), after.get((folder, name, mode, "greedy"))
            ab, gb = before.get((folder, name, mode, "auto")), before.get((folder, name, mode, "greedy"))
            fr = before.get((folder, name, "free", "auto"))
            if a is None or "error" in a:
                continue
            t0 = a["print_time_before_s"]

            def cell(r):
                if r is None or "error" in r:
                    return "-"
                return f"{r['print_time_after_s']:,.1f} ({_pct(r['print_time_after_s'], t0)})"
            tb = f"{ab['travel_change_pct']:+.1f} %" if ab and "error" not in ab else "-"
            ok = a["verified"] and (g is None or g.get("verified", False))
            sec.append(f"| {name} | {t0:,.1f} | {cell(ab)} | {cell(a)} | {cell(gb)} | {cell(g)} | "
                       f"{tb} / {a['travel_change_pct']:+.1f} % | "
                       f"{a.get('object_runs_moved', 0)}/{a.get('object_runs', 0)} | {cell(fr)} | "
                       f"{'yes' if ok else 'NO'} |")
    publish("\n".join(sec + [""]), args.write)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--files", default="*")
    r.add_argument("--extra", default=str(FRESH) if FRESH.exists() else None)
    r.add_argument("--no-extra", action="store_true", help="the corpus only")
    r.add_argument("--extra-files", default=None, help="default: the --files glob")
    r.add_argument("--modes", default="safe,free")
    r.add_argument("--formulations", default="auto,greedy")
    r.add_argument("--time-limit", type=float, default=2.0)
    r.add_argument("--budget", type=float, default=10.0)
    r.add_argument("--workers", type=int, default=1)
    r.add_argument("--out", default=str(DEFAULT_OUT))
    p = sub.add_parser("report")
    p.add_argument("--out", default=str(DEFAULT_OUT))
    p.add_argument("--write", default=None)
    p.add_argument("--command-line", default=None, help="the run command to print in the section")
    o = sub.add_parser("objects")
    o.add_argument("--before", required=True)
    o.add_argument("--after", required=True)
    o.add_argument("--write", default=None)
    o.add_argument("--command-line", default=None, help="the run commands to print in the section")
    a = sub.add_parser("all")
    a.add_argument("--extra", default=str(FRESH))
    a.add_argument("--budget", type=float, default=10.0)
    a.add_argument("--workers", type=int, default=1)
    a.add_argument("--out", default=str(DEFAULT_OUT))
    a.add_argument("--write", default=None)
    args = ap.parse_args()
    {"run": run, "report": report, "objects": objects, "all": run_all}[args.cmd](args)


def run_all(args) -> None:
    """``all`` (module docstring): corpus and fresh slices, both modes, auto and greedy, into a
    fresh ``--out``, then the report."""
    out = Path(args.out)
    if out.exists():
        out.unlink()
    run(argparse.Namespace(files="*", extra=args.extra, no_extra=False, extra_files="*",
                           modes="safe,free", formulations="auto,greedy", time_limit=2.0,
                           budget=args.budget, workers=args.workers, out=str(out)))
    cmd = ("python bench/ordering_as_printed.py all"
           + (f" --workers {args.workers}" if args.workers != 1 else "")
           + (f" --budget {args.budget:g}" if args.budget != 10.0 else "")
           + (f" --write {args.write}" if args.write else ""))
    report(argparse.Namespace(out=str(out), write=args.write, command_line=cmd))


if __name__ == "__main__":
    main()
