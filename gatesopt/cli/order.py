"""``gatesopt order``: re-order each layer's curves to cut travel (Fleming et al.).

Option parsing and printing only; the work is ``gatesopt.rewrite.order_program``
(build -> solve -> emit -> re-parse -> verify). The output is verified before it is written, written
to a temporary file beside the target and renamed; never over the input, never over an existing
file without ``--force``.
"""
from __future__ import annotations

import sys
import time

from ..errors import GatesoptError
from .files import (STDIO, check_distinct, check_input, check_new_file, check_output, read_program,
                    write_atomic, write_json, write_stdout)
from .options import number_or_none, ordering_formulations, positive_s
from .progress import default_workers, group_progress, wants_progress
from .summary import figure_lines, ordering_result_lines

NAME = "order"
HELP = "re-order extrusion curves to cut travel (Fleming et al.)"
DESCRIPTION = ("Re-order each layer's extrusion curves, each in either direction, to cut travel; the "
               "output is verified before it is written.")


def add_arguments(p) -> None:
    p.add_argument("file", help="input G-code (.gcode or .gcode.gz), or - for standard input")
    p.add_argument("-o", "--output", required=True, metavar="OUT.gcode",
                   help="output file (gzipped if its name ends in .gz), or - for standard output")
    p.add_argument("--formulation", choices=ordering_formulations(), default="auto",
                   help="greedy (nearest neighbour + 2-opt/Or-opt), tsp (Fleming's closed tour cut "
                        "open), cpsat, milp (exact), auto (exact where small enough; default)")
    p.add_argument("--order-mode", choices=("safe", "free"), default="safe",
                   help="safe: keep the slicer's feature groups, walls and objects (default); "
                        "free: re-order every curve of a layer, as the paper does (ironing keeps "
                        "its place)")
    p.add_argument("--move-seams", action="store_true",
                   help="closed loops may start at another vertex (default: keep the seam)")
    p.add_argument("--objective", choices=("time", "travel"), default="time",
                   help="what the curve ordering minimises: time (default), the travels' print time as emitted, retractions, z-hops and the slicer's own copied travels included; travel, their length (Fleming et al.)")
    p.add_argument("--time-limit", type=float, default=2.0, metavar="S",
                   help="time limit per group for the exact formulations (default 2 s)")
    p.add_argument("--budget", type=number_or_none, default=10.0, metavar="S|none",
                   help="finish in about S seconds, from reading the file to the verified output: the "
                        "solve gets what an estimate of the rest leaves (groups share it; default "
                        "10, as `solve --budget`); none: every group gets its --time-limit")
    p.add_argument("--workers", type=int, choices=(1, 2), default=default_workers(),
                   help="processes: 2 lets a second one solve the chain of groups from the back "
                        "(greedy: make the link matrices, greedy's paths stay one process's) "
                        "(default: 2 if this machine has 2 cores or more)")
    p.add_argument("--allow-slower-layers", action="store_true",
                   help="keep a layer's new order even if its rebuilt travels (retractions, "
                        "z-hops) make it take longer than the slicer's (default: such a layer "
                        "keeps the slicer's order)")
    p.add_argument("--json", metavar="REPORT.json", help="also write the report as JSON")
    p.add_argument("--plot", metavar="OUT.png",
                   help="also draw one layer's travels before and after, and every layer's travel")
    p.add_argument("--plot-layer", type=int, metavar="N",
                   help="the layer --plot draws (0-based, as in the JSON report; default: the layer "
                        "whose travel was cut the most)")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")


def run(args) -> int:
    # a --budget counts from the command's start (``cli.clock``): imports, parse, all of it
    started_s = getattr(args, "started_s", None) or time.perf_counter()
    from ..ordering import OrderingOptions
    from ..rewrite.budget import budget_clock
    from ..rewrite.order import order_program
    positive_s(args.time_limit, "--time-limit")
    if args.budget is not None:
        positive_s(args.budget, "--budget")
    check_input(args.file)
    _check_output(args)
    check_distinct({"-o": args.output, "--json": args.json, "--plot": args.plot})
    if args.json:
        check_new_file(args.json, [args.file], args.force)
    if args.plot_layer is not None and not args.plot:
        raise GatesoptError("--plot-layer needs --plot OUT.png")
    if args.plot:
        check_new_file(args.plot, [args.file], args.force, png=True)
    program = read_program(args.file)
    if args.plot_layer is not None and not 0 <= args.plot_layer < program.n_layers:
        raise GatesoptError(f"{args.file}: --plot-layer {args.plot_layer}: layers are 0 to "
                            f"{program.n_layers - 1}")
    options = OrderingOptions(mode=args.order_mode, move_seams=args.move_seams,
                                    objective=args.objective)
    # the rest of a budgeted run is estimated at the rate this machine gave it so far, as
    # ``gatesopt solve`` estimates it (a loaded machine: emit and verify take that much longer);
    # a first run counts its reading at the quiet rate (``budget_clock``)
    slow = 1.0
    if args.budget is not None:
        started_s, slow = budget_clock(started_s, getattr(args, "cpu_started_s", None), program.n_lines)
    deadline_s = None if args.budget is None else started_s + args.budget
    with group_progress(wants_progress(), deadline_s=deadline_s, after="verifying") as progress:
        result = order_program(program, options, formulation=args.formulation,
                               time_limit_s=args.time_limit, budget_s=args.budget,
                               workers=args.workers, time_guard=not args.allow_slower_layers,
                               progress=progress, started_s=started_s, slow=slow)
    s = result.summary
    report_to = sys.stderr if args.output == STDIO else sys.stdout     # stdout carries the G-code
    if not result.ok:
        print(format_report(s), file=report_to)
        print(f"gatesopt: error: the output failed verification; nothing written to {args.output}",
              file=sys.stderr)
        for f in result.findings[:10]:
            print(f"  {f}", file=sys.stderr)
        return 1
    if args.output == STDIO:
        write_stdout(result.text)
    else:
        _check_output(args)             # again: the solve may have taken a while
        write_atomic(args.output, result.text)
    s["output"] = args.output
    print(format_report(s), file=report_to)
    if args.json:
        write_json(args.json, s, default=float)
    if args.plot:
        from ..ordering.plot import plot_ordering
        print(f"plot          {plot_ordering(program, result.output, args.plot, layer=args.plot_layer)}",
              file=report_to)
    return 0


def _check_output(args) -> None:
    """``-o``: standard output, or a file that is not the input and not replaced without --force."""
    if args.output != STDIO:
        check_output(args.file, args.output, args.force)


def format_report(s: dict) -> str:
    lines = [
        f"file          {s['source']}",
        f"formulation   {s['formulation']}   mode {s['order_mode']}"
        + ("   seams may move" if s["move_seams"] else "   seams kept")
        + f"   time limit {s['time_limit_s']:g} s per group"
        + (f", budget {s['budget_s']:g} s for the whole run" if s.get("budget_s") else "")
        + (f", {s['workers']} processes" if s.get("workers", 1) > 1 else ""),
        *figure_lines(s),
        *ordering_result_lines(s),
        f"solve         {s['solve_s']:.2f} s"
        + (f" of the {s['solve_budget_s']:.2f} s the budget left it" if s.get("solve_budget_s") else "")
        + f"   (whole run {s['wall_s']:.2f} s)",
        f"verified      {'yes' if s['verified'] else 'NO'}",
    ]
    if s.get("output"):
        lines.append(f"written       {s['output']}")
    for n in s.get("notes", [])[:8]:
        lines.append(f"note          {n}")
    return "\n".join(lines)
