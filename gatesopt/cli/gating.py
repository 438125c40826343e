"""``gatesopt solve`` and ``gatesopt compare``: motor power gating (3DGates) from the command line.

Option parsing and printing only; the work is ``gatesopt.rewrite.run`` (order -> build ->
solve -> emit -> re-parse -> verify). Every output is verified before it is written; a file is
written to a temporary name in the target folder and renamed, never over an existing file without
``--force``, never over the input.
"""
from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import time

from ..errors import GatesoptError
from ..parse import parse

FIRMWARES = ("3dgates", "marlin", "klipper")
FORMULATION_NAMES = ("greedy", "dp", "milp", "cpsat")

#: the curve ordering's formulations (``order --formulation``, ``solve --order-formulation``)
ORDER_FORMULATIONS = ("greedy", "tsp", "cpsat", "milp", "auto")
#: the curve ordering's formulation for each gating formulation (``solve --order-formulation``)
ORDER_FORMULATION_OF = {"milp": "milp", "cpsat": "cpsat", "greedy": "greedy", "dp": "auto"}


def _add_common(p) -> None:
    p.add_argument("--firmware", choices=FIRMWARES, default="3dgates",
                   help="instruction dialect and cost model (default: 3dgates, the paper's S0/S1)")
    p.add_argument("--motors", default="X,Y", metavar="X,Y",
                   help="motors to gate, comma separated (default X,Y; Z and E opt-in)")
    p.add_argument("--rotate", default="auto", metavar="auto|none|DEG",
                   help="rotate the model on the bed: auto (best angle), none, or degrees ccw "
                        "(a print of objects one at a time is never rotated)")
    p.add_argument("--start-ahead-ms", type=float, default=1.8,
                   help="switch a motor on at least this long before it steps (default 1.8, paper)")
    p.add_argument("--end-late-ms", type=float, default=1.0,
                   help="keep a motor on at least this long after it steps (default 1.0, paper)")
    p.add_argument("--max-added-time-pct", type=float, default=None, metavar="P",
                   help="budget: firmware stalls may add at most P %% to the print time")
    p.add_argument("--max-added-lines-pct", type=float, default=None, metavar="P",
                   help="budget: at most P %% more lines")
    p.add_argument("--time-limit", type=float, default=60.0, metavar="S",
                   help="solver time limit in seconds (milp, cpsat; default 60)")
    p.add_argument("--profile", default="paper", metavar="NAME|TOML",
                   help="energy profile: shipped name or TOML file (default: paper)")
    p.add_argument("--threads", type=int, default=2, metavar="N",
                   help="solver threads (default 2); 1 makes every run byte-identical (seeds are fixed)")
    p.add_argument("--bed", default=None, metavar="WxD",
                   help="bed size in mm for the rotation check (default: from the file's header)")


def register(sub) -> None:
    p = sub.add_parser("solve", help="insert motor power-gating instructions (and re-order curves)",
                       description="Write gated G-code: motors switched off while idle (3DGates), "
                                   "optionally rotated on the bed; verified before it is written.")
    p.add_argument("file", help="input G-code (.gcode or .gcode.gz), or - for standard input")
    p.add_argument("-o", "--output", metavar="OUT.gcode", help="output file, or - for standard output")
    p.add_argument("--in-place", action="store_true",
                   help="replace the input file (a slicer's post-processing step): written to a "
                        "temporary file beside it, verified, then renamed over it keeping its "
                        "permissions; on any failure the input is left untouched")
    p.add_argument("--formulation", choices=FORMULATION_NAMES, default="dp",
                   help="greedy (paper's Algorithm 1), dp (exact when separable), milp, cpsat")
    _add_common(p)
    p.add_argument("--json", metavar="REPORT.json", help="also write the report as JSON")
    p.add_argument("--no-order", action="store_true", help="do not re-order curves")
    p.add_argument("--order-mode", choices=("safe", "free"), default="safe",
                   help="as `order --order-mode`: safe keeps the slicer's feature groups, walls and "
                        "objects (default); free re-orders every curve of a layer")
    p.add_argument("--move-seams", action="store_true",
                   help="closed loops may start at another vertex (default: keep the seam)")
    p.add_argument("--order-formulation", choices=ORDER_FORMULATIONS, default=None,
                   help="the curve ordering's formulation (default: the exact one named by "
                        "--formulation: milp or cpsat; greedy for greedy; auto for dp)")
    p.add_argument("--order-budget", type=float, default=10.0, metavar="S",
                   help="finish the curve ordering (build, solve, emit) in about S seconds "
                        "(default 10; the solve gets what an estimate of the emit leaves, as "
                        "`order --budget`)")
    p.add_argument("--no-gating", action="store_true", help="do not insert gating instructions")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.set_defaults(func=run_solve)

    c = sub.add_parser("compare", help="all gating (or --ordering: curve ordering) formulations side by side",
                       description="Solve each file with every gating formulation (greedy always "
                                   "included) and print one table; outputs are verified, not written. "
                                   "With --ordering: every curve-ordering formulation instead, by travel.")
    c.add_argument("files", nargs="+", help="G-code files")
    c.add_argument("--formulations", default=None, metavar="LIST",
                   help="comma separated (default: all of the compared kind); greedy is always a row")
    c.add_argument("--ordering", action="store_true",
                   help="compare the curve ordering's formulations (greedy, tsp, cpsat, milp, auto) "
                        "by travel instead of gating's by energy")
    c.add_argument("--order-mode", choices=("safe", "free"), default="safe",
                   help="with --ordering: as `order --order-mode` (default safe)")
    c.add_argument("--move-seams", action="store_true",
                   help="with --ordering: closed loops may start at another vertex")
    c.add_argument("--order-budget", type=float, default=10.0, metavar="S",
                   help="with --ordering: each formulation's run of a file, parse to verified output, "
                        "in about S seconds (default 10, as `order --budget`)")
    _add_common(c)
    c.add_argument("--plot", metavar="OUT.png", help="bar chart of the saving per formulation")
    c.add_argument("--json", metavar="OUT.json", help="write the rows as JSON")
    c.add_argument("--force", action="store_true", help="overwrite an existing plot or JSON file")
    c.set_defaults(func=run_compare)


# ------------------------------------------------------------------------------------------------
def options_from_args(args):
    from ..gating.options import GatingOptions
    motors = tuple(m.strip().upper() for m in args.motors.split(",") if m.strip())
    rotate = args.rotate
    if rotate not in ("auto", "none"):
        try:
            rotate = float(rotate)
        except ValueError:
            raise GatesoptError(f"--rotate must be auto, none or degrees, not {args.rotate!r}") from None
    for name in ("start_ahead_ms", "end_late_ms"):
        v = getattr(args, name)
        if not (math.isfinite(v) and v >= 0):
            raise GatesoptError(f"--{name.replace('_', '-')} must be >= 0, not {v}")
    if args.threads < 1:
        raise GatesoptError(f"--threads must be at least 1, not {args.threads}")
    if not (args.time_limit > 0):
        raise GatesoptError(f"--time-limit must be > 0 s, not {args.time_limit}")
    bed = None
    if args.bed:
        try:
            w, d = (float(v) for v in args.bed.lower().split("x"))
            bed = (w, d)
        except ValueError:
            raise GatesoptError(f"--bed must look like 220x220, not {args.bed!r}") from None
    return GatingOptions.for_firmware(
        args.firmware, motors=motors, rotate=rotate, start_ahead_s=args.start_ahead_ms / 1e3,
        end_late_s=args.end_late_ms / 1e3, max_added_time_pct=args.max_added_time_pct,
        max_added_lines_pct=args.max_added_lines_pct, profile=args.profile, bed_size_mm=bed,
        num_workers=args.threads)


def check_new_file(path: str, inputs, force: bool, png: bool = False) -> None:
    """Before any work: ``path`` (a report or plot the command will write) is none of ``inputs``,
    its folder exists, and an existing file is overwritten only with ``force``; ``png``: the
    name ends in .png (``gatesopt.plot.check_png_path``)."""
    if png:
        from ..plot import check_png_path
        check_png_path(path)
    for inp in inputs:
        _check_paths(inp, path, force)


def check_distinct(named: dict) -> None:
    """Before any work: the files one command writes (``{"--json": path, ...}``; None and "-"
    skipped) are different files; else the last write would silently replace the first."""
    seen = {}
    for flag, path in named.items():
        if not path or path == "-":
            continue
        key = os.path.abspath(path)
        if key in seen:
            raise GatesoptError(f"{path}: {seen[key]} and {flag} must name different files")
        seen[key] = flag


def _check_paths(inp: str, out: str, force: bool) -> None:
    if os.path.abspath(inp) == os.path.abspath(out) or (
            os.path.exists(out) and os.path.exists(inp) and os.path.samefile(inp, out)):
        raise GatesoptError(f"{out}: the output must not be the input file")
    if os.path.exists(out) and not force:
        raise GatesoptError(f"{out}: exists; pass --force to overwrite it")
    folder = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(folder):
        raise GatesoptError(f"{out}: folder {folder} does not exist")


def write_atomic(path: str, text: str, like: str | None = None) -> None:
    """Write ``text`` to a temporary file beside ``path`` and rename it into place.

    ``like``: an existing file whose permissions (and gzip compression) the new file keeps, for
    replacing a file in place.
    """
    import gzip
    import shutil
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".gatesopt-", suffix=".tmp", dir=folder)
    try:
        data = text.encode("utf-8", "surrogateescape")
        if like is not None:
            with open(like, "rb") as f:
                if f.read(2) == b"\x1f\x8b":
                    data = gzip.compress(data)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        if like is not None:
            shutil.copymode(like, tmp)
        else:       # mkstemp makes a private 0600 file; a new output gets the usual permissions
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def ordering_result_lines(s: dict) -> list[str]:
    """The lines of a re-ordering's report (``rewrite.order.order_summary``) that say what it
    did: travel, times, travels, curves, groups and layers (``order`` and ``solve`` print them)."""
    def pct(a, b):
        return f"{100.0 * (a / b - 1.0):+.1f} %" if b else "n/a"
    return [
        f"travel        {s['travel_before_mm']:,.1f} mm -> {s['travel_after_mm']:,.1f} mm"
        f"   ({pct(s['travel_after_mm'], s['travel_before_mm'])})",
        f"travel time   {s['travel_time_before_s']:,.1f} s -> {s['travel_time_after_s']:,.1f} s"
        f"   ({pct(s['travel_time_after_s'], s['travel_time_before_s'])})",
        f"print time    {s['print_time_before_s']:,.1f} s -> {s['print_time_after_s']:,.1f} s"
        f"   ({pct(s['print_time_after_s'], s['print_time_before_s'])}; travels, retractions, z-hops)",
        f"travels       {s['travels_before']:,} -> {s['travels_after']:,}"
        f"   retractions {s['retractions_before']:,} -> {s['retractions_after']:,}",
        f"curves        {s['curves']:,} in {s['groups']:,} groups; {s['groups_reordered']:,} re-orderable "
        f"(largest {s['largest_group']} curves)",
        f"groups        optimal {s['groups_optimal']:,}   feasible at limit {s['groups_feasible']:,}"
        f"   fallback {s['groups_fallback']:,}   worst gap {100 * s['worst_gap']:.2f} %",
        f"layers        optimal {s['layers_optimal']:,}   feasible at limit {s['layers_feasible']:,}"
        f"   fallback {s['layers_fallback']:,}   order kept {s['layers_kept']:,}"
        + (f" ({s['layers_kept_slower']:,} of them: slower re-ordered)" if s.get("layers_kept_slower") else ""),
    ]


def format_solve_report(s: dict) -> str:
    def pct(a, b):
        return 100.0 * (a / b - 1.0) if b else 0.0
    lines = [
        f"file          {s['source']}",
        f"formulation   {s['formulation'] or '-'} ({s['firmware']} firmware)   status {s['status']}"
        + (f"   bound {s['bound']:.3f} J" if s.get("bound") is not None else "")
        + (f"   gap {100 * s['gap']:.4f} %" if s.get("gap") is not None else "   gap n/a"),
        f"energy        {s['energy_before_j']:.1f} J -> {s['energy_after_j']:.1f} J"
        f"   saving {s['saving_pct']:.2f} %",
        f"time          {s['time_before_s']:.2f} s -> {s['time_after_s']:.2f} s"
        f"   ({pct(s['time_after_s'], s['time_before_s']):+.3f} %, firmware stalls included)",
        f"lines         +{s['lines_added']} ({s['instruction_lines']} instruction lines, {s['splits']} moves split)"
        f"   file size {s['size_change_pct']:+.2f} %",
        (f"rotation      {s['rotation_deg']:g} deg about ({s['center_xy'][0]:.3f}, {s['center_xy'][1]:.3f})"
         f"   largest single-axis snap {s['max_snap_mm'] * 1e3:.3f} um" if s["rotation_deg"]
         else "rotation      none"),
        "off time      " + ("  ".join(f"{m} {t:.2f} s" for m, t in s["off_time_s"].items()) or "-"),
        f"solve         {s['solve_s']:.3f} s   (whole run {s['wall_s']:.2f} s)",
    ]
    o = s.get("ordering")
    if o is not None:
        lines.append(f"ordering      {o['formulation']}   mode {o['order_mode']}"
                     + ("   seams may move" if o["move_seams"] else "   seams kept")
                     + f"   solve {o['solve_s']:.2f} s")
        lines += ordering_result_lines(o)
    else:
        lines.append("ordering      none: the slicer's order")
    lines.append(f"verified      {'yes' if s['verified'] else 'NO'}")
    for n in s.get("notes", []):
        lines.append(f"note          {n}")
    return "\n".join(lines)


def _solve_paths(args) -> tuple[str, str]:
    """(input, output) after checking the combination of FILE, -o and --in-place."""
    if args.in_place:
        if args.output not in (None, args.file):
            raise GatesoptError("--in-place writes over the input: do not give -o as well")
        if args.file == "-":
            raise GatesoptError("--in-place needs a file, not standard input")
        if not os.path.isfile(args.file):
            raise GatesoptError(f"{args.file}: no such file")
        return args.file, args.file
    if not args.output:
        raise GatesoptError("give an output file with -o OUT.gcode (or -o - for standard output), "
                            "or --in-place to replace the input")
    if args.output != "-":
        if args.file == "-":
            if os.path.exists(args.output) and not args.force:
                raise GatesoptError(f"{args.output}: exists; pass --force to overwrite it")
        else:
            _check_paths(args.file, args.output, args.force)
    return args.file, args.output


def run_solve(args) -> int:
    from ..rewrite.pipeline import run
    if not (math.isfinite(args.order_budget) and args.order_budget > 0):
        raise GatesoptError(f"--order-budget must be > 0 s, not {args.order_budget}")
    if args.no_gating and args.rotate not in ("auto", "none"):
        raise GatesoptError(f"--rotate {args.rotate}: the rotation is chosen with the gating, "
                            "which --no-gating turns off")
    inp, out = _solve_paths(args)
    if args.json:
        # the report must not replace the input, the output or a file the user did not give up
        check_distinct({"-o": None if args.in_place else out, "--json": args.json})
        check_new_file(args.json, [inp] if inp != "-" else [], args.force)
    report_to = sys.stderr if out == "-" else sys.stdout     # stdout carries the G-code
    options = options_from_args(args)
    from ..ordering import OrderingOptions
    order_options = OrderingOptions(mode=args.order_mode, move_seams=args.move_seams)
    # "--formulation milp means exact for both" (issue 4): the gating formulation names the
    # ordering's unless --order-formulation does; dp is gating's alone (ordering: auto)
    order_formulation = args.order_formulation or ORDER_FORMULATION_OF.get(args.formulation, "auto")
    if inp == "-":
        program = parse(sys.stdin.buffer.read(), source="<stdin>")
    else:
        program = parse(inp)
    from .ordering import default_workers, group_progress
    # the ordering starts now: its budget ends order_budget seconds from here
    with group_progress(sys.stderr.isatty() and not args.no_order,
                        deadline_s=time.perf_counter() + args.order_budget) as progress:
        result = run(program, options, formulation=args.formulation, time_limit_s=args.time_limit,
                     order=not args.no_order, gating=not args.no_gating,
                     order_workers=default_workers(), order_budget_s=args.order_budget,
                     order_progress=progress, order_options=order_options,
                     order_formulation=order_formulation)
    s = result.summary()
    if not result.report.ok:
        if out != "-":      # stderr keeps the one line a slicer shows
            print(format_solve_report(s))
        where = "the input is unchanged" if args.in_place else f"nothing written to {out}"
        first = str(result.report.findings[0]) if result.report.findings else "see above"
        from ..gating.rotation import own_xy_disable
        own = own_xy_disable(program, 0, program.n_steps)
        hint = "" if own is None else (
            f"; the input switches an X/Y motor off itself ({program.source}:"
            f"{int(program.line[own]) + 1}: already gated?): gate the slicer's original")
        raise GatesoptError(f"the output failed verification ({first}); {where}{hint}")
    if out == "-":
        sys.stdout.buffer.write(result.text.encode("utf-8", "surrogateescape"))
        sys.stdout.flush()
    elif args.in_place:
        write_atomic(out, result.text, like=inp)
    else:
        _check_paths(inp, out, args.force)   # again: the solve may have taken a while
        write_atomic(out, result.text)
    s["output"] = out
    print(format_solve_report(s), file=report_to)
    if args.json:
        write_atomic(args.json, json.dumps(s, indent=2, default=_jsonable) + "\n")
    return 0


def _jsonable(v):
    try:
        return float(v)
    except (TypeError, ValueError):
        return str(v)


# ------------------------------------------------------------------------------------------------
def formulation_rows(program, formulations, known, solve_row, installed=lambda name: True) -> list[dict]:
    """``compare``'s rows: one per formulation, greedy first; ``solve_row(name)`` gives a solved
    row's values. An unknown name, a backend not installed or a run that fails is a row saying so."""
    rows = []
    for name in ["greedy"] + [f for f in formulations if f != "greedy"]:
        row = {"file": os.path.basename(program.source), "formulation": name}
        if name not in known:
            row.update(status="unknown", error=f"unknown formulation {name!r}")
        elif not installed(name):
            row.update(status="unavailable", error="backend not installed")
        else:
            try:
                row.update(solve_row(name))
            except ModuleNotFoundError as exc:
                row.update(status="unavailable", error=str(exc))
            except GatesoptError as exc:
                row.update(status="error", error=str(exc))
        rows.append(row)
    return rows


def compare_rows(program, options, formulations, time_limit_s) -> list[dict]:
    """One row per gating formulation (greedy first), each a verified run (nothing written)."""
    from ..gating.solve import FORMULATIONS, is_installed
    from ..rewrite.pipeline import run

    def solve_row(name):
        r = run(program, options, formulation=name, time_limit_s=time_limit_s, order=False)
        s = r.summary()
        row = {k: s[k] for k in ("saving_pct", "energy_before_j", "energy_after_j", "lines_added",
                                 "instruction_lines", "size_change_pct", "added_time_pct",
                                 "status", "gap", "bound", "solve_s", "rotation_deg", "verified")}
        if not r.report.ok:
            row["findings"] = [str(f) for f in r.report.findings[:3]]
        return row
    return formulation_rows(program, formulations, FORMULATIONS, solve_row, is_installed)


def format_compare(rows: list[dict]) -> str:
    head = (f"{'file':28s} {'formulation':11s} {'saving %':>9s} {'instr':>7s} {'size +%':>8s} "
            f"{'time +%':>8s} {'rot deg':>8s} {'status':>11s} {'gap':>9s} {'solve s':>8s} {'verified':>8s}")
    out = [head, "-" * len(head)]
    for r in rows:
        if "saving_pct" not in r:
            out.append(f"{r['file'][:28]:28s} {r['formulation']:11s} {'':>9s} {'':>7s} {'':>8s} {'':>8s} "
                       f"{'':>8s} {r['status']:>11s}   {r.get('error', '')[:60]}")
            continue
        gap = "n/a" if r["gap"] is None else f"{100 * r['gap']:.3f}%"
        out.append(f"{r['file'][:28]:28s} {r['formulation']:11s} {r['saving_pct']:9.2f} "
                   f"{r['instruction_lines']:7d} {r['size_change_pct']:8.2f} {r['added_time_pct']:8.3f} "
                   f"{r['rotation_deg']:8.3f} {r['status']:>11s} {gap:>9s} {r['solve_s']:8.3f} "
                   f"{'yes' if r['verified'] else 'NO':>8s}")
    return "\n".join(out)


def plot_compare(rows: list[dict], path: str, ordering: bool = False) -> None:
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


def compare_order_rows(program, options, formulations, budget_s: float, workers: int) -> list[dict]:
    """``compare --ordering``: one row per curve-ordering formulation (greedy, the Fleming et al.
    baseline, first), each a verified run with ``budget_s`` for the whole of it (nothing written)."""
    from ..rewrite.order import order_program

    def solve_row(name):
        r = order_program(program, options, formulation=name, budget_s=budget_s, workers=workers)
        s = r.summary
        row = {k: s[k] for k in ("travel_before_mm", "travel_after_mm", "travel_change_pct",
                                 "model_travel_after_mm", "print_time_before_s", "print_time_after_s",
                                 "groups_reordered", "groups_optimal", "groups_feasible",
                                 "groups_fallback", "worst_gap", "solve_s", "wall_s")}
        row["verified"] = bool(r.ok)
        if not r.ok:
            row["findings"] = [str(f) for f in r.findings[:3]]
        return row
    return formulation_rows(program, formulations, ORDER_FORMULATIONS, solve_row)


def format_compare_order(rows: list[dict]) -> str:
    head = (f"{'file':28s} {'formulation':11s} {'travel mm':>11s} {'travel %':>9s} {'print s':>10s} "
            f"{'optimal':>8s} {'feasible':>8s} {'fallback':>8s} {'worst gap':>9s} {'run s':>7s} {'verified':>8s}")
    out = [head, "-" * len(head)]
    for r in rows:
        if "travel_after_mm" not in r:
            out.append(f"{r['file'][:28]:28s} {r['formulation']:11s} {r['status']:>11s}   {r.get('error', '')[:60]}")
            continue
        gap = "n/a" if r["worst_gap"] is None else f"{100 * r['worst_gap']:.2f}%"
        out.append(f"{r['file'][:28]:28s} {r['formulation']:11s} {r['travel_after_mm']:11,.1f} "
                   f"{r['travel_change_pct']:9.2f} {r['print_time_after_s']:10,.1f} {r['groups_optimal']:8d} "
                   f"{r['groups_feasible']:8d} {r['groups_fallback']:8d} {gap:>9s} {r['wall_s']:7.2f} "
                   f"{'yes' if r['verified'] else 'NO':>8s}")
    if rows and "travel_before_mm" in rows[0]:
        out.append("travel % is against the slicer's order; groups: proven optimal / feasible at the "
                   "limit / fallback (heuristic); worst gap to the group's lower bound")
    return "\n".join(out)


def run_compare(args) -> int:
    forms = [f.strip() for f in (args.formulations or ",".join(
        ORDER_FORMULATIONS if args.ordering else FORMULATION_NAMES)).split(",") if f.strip()]
    check_distinct({"--plot": args.plot, "--json": args.json})
    if args.ordering and not (math.isfinite(args.order_budget) and args.order_budget > 0):
        raise GatesoptError(f"--order-budget must be > 0 s, not {args.order_budget}")
    if args.plot:
        check_new_file(args.plot, args.files, args.force, png=True)
    if args.json:
        check_new_file(args.json, args.files, args.force)
    rows = []
    if args.ordering:
        from ..ordering import OrderingOptions
        from .ordering import default_workers
        order_options = OrderingOptions(mode=args.order_mode, move_seams=args.move_seams)
        for path in args.files:
            rows += compare_order_rows(parse(path), order_options, forms, args.order_budget,
                                       default_workers())
        print(format_compare_order(rows))
    else:
        options = options_from_args(args)
        for path in args.files:
            program = parse(path)
            rows += compare_rows(program, options, forms, args.time_limit)
        print(format_compare(rows))
    if args.plot:
        plot_compare(rows, args.plot, ordering=args.ordering)
    if args.json:
        write_atomic(args.json, json.dumps(rows, indent=2, default=_jsonable) + "\n")
    bad = [r for r in rows if "verified" in r and not r["verified"]]
    return 1 if bad else 0
