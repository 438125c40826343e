"""``gatesopt verify ORIG OUT``: the independent checks of ``gatesopt.verify``; exit 0 only if all hold."""
from __future__ import annotations

import json
import sys

from ..errors import GatesoptError
from .files import check_input, check_one_stdin, read_bytes, read_program
from .options import add_printer_config_option, firmware_names, printer_config

NAME = "verify"
HELP = "check a rewritten file against its original"
DESCRIPTION = ("Re-parse both files and check: extruded geometry per layer (after undoing a declared "
               "rotation), E per layer, every move's end point (as written or rotated; a relative "
               "move from the rotated print by the rotated delta), control commands in order, added "
               "motor lines in the firmware's dialect, motor timing (start-ahead, end-late), and "
               "energy/time against a claimed report. Exit 0 only if all hold.")


def add_arguments(p) -> None:
    p.add_argument("original", help="the original G-code (- for standard input)")
    p.add_argument("output", help="the rewritten G-code (- for standard input)")
    p.add_argument("--firmware", choices=("auto",) + firmware_names(), default="auto",
                   help="firmware the output is meant for (its motor-instruction dialect, the motors "
                        "it may gate, stall times, automatic re-enable); auto: the claimed report's, else "
                        "the dialect the original names (as solve reads it) where it takes every motor "
                        "line the rewrite added, else the dialect of those lines")
    p.add_argument("--start-ahead-ms", type=float, default=1.8,
                   help="a motor must be on at least this long before it steps (default 1.8, paper)")
    p.add_argument("--end-late-ms", type=float, default=1.0,
                   help="a motor must stay on at least this long after it steps (default 1.0, paper)")
    p.add_argument("--profile", default="paper", metavar="NAME|TOML", help="energy profile")
    p.add_argument("--reordered", action="store_true",
                   help="the output re-orders curves (default: detected from its header)")
    p.add_argument("--claimed", metavar="REPORT.json",
                   help="a `gatesopt solve --json` report: energy_after_j and time_after_s must match")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    add_printer_config_option(p)


def run(args) -> int:
    from ..verify import verify
    check_one_stdin([args.original, args.output, args.claimed])
    for path in (args.original, args.output) + ((args.claimed,) if args.claimed else ()):
        check_input(path)
    claimed = _read_claimed(args.claimed) if args.claimed else None
    original = read_program(args.original)
    output = read_program(args.output)
    from ..rewrite.figures import print_times
    from ..rewrite.printer import NOT_GATED
    from ..verify.firmware import firmware_of
    printer = printer_config(args)
    # the one detection `solve` and `profile` name the file's firmware by (``firmware_of``)
    name, firmware, gated = firmware_of(original, output, printer)
    given = args.firmware if args.firmware != "auto" else (claimed or {}).get("firmware")
    if given and given != NOT_GATED:
        name = firmware = given
    rep = verify(original, output, firmware=firmware, start_ahead_s=args.start_ahead_ms / 1e3,
                 end_late_s=args.end_late_ms / 1e3, claimed=claimed, profile=args.profile,
                 reordered=True if args.reordered else None, printer=printer)
    before_s, after_s = print_times(original, output, firmware, gated, printer)
    if args.json:
        json.dump({**rep.to_dict(), "firmware": name, "print_time_before_s": before_s,
                   "print_time_after_s": after_s, "print_time_model": "planner",
                   "paper_time_before_s": rep.time_before_s, "paper_time_after_s": rep.time_s},
                  sys.stdout, indent=2)
        print()
        return 0 if rep.ok else 1
    from ..rewrite.figures import ENERGY_WORDS, PRINT_TIME_WORDS, pct
    print(f"checks        {', '.join(rep.checks)}   (firmware: {name})")
    print(f"energy        {rep.energy_before_j:.1f} J -> {rep.energy_j:.1f} J   saving {rep.saving_pct:.2f} %"
          f"   ({ENERGY_WORDS})")
    # two time models, each named (realsweep P10: the paper's time can rise where the print falls)
    print(f"print time    {before_s:,.1f} s -> {after_s:,.1f} s   ({pct(after_s, before_s):+.1f} %; "
          f"{PRINT_TIME_WORDS})")
    print(f"paper time    {rep.time_before_s:,.2f} s -> {rep.time_s:,.2f} s   "
          f"({pct(rep.time_s, rep.time_before_s):+.1f} %; the paper's T = L/F, stalls {rep.stall_s:.2f} s "
          "included: what the energy integrates over, not the print time)")
    print(f"lines         {rep.lines_before} -> {rep.lines_after}   bytes {rep.bytes_before} -> {rep.bytes_after}")
    if rep.rotate_deg:
        print(f"rotation      {rep.rotate_deg:g} deg about ({rep.center_mm[0]:g}, {rep.center_mm[1]:g})")
    if rep.ok:
        print("verified      all checks hold")
        return 0
    print(f"verified      FAILED ({len(rep.findings)} finding(s))")
    for f in rep.findings:
        print(f"  {f}")
    return 1


def _read_claimed(path: str) -> dict:
    """The JSON report of ``gatesopt solve --json`` at ``path``."""
    try:
        claimed = json.loads(read_bytes(path).decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise GatesoptError(f"{path}: not a JSON report of gatesopt solve --json ({exc})") from None
    if not isinstance(claimed, dict):
        raise GatesoptError(f"{path}: not a JSON report of gatesopt solve --json (no object)")
    return claimed
