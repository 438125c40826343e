"""``gatesopt batch``: many files through solve + verify, one row each, on a process pool or Dask."""
from __future__ import annotations

import sys

from ..batch import BatchOptions, run_batch, summarize
from .files import refuse_existing
from .options import BUDGET_NOT_GIVEN, add_firmware_options, budget_pct, motor_list
from .progress import default_workers

NAME = "batch"
HELP = "solve + verify many files, one result row each (CSV or JSON)"
DESCRIPTION = ("Run every file (and every file in every folder) through ordering + gating + verify; "
               "write one row per file. A failing file becomes an error row and never stops the others.")


def add_arguments(p) -> None:
    p.add_argument("paths", nargs="+", help="G-code files or folders")
    p.add_argument("--formulation", default="dp",
                   help="gating formulation, or several separated by commas (greedy,dp,milp)")
    add_firmware_options(p)
    p.add_argument("--motors", default=None)
    p.add_argument("--rotate", default="auto")
    p.add_argument("--bed", default=None, metavar="WxD",
                   help="bed size in mm for every file (default: the bed each file names; none: no rotation)")
    p.add_argument("--max-added-time-pct", type=budget_pct, default=BUDGET_NOT_GIVEN, metavar="P|none")
    p.add_argument("--max-added-lines-pct", type=float)
    p.add_argument("--time-limit", type=float, default=60.0, help="seconds per solve")
    p.add_argument("--no-order", action="store_true")
    p.add_argument("--no-gating", action="store_true")
    p.add_argument("--profile", default="paper")
    p.add_argument("--jobs", "-j", type=int, default=1, help="worker processes (default 1)")
    p.add_argument("--dask", metavar="ADDRESS", help="run on a Dask cluster: tcp://HOST:8786, or 'local'")
    p.add_argument("--out", required=True, help="results file: .csv (appended as rows finish) or .json")
    p.add_argument("--resume", action="store_true", help="skip files already in --out")
    p.add_argument("--write-dir", help="write each verified output file into this folder")
    p.add_argument("--force", action="store_true", help="overwrite an existing --out without --resume")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args) -> int:
    refuse_existing(args.out, args.resume or args.force, "use --resume to continue it or --force to start over")
    forms = tuple(f.strip() for f in args.formulation.split(",") if f.strip())
    bed = None
    if args.bed:
        from ..errors import GatesoptError
        try:
            bed = tuple(float(v) for v in args.bed.lower().split("x"))
        except ValueError:
            raise GatesoptError(f"--bed must look like 220x220, not {args.bed!r}") from None
    opts = BatchOptions(formulation=forms[0], firmware=args.force_firmware or args.firmware,
                        force_firmware=args.force_firmware is not None, bed_size_mm=bed,
                        motors=None if args.motors is None else motor_list(args.motors), rotate=args.rotate,
                        max_added_time_pct="default" if args.max_added_time_pct is BUDGET_NOT_GIVEN else args.max_added_time_pct, max_added_lines_pct=args.max_added_lines_pct,
                        time_limit_s=args.time_limit, order=not args.no_order, gating=not args.no_gating,
                        profile=args.profile, write_dir=args.write_dir,
                        # one file at a time: its ordering may use both cores, as `solve` does
                        order_workers=default_workers() if args.jobs <= 1 and not args.dask else 1)
    rows = run_batch(args.paths, opts, out=args.out, jobs=args.jobs, resume=args.resume, dask=args.dask,
                     progress=not args.quiet and sys.stderr.isatty(), formulations=forms)
    s = summarize(rows)
    for r in rows:
        if r.get("error"):
            err = r["error"] if r["error"].startswith(r["file"]) else f"{r['file']}: {r['error']}"
            print(f"gatesopt: {err}", file=sys.stderr)
    print(f"{s['files']} rows: {s['verified']} verified, {s['errors']} errors; mean saving "
          f"{s['mean_saving_pct']:.1f} %, max {s['max_saving_pct']:.1f} %; results in {args.out}")
    return 0 if s["errors"] == 0 else 1
