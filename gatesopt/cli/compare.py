"""``gatesopt compare``: every gating (or, with ``--ordering``, curve-ordering) formulation on the
same files, side by side: one verified run each (nothing written), one table; the work is
``gatesopt.compare``."""
from __future__ import annotations

import math
import time

from .files import check_distinct, check_input, check_new_file, check_one_stdin, read_program, write_json
from .options import (add_gating_options, firmware_choice, gating_formulations, gating_options,
                      ordering_formulations, positive_s)
from .progress import default_workers

NAME = "compare"
HELP = "all gating (or --ordering: curve ordering) formulations side by side"
DESCRIPTION = ("Solve each file with every gating formulation (greedy always included) and print one "
               "table; outputs are verified, not written. With --ordering: every curve-ordering "
               "formulation instead, by travel.")


def add_arguments(c) -> None:
    c.add_argument("files", nargs="+", help="G-code files (one of them may be - for standard input)")
    c.add_argument("--formulations", default=None, metavar="LIST",
                   help="comma separated (default: all of the compared kind); greedy is always a row")
    c.add_argument("--ordering", action="store_true",
                   help="compare the curve ordering's formulations (greedy, tsp, cpsat, milp, auto) "
                        "by travel instead of gating's by energy")
    c.add_argument("--order-mode", choices=("safe", "free"), default="safe",
                   help="the curve ordering's mode, as `order --order-mode` (default safe)")
    c.add_argument("--move-seams", action="store_true",
                   help="the curve ordering: closed loops may start at another vertex")
    c.add_argument("--objective", choices=("time", "travel"), default="time",
                   help="what the curve ordering minimises: time (default), the travels' print time as emitted, retractions, z-hops and the slicer's own copied travels included; travel, their length (Fleming et al.)")
    c.add_argument("--no-order", action="store_true",
                   help="gating rows: gate the slicer's order (default: each row is the run `solve "
                        "--formulation F` makes, curve ordering included, within --budget)")
    c.add_argument("--budget", type=float, default=10.0, metavar="S",
                   help="gating rows: each run's whole-run budget, as `solve --budget` (default 10)")
    c.add_argument("--order-budget", type=float, default=10.0, metavar="S",
                   help="with --ordering: each formulation's run of a file, parse to verified output, "
                        "in about S seconds (default 10, as `order --budget`)")
    add_gating_options(c)
    c.add_argument("--plot", metavar="OUT.png", help="bar chart of the saving per formulation")
    c.add_argument("--json", metavar="OUT.json", help="write the rows as JSON")
    c.add_argument("--force", action="store_true", help="overwrite an existing plot or JSON file")


def run(args) -> int:
    from ..compare import gating_rows, ordering_rows
    known = ordering_formulations() if args.ordering else gating_formulations()
    forms = [f.strip() for f in (args.formulations or ",".join(known)).split(",") if f.strip()]
    check_one_stdin(args.files)
    for path in args.files:
        check_input(path)
    check_distinct({"--plot": args.plot, "--json": args.json})
    if args.ordering:
        positive_s(args.order_budget, "--order-budget")
    if args.plot:
        check_new_file(args.plot, args.files, args.force, png=True)
    if args.json:
        check_new_file(args.json, args.files, args.force)
    rows = []
    if args.ordering:
        from ..ordering import OrderingOptions
        order_options = OrderingOptions(mode=args.order_mode, move_seams=args.move_seams,
                                    objective=args.objective)
        for path in args.files:
            rows += ordering_rows(read_program(path), order_options, forms, known, args.order_budget,
                                  default_workers())
        print(format_compare_order(rows))
    else:
        positive_s(args.budget, "--budget")
        fields = gating_options(args)
        from ..ordering import OrderingOptions
        order_options = OrderingOptions(mode=args.order_mode, move_seams=args.move_seams,
                                        objective=args.objective)
        for path in args.files:
            t = time.perf_counter()
            program = read_program(path)
            read_s = time.perf_counter() - t
            choice = firmware_choice(args, program, **fields)   # per file: each names its printer
            print(f"{program.source}: firmware {choice.line}")
            if choice.options is None:
                # a row that says so (not an empty table): nothing to gate on this printer
                rows.append({"file": program.source, "formulation": "-", "status": "not gated",
                             "error": "no motor line for this printer; try --ordering"})
                continue
            # each row the run `gatesopt solve --formulation F` makes of the file (issue 37)
            rows += gating_rows(program, choice.options, forms, args.time_limit, order=not args.no_order,
                                budget_s=args.budget, order_options=order_options,
                                workers=default_workers(), choice=choice, read_s=read_s)
        print(format_compare(rows))
    if args.plot:
        plot_compare(rows, args.plot, ordering=args.ordering)
    if args.json:
        write_json(args.json, rows)
    bad = [r for r in rows if "verified" in r and not r["verified"]]
    return 1 if bad else 0


def format_compare(rows: list[dict]) -> str:
    head = (f"{'file':28s} {'formulation':11s} {'saving %':>9s} {'instr':>7s} {'size +%':>8s} "
            f"{'print +%':>8s} {'rot deg':>8s} {'status':>11s} {'gap':>9s} {'solve s':>8s} {'run s':>7s} "
            f"{'verified':>8s}")
    out = [head, "-" * len(head)]
    for r in rows:
        if "saving_pct" not in r:
            out.append(f"{r['file'][:28]:28s} {r['formulation']:11s} {'':>9s} {'':>7s} {'':>8s} {'':>8s} "
                       f"{'':>8s} {r['status']:>11s}   {r.get('error', '')[:60]}")
            continue
        gap = "n/a" if r["gap"] is None else f"{100 * r['gap']:.3f}%"
        status = str(r["status"]) + ("*" if r.get("stopped") else "")
        out.append(f"{r['file'][:28]:28s} {r['formulation']:11s} {r['saving_pct']:9.2f} "
                   f"{r['instruction_lines']:7d} {r['size_change_pct']:8.2f} {r['print_time_change_pct']:8.3f} "
                   f"{r['rotation_deg']:8.3f} {status:>11s} {gap:>9s} {r['solve_s']:8.3f} {r['wall_s']:7.2f} "
                   f"{'yes' if r['verified'] else 'NO':>8s}")
    if any("saving_pct" in r for r in rows):
        out.append("each row: the run `gatesopt solve --formulation F` makes (curve ordering included "
                   "unless --no-order); print +%: print time against the file as given, planner "
                   "model, what --max-added-time-pct bounds (status infeasible: a run over it or "
                   "over the line budget); solve s: every solve of the run "
                   "(ordering, rotation search, the solve again after rotating); run s: the whole run")
    for r in rows:
        if r.get("status") == "infeasible" and r.get("message"):
            # why (greedy, the paper's re-compiler, knows no budget): over the time budget on the
            # print +% column's planner time, or over the line budget
            out.append(f"infeasible: {r['file'][:28]} {r['formulation']}: {r['message']}")
    if any(r.get("stopped") for r in rows):
        out.append("*: stopped before its gap (" + ", ".join(sorted({str(r['stopped']) for r in rows
                                                                     if r.get("stopped")})) + ")")
    return "\n".join(out)


def format_compare_order(rows: list[dict]) -> str:
    head = (f"{'file':28s} {'formulation':11s} {'travel mm':>11s} {'travel %':>9s} {'print s':>10s} "
            f"{'time %':>7s} "
            f"{'optimal':>8s} {'feasible':>8s} {'fallback':>8s} {'worst gap':>9s} {'run s':>7s} {'verified':>8s}")
    out = [head, "-" * len(head)]
    for r in rows:
        if "travel_after_mm" not in r:
            out.append(f"{r['file'][:28]:28s} {r['formulation']:11s} {r['status']:>11s}   {r.get('error', '')[:60]}")
            continue
        gap = "n/a" if r["worst_gap"] is None else f"{100 * r['worst_gap']:.2f}%"
        out.append(f"{r['file'][:28]:28s} {r['formulation']:11s} {r['travel_after_mm']:11,.1f} "
                   f"{r['travel_change_pct']:9.2f} {r['print_time_after_s']:10,.1f} "
                   f"{r['print_time_change_pct']:7.2f} {r['groups_optimal']:8d} "
                   f"{r['groups_feasible']:8d} {r['groups_fallback']:8d} {gap:>9s} {r['wall_s']:7.2f} "
                   f"{'yes' if r['verified'] else 'NO':>8s}")
    if rows and "travel_before_mm" in rows[0]:
        out.append("travel % and time % are against the slicer's order (travel measured on the files; "
                   "print s, time %: the planner model); groups: proven optimal / feasible at the limit / fallback (heuristic); "
                   "worst gap to the group's lower bound")
    return "\n".join(out)


def plot_compare(rows: list[dict], path: str, ordering: bool = False) -> None:
    """A bar chart of the rows: energy saving (or, ``ordering``, travel change) per formulation
    and file."""
    from ..plot import check_png_path, save_png
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    key, ylabel, title = (("travel_change_pct", "travel change % (vs the slicer's order)",
                           "curve ordering: travel by formulation") if ordering else
                          ("saving_pct", "energy saving %", "motor power gating: saving by formulation"))
    files = list(dict.fromkeys(r["file"] for r in rows))
    forms = list(dict.fromkeys(r["formulation"] for r in rows))
    fig, ax = plt.subplots(figsize=(max(6, 1.2 * len(files) * len(forms) / 2), 4))
    w = 0.8 / max(len(forms), 1)
    for k, f in enumerate(forms):
        ys = []
        for fn in files:
            r = next((r for r in rows if r["file"] == fn and r["formulation"] == f), None)
            ys.append(r.get(key, math.nan) if r else math.nan)
        ax.bar([i + k * w for i in range(len(files))], ys, width=w, label=f)
    ax.set_xticks([i + w * (len(forms) - 1) / 2 for i in range(len(files))])
    ax.set_xticklabels(files, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    try:
        save_png(fig, check_png_path(path), dpi=120)
    finally:
        plt.close(fig)
