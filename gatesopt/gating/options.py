"""Gating options: what to gate, how the firmware behaves, and the budgets.

3DGates (Chen et al., ASPLOS'17) Section 4.2 gives the defaults: Start-Ahead 1.8 ms (NEMA 17
start-up delay) and End-Late 1.0 ms (empirical stop delay). Firmware numbers (stall per motor line,
whether re-enable needs a line, whether motors share a line, a firmware that times its own
switches: ``schedule``, the time model) are plain values here; ``GatingOptions.for_firmware(name)``
fills them from the dialect in ``gatesopt.firmware`` (and the printer's Klipper config, if given).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from .. import firmware as fw_mod
from ..errors import GatesoptError
from ..firmware import Schedule
from ..printer_config import PrinterConfig
from ..program import AXES

TIME_MODELS = ("paper", "planner")


class GatingOptionsError(GatesoptError, ValueError):
    """Bad gating options (unknown motor, negative time, ...)."""


@dataclass(frozen=True)
class GatingOptions:
    """What to gate, how the firmware behaves, and the budgets.

    Firmware numbers are plain numbers here; ``GatingOptions.for_firmware(name)`` fills them from
    the presets in ``gatesopt.firmware``.
    """

    motors: tuple[str, ...] = ("X", "Y")
    start_ahead_s: float = 1.8e-3       # 3DGates Sec. 4.2: NEMA 17 start-up delay
    end_late_s: float = 1.0e-3          # 3DGates Sec. 4.2: empirical stop delay
    rotate: str | float = "auto"        # "auto" | "none" | degrees (counter-clockwise)
    max_angles: int = 16                # cap on rotation candidates under "auto" (plus 0/30/60)
    snap_mm: float = 1e-3               # other-axis displacement below this -> single-axis move
    bed_size_mm: tuple[float, float] | None = None   # None: the bed the file names (rotation.bed_of);
                                        # no bed known: no rotation (issue 37)
    bed: object = None                  # a ``slicers.Bed`` read from the user's file, given by a caller
                                        # that gates a rewritten copy (re-ordered: other line numbers)
    bed_margin_mm: float | None = None  # a rotated print's least distance to the bed's edges (None:
                                        # rotation.BED_MARGIN_MM, or less where the slicer kept less)
    min_rotation_gain_pct: float = 0.5  # under rotate="auto" a rotation must save this much energy
                                        # more than 0 deg (% of the 0 deg answer's), else the print
                                        # stays as the slicer placed it (rewrite.run; issue 37)
    max_rotation_added_time_pct: float | None = None   # under rotate="auto" a rotation may make the
                                        # print (its first extrusion to its end, on the time model)
                                        # at most this much longer, else it stays (rewrite.run; the
                                        # klipper-gating dialect: issue 34's 0.05 %); None: no limit
    check_bed: bool = True              # False: rotations are not checked against a bed (a model
                                        # experiment, e.g. ``report.rotation_sweep``: nothing printed)
    profile: str = "paper"              # energy profile name or TOML path
    firmware: str = "3dgates"           # label only (the numbers below are what the solver uses)
    stall_off_s: float = 0.0            # stall per off line (whole printer keeps drawing power)
    stall_on_s: float = 0.0             # stall per on line
    on_line: bool = True                # re-enable needs a line (False: automatic at the first step)
    merge_lines: bool = True            # instructions of several motors at one moment share a line
    split_moves: str = "all"            # moves a line may split: "all" | "kinematic" (not extrude-only)
                                        # | "none"; else it goes before / after the whole move
    max_added_time_pct: float | None = None    # budget on stall time, % of the print time
    max_added_lines_pct: float | None = None   # budget on added lines, % of the file's lines
    num_workers: int = 2                # CP-SAT workers
    seed: int = 0                       # CP-SAT random seed
    mip_rel_gap: float = 1e-6           # MILP/CP-SAT relative gap at which to stop
    neighbour_mm: float = 0.5           # greedy grouping threshold (3DGates Algorithm 1 neigh_t)
    shared_enable: tuple = ()           # groups of motors wired to one enable pin, e.g. (("X", "Y"),)
    schedule: Schedule | None = None    # the firmware times its own switches (``firmware.Schedule``):
                                        # the off line goes right after the motors' last step
    time_model: str = "paper"           # "paper": T = L / F (3DGates Eq. 2); "planner": gatesopt.planner
    planner_family: str | None = None   # the planner's rules ("klipper"; None: limits.default_family)
    printer: PrinterConfig | None = None  # the printer's Klipper config: planner limits, shaper

    def __post_init__(self):
        motors = tuple(str(m).upper() for m in self.motors)
        bad = [m for m in motors if m not in AXES]
        if bad or not motors or len(set(motors)) != len(motors):
            raise GatingOptionsError(f"motors must be distinct letters of {','.join(AXES)}, not "
                                     f"{','.join(self.motors) or 'nothing'}")
        object.__setattr__(self, "motors", tuple(m for m in AXES if m in motors))
        for name in ("start_ahead_s", "end_late_s", "stall_off_s", "stall_on_s", "snap_mm"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise GatingOptionsError(f"{name} must be a finite number >= 0, not {v!r}")
        for name in ("max_added_time_pct", "max_added_lines_pct", "bed_margin_mm", "min_rotation_gain_pct",
                     "max_rotation_added_time_pct"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v >= 0):
                raise GatingOptionsError(f"{name} must be >= 0 or None, not {v!r}")
        r = self.rotate
        if isinstance(r, str) and r not in ("auto", "none"):
            try:
                r = float(r)
            except ValueError:
                raise GatingOptionsError(f"rotate must be 'auto', 'none' or degrees, not {r!r}") from None
            object.__setattr__(self, "rotate", r)
        if not isinstance(self.rotate, str) and not math.isfinite(float(self.rotate)):
            raise GatingOptionsError(f"rotate must be finite, not {self.rotate!r}")
        if self.bed_size_mm is not None:
            b = tuple(float(v) for v in self.bed_size_mm)
            if len(b) != 2 or min(b) <= 0:
                raise GatingOptionsError(f"bed_size_mm must be two positive numbers, not {self.bed_size_mm!r}")
            object.__setattr__(self, "bed_size_mm", b)
        if self.max_angles < 1:
            raise GatingOptionsError("max_angles must be >= 1")
        groups, seen = [], set()
        for grp in self.shared_enable:
            g = tuple(m for m in AXES if m in {str(x).upper() for x in grp})
            if len(g) < 2 or len(g) != len(tuple(grp)) or seen & set(g):
                raise GatingOptionsError(f"shared_enable groups must be disjoint sets of 2+ motors of "
                                         f"{','.join(AXES)}, not {grp!r}")
            inside = [m for m in g if m in self.motors]
            if inside and len(inside) != len(g):
                raise GatingOptionsError(f"motors {','.join(g)} share one enable pin: gate all of them or none")
            seen |= set(g)
            groups.append(g)
        object.__setattr__(self, "shared_enable", tuple(groups))
        if self.split_moves not in fw_mod.SPLIT_MOVES:
            raise GatingOptionsError(f"split_moves must be one of {', '.join(fw_mod.SPLIT_MOVES)}, "
                                     f"not {self.split_moves!r}")
        if self.time_model not in TIME_MODELS:
            raise GatingOptionsError(f"time_model must be one of {', '.join(TIME_MODELS)}, not {self.time_model!r}")
        if self.schedule is not None:
            if self.on_line or not self.merge_lines or self.stall_off_s or self.stall_on_s or self.shared_enable:
                raise GatingOptionsError("a firmware that times its own switches (schedule) writes one off "
                                         "line per moment, no on line, no stall, one pin per motor")

    def off_margin_s(self, m: int) -> float:
        """Seconds from the end of motor ``m``'s last step to its off: end-late, plus the
        firmware's own delay when it times its switches (``schedule``)."""
        extra = self.schedule.off_delay_s[m] if self.schedule is not None else 0.0
        return self.end_late_s + extra

    def on_margin_s(self, m: int) -> float:
        """Seconds from motor ``m``'s on to its next step: start-ahead (0 when the firmware
        re-enables at the step itself, no on line), plus the firmware's own lead (``schedule``)."""
        if self.schedule is not None:
            return self.start_ahead_s + self.schedule.on_lead_s[m]
        return self.start_ahead_s if self.on_line else 0.0

    @property
    def motor_index(self) -> tuple[int, ...]:
        return tuple(AXES.index(m) for m in self.motors)

    @property
    def groups(self) -> tuple[tuple[int, ...], ...]:
        """Gated motors by enable pin: each a tuple of axis indices, its first the representative
        that carries the group's idle intervals (a motor with its own pin is a group of one)."""
        out = []
        for m in self.motors:
            grp = next((g for g in self.shared_enable if m in g), (m,))
            if grp[0] == m:
                out.append(tuple(AXES.index(x) for x in grp))
        return tuple(out)

    @property
    def has_budget(self) -> bool:
        return self.max_added_time_pct is not None or self.max_added_lines_pct is not None

    def replace(self, **changes) -> "GatingOptions":
        return dataclasses.replace(self, **changes)

    @classmethod
    def for_firmware(cls, firmware: str = "3dgates", *, printer: PrinterConfig | None = None,
                     **changes) -> "GatingOptions":
        """Options with the numbers of a ``gatesopt.firmware`` dialect: stalls and lines, its own
        timing of the switches (``Firmware.schedule``), its time model, the moves its lines may
        split (``split_moves``) and its ``start_lead_s`` (steps before a move's nominal start, added
        to the start-ahead). ``printer``: the
        printer's Klipper config (``gatesopt.printer_config``): the planner's limits, the input
        shaper's step window, the options a firmware module reads there (``gating_defaults``: a
        value in ``changes`` that disagrees with it is an error; None in ``changes``: not given)."""
        fw = fw_mod.get(firmware)
        c = fw_mod.gating_costs(fw)
        kw = dict(firmware=c.firmware, stall_off_s=c.stall_off_s, stall_on_s=c.stall_on_s,
                  on_line=c.on_lines_per_gate > 0, merge_lines=c.off_lines_merged,
                  time_model=fw.time_model, planner_family=fw.planner.family if fw.planner else None,
                  printer=printer, split_moves=fw.split_moves,
                  max_rotation_added_time_pct=fw.rotation_max_added_time_pct)
        defaults = dict(fw.gating_defaults(printer))
        gateable = defaults.pop("gateable", None)
        for k, v in defaults.items():
            given = changes.get(k)
            if given is not None and abs(float(given) - float(v)) > 1e-12:
                raise fw_mod.FirmwareError(f"{k} = {given:g} disagrees with the printer config "
                                           f"{printer.source} ({v:g}), which the firmware uses")
        kw.update(defaults)
        kw.update({k: v for k, v in changes.items() if v is not None})
        kw["start_ahead_s"] = kw.get("start_ahead_s", cls.start_ahead_s) + fw.start_lead(printer)
        opts = cls(**kw)
        fw.check_motors(opts.motors)
        if gateable is not None and not set(opts.motors) <= set(gateable):
            raise fw_mod.FirmwareError(f"{printer.source}: [gatesopt_gating] steppers lets the module gate "
                                       f"{','.join(gateable)} only, not {','.join(opts.motors)}")
        schedule = fw.schedule(printer, start_ahead_s=opts.start_ahead_s, end_late_s=opts.end_late_s)
        if schedule is not None:
            opts = opts.replace(schedule=schedule)
        return opts
