"""Options several commands share: the choices the library's registries offer, the gating options
(``solve``, ``compare``), and checks of option values.

The choices are read from the registries, never copied here: a firmware preset, a gating or an
ordering formulation added to the library is a choice of every command that takes one. A command's
options are added only when that command runs (``cli.build_parser``), so a command does not import
another's registries.
"""
from __future__ import annotations

import math

from ..errors import GatesoptError


def firmware_names() -> tuple[str, ...]:
    """The firmware dialects (``gatesopt.firmware.names``: one module each)."""
    from ..firmware import names
    return names()


def gating_formulations() -> tuple[str, ...]:
    """The gating formulations (``gatesopt.gating.solve.FORMULATIONS``)."""
    from ..gating.solve import FORMULATIONS
    return tuple(FORMULATIONS)


def ordering_formulations() -> tuple[str, ...]:
    """The curve ordering's formulations a command offers (``gatesopt.ordering.FORMULATIONS``):
    those that take groups of any size (``dp`` takes only small ones: the library's, for tests
    and bounds)."""
    from ..ordering import FORMULATIONS
    return tuple(name for name, f in FORMULATIONS.items() if "any_size" in f.capabilities)


def positive_s(value: float, flag: str) -> None:
    """``value`` (seconds, given as ``flag``) is finite and > 0."""
    if not (math.isfinite(value) and value > 0):
        raise GatesoptError(f"{flag} must be > 0 s, not {value}")


def number_or_none(text: str):
    """A number, or "none" (``--max-added-time-pct``, ``order --budget``: no budget)."""
    import argparse
    if str(text).strip().lower() == "none":
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a number or none, not {text!r}") from None


class _NotGiven:
    def __repr__(self) -> str:
        return "the firmware's default"


#: ``--max-added-time-pct`` not given: the firmware's default (``rewrite.printer.choose``); not a
#: string, which argparse would pass through ``number_or_none``
BUDGET_NOT_GIVEN = _NotGiven()


DEFAULT_START_AHEAD_MS = 1.8     # 3DGates Sec. 4.2
DEFAULT_END_LATE_MS = 1.0


def add_firmware_options(p) -> None:
    """``--firmware`` (auto: read from the file) and ``--force-firmware`` (``solve``, ``compare``,
    ``batch``)."""
    p.add_argument("--firmware", choices=("auto",) + firmware_names(), default="auto",
                   help="the printer's firmware, whose motor on/off lines gating writes (default auto: "
                        "read from the file's flavor setting, printer model and Klipper commands, and "
                        "said; marlin when the file names none). 3dgates (the paper's S0/S1) only by name")
    p.add_argument("--force-firmware", choices=firmware_names(), default=None, metavar="NAME",
                   help="write NAME's lines even where the file is for another firmware (refused "
                        "without it: marlin's M18 on a Klipper file stops the print)")
    add_printer_config_option(p)


def add_printer_config_option(p) -> None:
    """``--printer-config`` (``solve``, ``compare``, ``batch``, ``verify``)."""
    p.add_argument("--printer-config", default=None, metavar="printer.cfg",
                   help="the printer's Klipper config, read by --firmware klipper-gating: the input "
                        "shaper (its step window widens each switch's margins) and the [gatesopt_gating] "
                        "section (start_ahead, end_late, min_off_time, steppers)")


def printer_config(args):
    """The ``--printer-config`` file read (``gatesopt.printer_config``), or None."""
    path = getattr(args, "printer_config", None)
    if not path:
        return None
    from ..printer_config import read_printer_config
    return read_printer_config(path)


def add_gating_options(p) -> None:
    """The options of a gating run (``solve``, ``compare``)."""
    add_firmware_options(p)
    p.add_argument("--motors", default=None, metavar="X,Y",
                   help="motors to gate, comma separated (default X,Y, or what the firmware may gate "
                        "of them; Z and E opt-in)")
    p.add_argument("--rotate", default="auto", metavar="auto|none|DEG",
                   help="rotate the model on the bed: auto (best angle), none, or degrees ccw "
                        "(a print of objects one at a time is never rotated)")
    p.add_argument("--start-ahead-ms", type=float, default=DEFAULT_START_AHEAD_MS,
                   help="switch a motor on at least this long before it steps (default 1.8, paper)")
    p.add_argument("--end-late-ms", type=float, default=DEFAULT_END_LATE_MS,
                   help="keep a motor on at least this long after it steps (default 1.0, paper)")
    p.add_argument("--max-added-time-pct", type=number_or_none, default=BUDGET_NOT_GIVEN, metavar="P|none",
                   help="budget: the print takes at most P %% longer than the file as given (its print "
                        "time as every report gives it, planner model; re-ordering, rotation and "
                        "stalls together) (default: 1 for firmware whose motor lines stall the print, "
                        "Marlin, Klipper, RepRapFirmware; none for the paper's); none: no budget")
    p.add_argument("--max-added-lines-pct", type=float, default=None, metavar="P",
                   help="budget: at most P %% more lines")
    p.add_argument("--time-limit", type=float, default=60.0, metavar="S",
                   help="time limit of the gating solves together, rotation search included "
                        "(milp, cpsat; default 60); in `solve` and `batch` within --budget, which "
                        "covers the whole run")
    p.add_argument("--profile", default="paper", metavar="NAME|TOML",
                   help="energy profile: shipped name or TOML file (default: paper)")
    p.add_argument("--threads", type=int, default=2, metavar="N",
                   help="solver threads (default 2); 1 makes every run byte-identical (seeds are fixed)")
    p.add_argument("--bed", default=None, metavar="WxD",
                   help="bed size in mm, from 0,0: a rotation must fit it (default: the bed the file "
                        "names; Cura files name none, and without a bed the print is not rotated)")
    p.add_argument("--bed-margin", type=float, default=None, metavar="MM",
                   help="a rotated print keeps this far from the bed's edges (default 5, or what the "
                        "slicer's own placement kept where that is less)")


def firmware_choice(args, program, **gating):
    """``rewrite.printer.choose`` for ``program`` from ``--firmware``/``--force-firmware``,
    ``--max-added-time-pct`` and ``--motors`` (given or not), with ``gating`` (GatingOptions fields)."""
    from ..rewrite.printer import DEFAULT, choose
    budget = getattr(args, "max_added_time_pct", BUDGET_NOT_GIVEN)
    motors = None if args.motors is None else motor_list(args.motors)
    forced = getattr(args, "force_firmware", None)
    printer = printer_config(args)
    if printer is not None:
        gating.setdefault("printer", printer)
        if printer.gating is not None:
            # the module's [gatesopt_gating] options win over the command line's defaults (a value
            # given that disagrees with them is refused by ``GatingOptions.for_firmware``)
            for key, default_s in (("start_ahead_s", DEFAULT_START_AHEAD_MS / 1e3),
                                   ("end_late_s", DEFAULT_END_LATE_MS / 1e3)):
                if gating.get(key) == default_s:
                    gating[key] = None
    return choose(program, forced or args.firmware, force=forced is not None,
                  max_added_time_pct=DEFAULT if budget is BUDGET_NOT_GIVEN else budget,
                  motors=motors, **gating)


def motor_list(text: str) -> tuple:
    motors = tuple(m.strip().upper() for m in text.split(",") if m.strip())
    if not motors:
        raise GatesoptError("--motors names no motor")
    return motors


def gating_options(args) -> dict:
    """The ``GatingOptions`` fields of ``add_gating_options`` other than the firmware, the time
    budget and the motors (``firmware_choice`` decides those per file)."""
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
    if args.bed_margin is not None and not (math.isfinite(args.bed_margin) and args.bed_margin >= 0):
        raise GatesoptError(f"--bed-margin must be >= 0 mm, not {args.bed_margin}")
    return dict(rotate=rotate, start_ahead_s=args.start_ahead_ms / 1e3, end_late_s=args.end_late_ms / 1e3,
                max_added_lines_pct=args.max_added_lines_pct, profile=args.profile, bed_size_mm=bed,
                bed_margin_mm=args.bed_margin, num_workers=args.threads)
