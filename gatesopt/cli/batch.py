"""``gatesopt batch``: many files through solve + verify, one row each, on a process pool or Dask."""
from __future__ import annotations

import os
import sys

from ..batch import STDIN_FILE, BatchOptions, expand_paths, output_name, run_batch, summarize
from ..errors import GatesoptError
from .files import check_input, check_new_file, check_one_stdin, refuse_existing
from .progress import default_workers, pause_status, resume_status, wants_progress
from .options import (BUDGET_NOT_GIVEN, add_firmware_options, gating_formulations, motor_list,
                      number_or_none, positive_s, printer_config)

NAME = "batch"
HELP = "solve + verify many files, one result row each (CSV or JSON)"
DESCRIPTION = ("Run every file (and every file in every folder) through ordering + gating + verify; "
               "write one row per file. A failing file becomes an error row and never stops the others.")


def add_arguments(p) -> None:
    p.add_argument("paths", nargs="+", metavar="PATH",
                   help="G-code files or folders (the .gcode/.gcode.gz/.gco/.g files in them); - for "
                        "one file on standard input")
    p.add_argument("--formulation", default="dp", metavar="F[,F...]",
                   help="gating formulation, or several separated by commas, one row each "
                        f"({', '.join(gating_formulations())}; default dp)")
    add_firmware_options(p)
    p.add_argument("--motors", default=None, metavar="X,Y",
                   help="motors to gate, comma separated (default X,Y, or what the firmware may gate "
                        "of them; Z and E opt-in)")
    p.add_argument("--rotate", default="auto", metavar="auto|none|DEG",
                   help="rotate the model on the bed, as `solve --rotate` (default auto: only on a "
                        "known bed the rotated print fits)")
    p.add_argument("--bed", default=None, metavar="WxD",
                   help="bed size in mm for every file, as `solve --bed` (default: the bed each file names; a "
                        "file that names none is not rotated)")
    p.add_argument("--max-added-time-pct", type=number_or_none, default=BUDGET_NOT_GIVEN, metavar="P|none",
                   help="budget: the print takes at most P %% longer than the file as given (planner "
                        "model; default: 1 for stock firmware, none for the paper's), as `solve`")
    p.add_argument("--max-added-lines-pct", type=float, metavar="P", help="budget: at most P %% more lines")
    p.add_argument("--time-limit", type=float, default=60.0, metavar="S",
                   help="gating solver time limit per file in seconds (milp, cpsat; default 60), "
                        "within --budget")
    p.add_argument("--no-order", action="store_true", help="do not re-order curves")
    p.add_argument("--order-mode", choices=("safe", "free"), default="safe",
                   help="as `solve --order-mode`: safe keeps the slicer's feature groups, walls and "
                        "objects (default); free re-orders every curve of a layer (ironing keeps "
                        "its place)")
    p.add_argument("--budget", type=float, default=10.0, metavar="S",
                   help="finish each file's run in about S seconds (default 10, as `solve --budget`: "
                        "every solve included: the curve ordering gets what an estimate of the rest "
                        "leaves, an exact --formulation what is left of it, at most --time-limit)")
    p.add_argument("--no-gating", action="store_true", help="do not insert gating instructions")
    p.add_argument("--profile", default="paper", metavar="NAME|TOML",
                   help="energy profile: shipped name or TOML file (default: paper)")
    p.add_argument("--jobs", "-j", type=int, default=1, metavar="N", help="worker processes (default 1)")
    p.add_argument("--dask", metavar="ADDRESS", help="run on a Dask cluster: tcp://HOST:8786, or 'local'")
    p.add_argument("--out", required=True, metavar="RESULTS.csv|RESULTS.json",
                   help="results file: .csv (appended as rows finish) or .json")
    p.add_argument("--resume", action="store_true", help="skip files already in --out")
    p.add_argument("--write-dir", metavar="DIR",
                   help="write each verified output file into this folder (never over an input; an "
                        "existing file only with --force or --resume)")
    p.add_argument("--force", action="store_true",
                   help="overwrite an existing --out without --resume, and existing files in --write-dir")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args) -> int:
    check_one_stdin(args.paths)
    for path in args.paths:
        if path != STDIN_FILE and not os.path.isdir(path):
            check_input(path)
    files = expand_paths(args.paths)
    if not files:
        raise GatesoptError(f"no G-code files in {', '.join(args.paths)}")
    if args.jobs < 1:
        raise GatesoptError(f"--jobs must be at least 1, not {args.jobs}")
    positive_s(args.budget, "--budget")
    positive_s(args.time_limit, "--time-limit")
    if not args.out.lower().endswith((".csv", ".json")):
        raise GatesoptError(f"--out {args.out}: a results file ends in .csv (rows appended as they "
                            "finish) or .json")
    refuse_existing(args.out, args.resume or args.force, "use --resume to continue it or --force to start over")
    check_new_file(args.out, files, True)       # not an input, its folder exists
    if args.write_dir:
        _check_write_dir(args.write_dir, files, args.force or args.resume)
    forms = tuple(f.strip() for f in args.formulation.split(",") if f.strip())
    unknown = [f for f in forms if f not in gating_formulations()]
    if unknown or not forms:
        raise GatesoptError(f"--formulation {args.formulation!r}: choose from {', '.join(gating_formulations())}")
    bed = None
    if args.bed:
        try:
            bed = tuple(float(v) for v in args.bed.lower().split("x"))
        except ValueError:
            raise GatesoptError(f"--bed must look like 220x220, not {args.bed!r}") from None
    budget = args.max_added_time_pct
    printer_config(args)        # a printer.cfg that cannot be read: one error now, not one per file
    opts = BatchOptions(formulation=forms[0], firmware=args.force_firmware or args.firmware,
                        force_firmware=args.force_firmware is not None, bed_size_mm=bed,
                        motors=None if args.motors is None else motor_list(args.motors), rotate=args.rotate,
                        max_added_time_pct="default" if budget is BUDGET_NOT_GIVEN else budget,
                        max_added_lines_pct=args.max_added_lines_pct,
                        time_limit_s=args.time_limit, order=not args.no_order, gating=not args.no_gating,
                        profile=args.profile, write_dir=args.write_dir, order_mode=args.order_mode,
                        budget_s=args.budget, printer_config=args.printer_config,
                        # one file at a time: its ordering may use both cores, as `solve` does
                        order_workers=default_workers() if args.jobs <= 1 and not args.dask else 1)
    stdin_data = sys.stdin.buffer.read() if STDIN_FILE in files else None
    bar = not args.quiet and wants_progress()
    if bar:
        pause_status()          # the bar over the files is the progress line from here on
    try:
        rows = run_batch(files, opts, out=args.out, jobs=args.jobs, resume=args.resume, dask=args.dask,
                         progress=bar, formulations=forms, stdin_data=stdin_data)
    finally:
        if bar:
            resume_status()
    s = summarize(rows)
    for r in rows:
        for w in filter(None, str(r.get("warnings") or "").split(" | ")):
            print(f"gatesopt: warning: {w}", file=sys.stderr)
        if r.get("error"):
            err = r["error"] if r["error"].startswith(r["file"]) else f"{r['file']}: {r['error']}"
            print(f"gatesopt: {err}", file=sys.stderr)
    print(f"{s['files']} rows: {s['verified']} verified, {s['errors']} errors; mean saving "
          f"{s['mean_saving_pct']:.1f} %, max {s['max_saving_pct']:.1f} %; results in {args.out}")
    return 0 if s["errors"] == 0 else 1


def _check_write_dir(folder: str, files: list[str], force: bool) -> None:
    """Before any work: the outputs ``--write-dir`` would hold replace no input, no two inputs
    share an output name, and an existing file is replaced only with ``force``."""
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise GatesoptError(f"--write-dir {folder}: exists and is not a folder")
    seen = {}
    for f in files:
        out = os.path.join(folder, output_name(f))
        key = os.path.abspath(out)
        if key in seen:
            raise GatesoptError(f"--write-dir {folder}: {seen[key]} and {f} would both be written to {out}")
        seen[key] = f
        if f != STDIN_FILE and os.path.exists(out) and os.path.samefile(f, out):
            raise GatesoptError(f"--write-dir {folder}: {out} is an input file; write elsewhere")
        if os.path.exists(out) and not force:
            raise GatesoptError(f"{out}: exists; pass --force to overwrite it (or --resume)")
