"""``gatesopt report``: a self-contained HTML page (and PNGs) from batch results."""
from __future__ import annotations

import sys
from pathlib import Path

from ..batch import parse_rows, read_rows
from ..errors import GatesoptError
from ..report import rotation_sweep, write_report
from .files import STDIO, STDIN_NAME, check_input, check_new_file, check_one_stdin, read_program

NAME = "report"
HELP = "HTML report with the papers' figures from batch results"
DESCRIPTION = ("Draw the 3DGates and Fleming et al. figures from the rows of `gatesopt batch` into "
               "one self-contained HTML file.")


def add_arguments(p) -> None:
    p.add_argument("results", help="results file written by gatesopt batch (.csv or .json), or - "
                                   "for standard input")
    p.add_argument("-o", "--output", required=True, metavar="REPORT.html", help="HTML file to write")
    p.add_argument("--png", metavar="DIR", help="also write each figure as a PNG into DIR")
    p.add_argument("--sweep", action="append", default=[], metavar="GCODE",
                   help="draw Fig. 14 from a rotation sweep of this G-code file, at the angles "
                        "--rotate auto tries (repeat for more models)")
    p.add_argument("--title", default="gatesopt results", help="the page's title")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file or PNGs")


def run(args) -> int:
    check_one_stdin([args.results, *args.sweep])
    for path in (args.results, *args.sweep):
        check_input(path)
    check_new_file(args.output, [args.results, *args.sweep], args.force)
    if args.results == STDIO:
        rows = parse_rows(sys.stdin.read(), STDIN_NAME)
    else:
        rows = read_rows(args.results)
    if not rows:
        raise GatesoptError(f"{args.results}: no result rows to report")
    if args.png:
        if Path(args.png).exists() and not Path(args.png).is_dir():
            raise GatesoptError(f"{args.png}: exists and is not a folder (--png DIR)")
    sweeps = {}
    for s in args.sweep:
        program = read_program(s)
        sweeps[Path(program.source).name] = rotation_sweep(program)
    pngs = write_report(rows, args.output, png_dir=args.png, sweeps=sweeps or None, title=args.title,
                        overwrite=args.force)
    print(f"report written to {args.output}" + (f" and {len(pngs)} PNGs to {args.png}" if pngs else ""))
    return 0
