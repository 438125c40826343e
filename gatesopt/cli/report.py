"""``gatesopt report``: a self-contained HTML page (and PNGs) from batch results."""
from __future__ import annotations

import os
from pathlib import Path

from ..batch import read_rows
from ..errors import GatesoptError
from ..report import rotation_sweep, write_report
from .files import refuse_existing

NAME = "report"
HELP = "HTML report with the papers' figures from batch results"
DESCRIPTION = ("Draw the 3DGates and Fleming et al. figures from the rows of `gatesopt batch` into "
               "one self-contained HTML file.")


def add_arguments(p) -> None:
    p.add_argument("results", help="results file written by gatesopt batch (.csv or .json)")
    p.add_argument("-o", "--output", required=True, help="HTML file to write")
    p.add_argument("--png", metavar="DIR", help="also write each figure as a PNG into DIR")
    p.add_argument("--sweep", action="append", default=[], metavar="GCODE",
                   help="draw Fig. 14 from a 30° rotation sweep of this file (repeat for two models)")
    p.add_argument("--title", default="gatesopt results")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")


def run(args) -> int:
    if not os.path.exists(args.results):
        raise GatesoptError(f"{args.results}: no such results file")
    refuse_existing(args.output, args.force, "use --force to overwrite")
    rows = read_rows(args.results)
    sweeps = {Path(s).name: rotation_sweep(s) for s in args.sweep} or None
    pngs = write_report(rows, args.output, png_dir=args.png, sweeps=sweeps, title=args.title)
    print(f"report written to {args.output}" + (f" and {len(pngs)} PNGs to {args.png}" if pngs else ""))
    return 0
