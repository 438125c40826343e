"""``gatesopt calibrate``: fit a component energy profile from a power-meter log of a print."""
from __future__ import annotations

import sys

from ..calibrate import fit, read_power_log
from ..planner import TIME_MODELS, durations
from .files import STDIO, check_input, check_new_file, check_one_stdin, read_program, write_atomic

NAME = "calibrate"
HELP = "fit an energy profile to a power-meter log of a real print"
DESCRIPTION = ("Align a power-meter log (CSV: time in s or ISO date-time, watts) with a print's "
               "timeline and fit a component energy profile by least squares; writes a TOML profile "
               "usable with --profile.")


def add_arguments(p) -> None:
    p.add_argument("--gcode", required=True, help="the G-code that was printed (- for standard input)")
    p.add_argument("--power-log", required=True,
                   help="CSV of (time, watts) samples (- for standard input)")
    p.add_argument("-o", "--output", required=True, metavar="PROFILE.toml", help="profile TOML to write")
    p.add_argument("--prior", default="component_example",
                   help="component profile to start from and to keep what the log cannot determine")
    p.add_argument("--offset-s", type=float, default=None,
                   help="where the print starts on the log's clock (default: found by correlation)")
    p.add_argument("--time-model", choices=TIME_MODELS, default="planner",
                   help="the print's timeline: planner (acceleration and junction limits; default) "
                        "or paper (T = L/F)")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")


def run(args) -> int:
    check_one_stdin([args.gcode, args.power_log])
    check_input(args.gcode)
    check_input(args.power_log, "power log")
    check_new_file(args.output, [args.gcode, args.power_log], args.force)
    program = read_program(args.gcode)
    log = read_power_log(sys.stdin if args.power_log == STDIO else args.power_log,
                         source="<stdin>" if args.power_log == STDIO else None)
    dur = durations(program, model=args.time_model)
    cal = fit(program, log, prior=args.prior, duration_s=dur, offset_s=args.offset_s)
    write_atomic(args.output, cal.profile_toml)
    print(f"aligned: print starts at {cal.offset_s:.1f} s on the log, log/model time ratio {cal.time_scale:.3f}")
    print(f"fit over {cal.n_samples} samples: mean abs error {100 * cal.rel_error:.1f} % of mean power, "
          f"energy error {100 * cal.energy_error:.2f} % (the 3DGates paper validated its model at 3.0 %)")
    for k, v in cal.params.items():
        note = "" if cal.identifiable[k] else "   (not identifiable alone from this print: kept from the prior, or fitted only as a sum with a motor switched together)"
        print(f"  {k:15s} {v:9.3f} W{note}")
    print(f"profile written to {args.output}", file=sys.stderr)
    return 0
