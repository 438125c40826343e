"""``gatesopt solve``: motor power gating (3DGates), with the curve ordering before it.

Option parsing and printing only; the work is ``gatesopt.rewrite.run`` (order -> build ->
solve -> emit -> re-parse -> verify). Every output is verified before it is written; a file is
written to a temporary name in the target folder and renamed, never over an existing file without
``--force``, never over the input.
"""
from __future__ import annotations

import sys
import time

from ..errors import GatesoptError
from .files import (STDIO, check_distinct, check_input, check_new_file, check_output, read_program,
                    write_atomic, write_json, write_stdout)
from .options import (add_gating_options, firmware_choice, gating_formulations, gating_options,
                      ordering_formulations, positive_s)
from .progress import default_workers, group_progress, wants_progress
from .summary import figure_lines, ordering_result_lines, time_spent_line

NAME = "solve"
HELP = "insert motor power-gating instructions (and re-order curves)"
DESCRIPTION = ("Write gated G-code: motors switched off while idle (3DGates), optionally rotated on "
               "the bed; verified before it is written.")


def add_arguments(p) -> None:
    p.add_argument("file", help="input G-code (.gcode or .gcode.gz), or - for standard input")
    p.add_argument("-o", "--output", metavar="OUT.gcode",
                   help="output file (gzipped if its name ends in .gz), or - for standard output")
    p.add_argument("--in-place", action="store_true",
                   help="replace the input file (a slicer's post-processing step): written to a "
                        "temporary file beside it, verified, then renamed over it keeping its "
                        "permissions; on any failure the input is left untouched")
    p.add_argument("--formulation", choices=gating_formulations(), default="dp",
                   help="greedy (paper's Algorithm 1), dp (exact when separable), milp, cpsat")
    add_gating_options(p)
    p.add_argument("--json", metavar="REPORT.json", help="also write the report as JSON")
    p.add_argument("--no-order", action="store_true", help="do not re-order curves")
    p.add_argument("--order-mode", choices=("safe", "free"), default="safe",
                   help="as `order --order-mode`: safe keeps the slicer's feature groups, walls and "
                        "objects (default); free re-orders every curve of a layer (ironing keeps "
                        "its place)")
    p.add_argument("--move-seams", action="store_true",
                   help="closed loops may start at another vertex (default: keep the seam)")
    p.add_argument("--objective", choices=("time", "travel"), default="time",
                   help="what the curve ordering minimises: time (default), the travels' print time as emitted, retractions, z-hops and the slicer's own copied travels included; travel, their length (Fleming et al.)")
    p.add_argument("--order-formulation", choices=ordering_formulations(), default=None,
                   help="the curve ordering's formulation (default: the exact one named by "
                        "--formulation: milp or cpsat; greedy for greedy; auto for dp)")
    p.add_argument("--budget", type=float, default=10.0, metavar="S",
                   help="finish the whole run, from the start of the command to the verified "
                        "output, in about S seconds (default 10), every solve included: the curve "
                        "ordering gets what an estimate of the rest leaves, and an exact "
                        "--formulation (milp, cpsat) searches for what is left of it, at most "
                        "--time-limit")
    p.add_argument("--no-gating", action="store_true", help="do not insert gating instructions")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")


def order_formulation_of(gating_formulation: str) -> str:
    """``rewrite.pipeline.order_formulation_of`` (the one rule ``solve``, ``compare`` and ``batch``
    share)."""
    from ..rewrite.pipeline import order_formulation_of as of
    return of(gating_formulation)


def status_text(s: dict) -> str:
    """"optimal", or "feasible (stopped: time limit)": the status and why a search stopped."""
    return str(s["status"]) + (f" (stopped: {s['stopped']})" if s.get("stopped") else "")


def _off_model_part(s: dict) -> str:
    """Which timeline the off times are on: the energy model's (the paper's T = L/F, shorter than
    the printer's: Klipper replays measured X 19.2 s off where this said 12.5 s) or the
    planner's."""
    model = s.get("off_time_model")
    if not s.get("off_time_s") or model is None:
        return ""
    return ("   (planner times)" if model == "planner"
            else "   (the energy model's T = L/F times; the printer's are longer)")


def _waits_part(waits: dict) -> str:
    """"   (in heat-up waits: X 92.50 s ...)": the off time that lies in M109 / M190 waits."""
    shown = {m: t for m, t in waits.items() if t > 0.005}
    if not shown:
        return ""
    return "   (in heat-up waits: " + "  ".join(f"{m} {t:.2f} s" for m, t in shown.items()) + ")"


def format_solve_report(s: dict) -> str:
    at = f" at the {s['rotation_deg']:g} deg rotation chosen" if s["rotation_deg"] else ""
    lines = [
        f"file          {s['source']}",
        f"firmware      {s.get('firmware_line') or s['firmware']}",
        f"formulation   {s['formulation'] or '-'} ({s['firmware']} firmware)   status {status_text(s)}{at}"
        + (f"   bound {s['bound']:.3f} J" if s.get("bound") is not None else "")
        + (f"   gap {100 * s['gap']:.4f} %" if s.get("gap") is not None else "   gap n/a"),
        f"energy        {s['energy_before_j']:.1f} J -> {s['energy_after_j']:.1f} J"
        f"   saving {s['saving_pct']:.2f} %   (3DGates model over the paper's T = L/F times, "
        "firmware stalls included)",
        figure_lines(s)[0],
    ]
    if s.get("max_added_time_pct") is not None:
        lines.append(f"time budget   print time {s['added_time_pct']:+.3f} % against the file as given "
                     f"(planner model; re-ordering, rotation and the firmware's stalls together), "
                     f"at most {s['max_added_time_pct']:+g} %")
    lines += [
        f"lines         {s['lines_added']:+d} ({s['instruction_lines']} instruction lines, {s['splits']} moves split)"
        f"   file size {s['size_change_pct']:+.2f} %",
        f"rotation      {s.get('rotation_line') or 'none'}"
        + (f"   largest single-axis snap {s['max_snap_mm'] * 1e3:.3f} um" if s["rotation_deg"] else ""),
        "off time      " + ("  ".join(f"{m} {t:.2f} s" for m, t in s["off_time_s"].items()) or "-")
        + _waits_part(s.get("off_time_waits_s") or {}) + _off_model_part(s),
        figure_lines(s)[1],
    ]
    o = s.get("ordering")
    if o is not None:
        lines.append(f"ordering      {o['formulation']}   mode {o['order_mode']}"
                     + ("   seams may move" if o["move_seams"] else "   seams kept")
                     + f"   solve {o['solve_s']:.2f} s")
        lines += ordering_result_lines(o)
    else:
        lines.append("ordering      none: the slicer's order")
    lines.append(f"solve         {s['solve_s']:.2f} s   (every solver: ordering "
                 f"{s['ordering_solve_s']:.2f} s, gating {s['gating_solve_s']:.2f} s)")
    lines.append(time_spent_line(s))
    lines.append(f"verified      {'yes' if s['verified'] else 'NO'}")
    if s.get("status") == "infeasible" and s.get("message"):
        lines.append(f"note          {s['message']}")   # greedy: which budget it broke
    for n in s.get("notes", []):
        lines.append(f"note          {n}")
    return "\n".join(lines)


def _solve_paths(args) -> tuple[str, str]:
    """(input, output) after checking the combination of FILE, -o and --in-place."""
    check_input(args.file)
    if args.in_place:
        if args.output not in (None, args.file):
            raise GatesoptError("--in-place writes over the input: do not give -o as well")
        if args.file == STDIO:
            raise GatesoptError("--in-place needs a file, not standard input")
        return args.file, args.file
    if not args.output:
        raise GatesoptError("give an output file with -o OUT.gcode (or -o - for standard output), "
                            "or --in-place to replace the input")
    if args.output != STDIO:
        check_output(args.file, args.output, args.force)
    return args.file, args.output


def run(args) -> int:
    from ..rewrite.pipeline import run as run_job
    positive_s(args.budget, "--budget")
    if args.no_gating and args.rotate not in ("auto", "none"):
        raise GatesoptError(f"--rotate {args.rotate}: the rotation is chosen with the gating, "
                            "which --no-gating turns off")
    inp, out = _solve_paths(args)
    if args.json:
        # the report must not replace the input, the output or a file the user did not give up
        check_distinct({"-o": None if args.in_place else out, "--json": args.json})
        check_new_file(args.json, [inp] if inp != STDIO else [], args.force)
    report_to = sys.stderr if out == STDIO else sys.stdout     # stdout carries the G-code
    fields = gating_options(args)
    from ..ordering import OrderingOptions
    order_options = OrderingOptions(mode=args.order_mode, move_seams=args.move_seams,
                                    objective=args.objective)
    # "--formulation milp means exact for both" (issue 4): the gating formulation names the
    # ordering's unless --order-formulation does; dp is gating's alone (ordering: auto)
    order_formulation = args.order_formulation or order_formulation_of(args.formulation)
    started_s = getattr(args, "started_s", None) or time.perf_counter()
    program = read_program(inp)
    # the firmware the file's printer runs, its budget, and the line that says so (issue 37)
    choice = firmware_choice(args, program, **fields)
    gating = not args.no_gating and choice.options is not None
    # the budget counts from the command's start (``cli.clock``): reading the file, all of it
    with group_progress(wants_progress() and not args.no_order, after="gating, verifying",
                        deadline_s=started_s + args.budget) as progress:
        result = run_job(program, choice.options, formulation=args.formulation, time_limit_s=args.time_limit,
                         order=not args.no_order, gating=gating, choice=choice,
                         order_workers=default_workers(), budget_s=args.budget,
                         order_progress=progress, order_options=order_options,
                         order_formulation=order_formulation, started_s=started_s,
                         cpu_started_s=getattr(args, "cpu_started_s", None))
    s = result.summary()
    s["max_added_time_pct"] = None if choice.options is None else choice.options.max_added_time_pct
    if not result.report.ok:
        if out != STDIO:    # stderr keeps the one line a slicer shows
            print(format_solve_report(s))
        where = "the input is unchanged" if args.in_place else f"nothing written to {out}"
        first = str(result.report.findings[0]) if result.report.findings else "see above"
        from ..gating.rotation import own_xy_disable
        own = own_xy_disable(program, 0, program.n_steps)
        hint = "" if own is None else (
            f"; the input switches an X/Y motor off itself ({program.source}:"
            f"{int(program.line[own]) + 1}: already gated?): gate the slicer's original")
        raise GatesoptError(f"the output failed verification ({first}); {where}{hint}")
    if out == STDIO:
        write_stdout(result.text)
    elif args.in_place:
        write_atomic(out, result.text, like=inp)
    else:
        check_output(inp, out, args.force)   # again: the solve may have taken a while
        write_atomic(out, result.text)
    s["output"] = out
    print(format_solve_report(s), file=report_to)
    if args.json:
        write_json(args.json, s)
    return 0


