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


def add_gating_options(p) -> None:
    """The options of a gating run (``solve``, ``compare``)."""
    p.add_argument("--firmware", choices=firmware_names(), default="3dgates",
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


def gating_options(args):
    """``gatesopt.gating.GatingOptions`` from the options of ``add_gating_options``."""
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
