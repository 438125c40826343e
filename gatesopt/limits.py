"""Machine limits: what the firmware's planner is allowed to do, read from the G-code file itself.

Sources, in the order a value is taken (each value records which one it came from):

1. lines of the file that set limits -- Marlin ``M201`` (max acceleration per axis), ``M203`` (max
   feedrate per axis), ``M204`` (print/retract/travel acceleration), ``M205`` (classic jerk X Y Z E,
   minimum feedrates S T, minimum segment time B, junction deviation J), RepRapFirmware ``M566``
   (jerk in mm/min), Klipper ``SET_VELOCITY_LIMIT`` (VELOCITY, ACCEL, ACCEL_TO_DECEL,
   SQUARE_CORNER_VELOCITY). A line applies from its own line on, as in the firmware: a file that
   switches ``M204 P800`` / ``M204 P1000`` per feature gets per-step accelerations;
2. the slicer's configuration block (PrusaSlicer / SuperSlicer / OrcaSlicer / Bambu Studio write
   ``; machine_max_acceleration_x = 1000`` etc. at the end of the file; a value "a,b" is the normal
   and the silent mode: we take the normal one). ``machine_limits_usage = ignore`` means the slicer
   did not use them, so neither do we;
3. a printer profile default (``PRINTER_DEFAULTS``): the firmware's stock configuration, or a
   printer definition recognised from the header (Cura's Creality Ender-3 and Prusa i3 MK3
   definitions, whose machine settings Cura's own estimator uses).

Units: accelerations mm/s^2 (``_mm_s2``), speeds mm/s, times s; axis order X Y Z E.

``MachineLimits`` carries the values in force at the first motion step (what a report shows) and
``changes``: the later lines, so that ``per_step(program)`` gives the value in force at every step.
"""
from __future__ import annotations

import re
import weakref
from dataclasses import dataclass, field

import numpy as np

from . import firmware, slicers
from .errors import GatesoptError
from .headers import PREFIX as GATESOPT_PREFIX
from .program import MOTION_KINDS, Program

# The flat parameter vector: one name per scalar limit. ``MachineLimits`` exposes them as typed
# fields; ``KEYS`` orders the columns of ``per_step``.
KEYS = (
    "max_accel_x", "max_accel_y", "max_accel_z", "max_accel_e",
    "max_feed_x", "max_feed_y", "max_feed_z", "max_feed_e",
    "jerk_x", "jerk_y", "jerk_z", "jerk_e",
    "accel_print", "accel_travel", "accel_retract", "accel_to_decel",
    "junction_deviation", "square_corner_velocity", "max_velocity",
    "min_segment_time", "min_feed", "min_travel_feed", "min_cruise_ratio",
)
K = {k: i for i, k in enumerate(KEYS)}
INF = float("inf")

# Stock firmware configurations (each dialect's ``PlannerRules.defaults``, ``gatesopt.firmware``:
# "marlin", "klipper", "reprap") and known printer definitions. Sources of the printer rows:
# - "creality_ender3" / "prusa_i3_mk3" / "cura_fdmprinter": Cura's machine definitions
#   (Ultimaker/Cura resources/definitions creality_base.def.json, prusa_i3_mk3.def.json,
#   fdmprinter.def.json: machine_max_feedrate_*, machine_max_acceleration_*, machine_acceleration,
#   machine_max_jerk_xy/z/e), the limits Cura's own estimator runs with (fdmprinter's
#   299792458000 mm/s "no limit" feedrates are written as inf).
PRINTER_DEFAULTS: dict[str, dict[str, float]] = {
    **{f: dict(firmware.planner_rules(f).defaults) for f in firmware.planner_families()},
    "creality_ender3": dict(max_accel_x=500, max_accel_y=500, max_accel_z=100, max_accel_e=5000,
                            max_feed_x=500, max_feed_y=500, max_feed_z=10, max_feed_e=50,
                            jerk_x=10, jerk_y=10, jerk_z=0.4, jerk_e=5,
                            accel_print=500, accel_travel=500, accel_retract=500, accel_to_decel=INF,
                            junction_deviation=np.nan, square_corner_velocity=np.nan, max_velocity=INF,
                            min_segment_time=0.0, min_feed=0.0, min_travel_feed=0.0, min_cruise_ratio=0.0),
    # Cura's fdmprinter.def.json default_value entries: what CuraEngine run from the command line
    # uses (the CLI does not evaluate a definition's "value" formulas), and so what Cura's own
    # estimate assumes for a file sliced that way
    "cura_fdmprinter": dict(max_accel_x=9000, max_accel_y=9000, max_accel_z=100, max_accel_e=10000,
                            max_feed_x=INF, max_feed_y=INF, max_feed_z=INF, max_feed_e=INF,
                            jerk_x=20, jerk_y=20, jerk_z=0.4, jerk_e=5,
                            accel_print=4000, accel_travel=4000, accel_retract=4000, accel_to_decel=INF,
                            junction_deviation=np.nan, square_corner_velocity=np.nan, max_velocity=INF,
                            min_segment_time=0.0, min_feed=0.0, min_travel_feed=0.0, min_cruise_ratio=0.0),
    # prusa_i3_mk3.def.json: fdmprinter plus default_value overrides machine_acceleration 1000,
    # machine_max_acceleration_z 500, machine_max_feedrate_z 12 / _e 120, machine_max_jerk_xy 10,
    # _z 0.2, _e 2.5 (default_value entries, so the CLI applies them too)
    "prusa_i3_mk3": dict(max_accel_x=9000, max_accel_y=9000, max_accel_z=500, max_accel_e=10000,
                         max_feed_x=INF, max_feed_y=INF, max_feed_z=12, max_feed_e=120,
                         jerk_x=10, jerk_y=10, jerk_z=0.2, jerk_e=2.5,
                         accel_print=1000, accel_travel=1000, accel_retract=1000, accel_to_decel=INF,
                         junction_deviation=np.nan, square_corner_velocity=np.nan, max_velocity=INF,
                         min_segment_time=0.0, min_feed=0.0, min_travel_feed=0.0, min_cruise_ratio=0.0),
}
# Which junction rule each default uses: Marlin 2 stock is junction deviation; the printer
# definitions above (and Prusa / Creality firmware) use classic jerk.
DEFAULT_JUNCTION = {**{f: firmware.planner_rules(f).junction for f in firmware.planner_families()},
                    "cura_fdmprinter": "jerk", "creality_ender3": "jerk", "prusa_i3_mk3": "jerk"}


@dataclass(frozen=True, eq=False)
class MachineLimits:
    """Planner limits in force at the first motion step, with their sources and later changes."""

    firmware: str                       # "marlin" | "klipper" | "reprap": whose planner rules apply
    junction: str                       # "jerk" (classic, Marlin/Prusa) | "deviation" (Marlin 2 JD) | "scv" (Klipper)
    max_accel_mm_s2: np.ndarray         # (4,) X Y Z E, per-axis acceleration limit (M201)
    max_feed_mm_s: np.ndarray           # (4,) per-axis feedrate limit (M203)
    jerk_mm_s: np.ndarray               # (4,) classic jerk: max instantaneous speed change (M205 X Y Z E / M566)
    accel_print_mm_s2: float            # M204 P (S)
    accel_travel_mm_s2: float           # M204 T (Marlin 2), = print on firmwares without one
    accel_retract_mm_s2: float          # M204 R: extruder-only moves
    accel_to_decel_mm_s2: float         # Klipper max_accel_to_decel (inf: none set in the file)
    junction_deviation_mm: float        # Marlin 2 JD (M205 J) / machine_max_junction_deviation
    square_corner_velocity_mm_s: float  # Klipper square_corner_velocity
    max_velocity_mm_s: float            # Klipper max_velocity (caps every move's speed)
    min_segment_time_s: float           # Marlin M205 B (us -> s); 0: not modelled / none
    min_feed_mm_s: float                # M205 S: minimum printing feedrate
    min_travel_feed_mm_s: float         # M205 T: minimum travel feedrate
    min_cruise_ratio: float             # Klipper minimum_cruise_ratio (0: none; with max_accel_to_decel)
    source: dict = field(default_factory=dict)   # key (see KEYS, plus firmware/junction) -> where it came from
    changes: tuple = ()                 # ((line, key, value), ...) applied from that line on, after the first motion
    profile: str = ""                   # which PRINTER_DEFAULTS row filled the gaps

    def vector(self) -> np.ndarray:
        """The values as one float vector in ``KEYS`` order."""
        v = np.empty(len(KEYS))
        v[0:4], v[4:8], v[8:12] = self.max_accel_mm_s2, self.max_feed_mm_s, self.jerk_mm_s
        v[12:] = (self.accel_print_mm_s2, self.accel_travel_mm_s2, self.accel_retract_mm_s2,
                  self.accel_to_decel_mm_s2, self.junction_deviation_mm,
                  self.square_corner_velocity_mm_s, self.max_velocity_mm_s, self.min_segment_time_s,
                  self.min_feed_mm_s, self.min_travel_feed_mm_s, self.min_cruise_ratio)
        return v

    def regimes(self) -> tuple[np.ndarray, np.ndarray]:
        """``(change_line, table)``: row r of ``table`` (len(KEYS) columns) is in force from
        ``change_line[r-1]`` (row 0 from the start); a step on line l uses row
        ``searchsorted(change_line, l, 'right')``."""
        rows = [self.vector()]
        lines = []
        for line, key, value in self.changes:
            row = rows[-1].copy()
            row[K[key]] = value
            if lines and lines[-1] == line:
                rows[-1] = row
            else:
                rows.append(row)
                lines.append(line)
        return np.asarray(lines, dtype=np.int64), np.vstack(rows)

    def regimes_at(self, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(table, regime)``: the table of ``regimes`` and, per file line of ``line`` (steps'
        ``Program.line``), the row of it in force there (int64)."""
        change_line, table = self.regimes()
        return table, np.searchsorted(change_line, line, side="right").astype(np.int64)

    def per_step(self, program: Program) -> np.ndarray:
        """(n_steps, len(KEYS)): the limits in force at each step."""
        table, regime = self.regimes_at(program.line)
        return table[regime]

    def with_values(self, **values) -> "MachineLimits":
        """A copy with some scalar limits replaced everywhere (keys as in ``KEYS``)."""
        v = self.vector()
        for k, x in values.items():
            v[K[k]] = x
        changes = tuple(c for c in self.changes if c[1] not in values)
        src = dict(self.source, **{k: "override" for k in values})
        return _from_vector(v, self.firmware, self.junction, src, changes, self.profile)

    def describe(self) -> list[str]:
        """Human-readable lines: each value with its source."""
        v = self.vector()
        out = [f"firmware {self.firmware}, junction rule {self.junction} ({self.source.get('junction', '')})"]
        for i, k in enumerate(KEYS):
            out.append(f"{k} = {v[i]:g}  [{self.source.get(k, '')}]")
        if self.changes:
            out.append(f"{len(self.changes)} changes after the first motion step")
        return out


def _from_vector(v, firmware, junction, source, changes, profile) -> MachineLimits:
    return MachineLimits(
        firmware=firmware, junction=junction,
        max_accel_mm_s2=v[0:4].copy(), max_feed_mm_s=v[4:8].copy(), jerk_mm_s=v[8:12].copy(),
        accel_print_mm_s2=float(v[12]), accel_travel_mm_s2=float(v[13]),
        accel_retract_mm_s2=float(v[14]), accel_to_decel_mm_s2=float(v[15]),
        junction_deviation_mm=float(v[16]), square_corner_velocity_mm_s=float(v[17]),
        max_velocity_mm_s=float(v[18]), min_segment_time_s=float(v[19]),
        min_feed_mm_s=float(v[20]), min_travel_feed_mm_s=float(v[21]), min_cruise_ratio=float(v[22]),
        source=source, changes=tuple(changes), profile=profile)


# ------------------------------------------------------------------------------------------------
# reading the file
_CONFIG_RE = re.compile(rb"^; *(machine_[a-z_]+|gcode_flavor|xy_accel_mm_per_s_per_s) *= *([^\r\n]*)", re.M)
#: the commands that set the planner's limits (the emitter re-issues those in force at a rebuilt
#: travel: ``ordering.layout.link_travel_steps``)
LIMIT_COMMANDS = ("M201", "M203", "M204", "M205", "M566", "SET_VELOCITY_LIMIT")
_CMD_RE = re.compile(rb"^[ \t]*(?:N\d+[ \t]*)?(" + "|".join(LIMIT_COMMANDS).encode() + rb")"
                     rb"(?![0-9A-Za-z_.])([^;\r\n]*)", re.M | re.I)
_WORD_RE = re.compile(rb"([A-Za-z])[ \t]*([-+]?(?:\d+\.?\d*|\.\d+))")
_KLIPPER_PARAM_RE = re.compile(rb"([A-Za-z_]+)[ \t]*=[ \t]*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")
_FLAVOR_RE = re.compile(rb"^;FLAVOR:([^\r\n]*)", re.M)
_FIRMWARE_RE = re.compile(rb"^;Firmware: *([^\r\n]*)", re.M)     # ideaMaker
_CURA_MACHINE_RE = re.compile(rb"^;TARGET_MACHINE\.NAME:([^\r\n]*)", re.M)

_CONFIG_MAP = {
    "machine_max_acceleration_x": "max_accel_x", "machine_max_acceleration_y": "max_accel_y",
    "machine_max_acceleration_z": "max_accel_z", "machine_max_acceleration_e": "max_accel_e",
    "machine_max_feedrate_x": "max_feed_x", "machine_max_feedrate_y": "max_feed_y",
    "machine_max_feedrate_z": "max_feed_z", "machine_max_feedrate_e": "max_feed_e",
    "machine_max_jerk_x": "jerk_x", "machine_max_jerk_y": "jerk_y",
    "machine_max_jerk_z": "jerk_z", "machine_max_jerk_e": "jerk_e",
    "machine_max_acceleration_extruding": "accel_print",
    "machine_max_acceleration_travel": "accel_travel",
    "machine_max_acceleration_retracting": "accel_retract",
    "machine_max_junction_deviation": "junction_deviation",
    "machine_min_extruding_rate": "min_feed", "machine_min_travel_rate": "min_travel_feed",
}
# KISSlicer's single XY acceleration (its config block): print and travel acceleration
_KISS_ACCEL = "xy_accel_mm_per_s_per_s"


def _first_number(text: str) -> float | None:
    try:
        return float(text.split(",")[0].strip())
    except ValueError:
        return None


_HEAD_BYTES, _TAIL_BYTES = 262144, 524288   # where slicers put their config blocks


def _ends(data: bytes) -> list[tuple[bytes, int]]:
    """The head and the tail of the file (config blocks live there), as (chunk, offset)."""
    if len(data) <= _HEAD_BYTES + _TAIL_BYTES:
        return [(data, 0)]
    start = len(data) - _TAIL_BYTES
    start = data.find(b"\n", start) + 1 or start
    return [(data[:_HEAD_BYTES], 0), (data[start:], start)]


def _config(data: bytes) -> dict[str, str]:
    out = {}
    for chunk, _ in _ends(data):
        for m in _CONFIG_RE.finditer(chunk):
            out.setdefault(m.group(1).decode(), m.group(2).decode("utf-8", "replace"))
    return out


#: program -> its ``_limit_commands``, for as long as the program lives: a run plans one program
#: several times (the print time before, the gating problem, the figures), each reading its
#: limit lines (0.23 s a time on a 28 MB file)
_COMMANDS: "weakref.WeakKeyDictionary[Program, list]" = weakref.WeakKeyDictionary()


def _limit_commands(program: Program) -> list:
    """``(line, match)`` for each limit-setting line (M201/M203/M204/M205/M566/SET_VELOCITY_LIMIT).
    Read once per program (``_COMMANDS``; the list is not to be changed by callers)."""
    got = _COMMANDS.get(program)
    if got is None:
        got = _COMMANDS[program] = _read_limit_commands(program)
    return got


def _read_limit_commands(program: Program) -> list:
    """``_limit_commands`` read: the parser's per-line command columns, when present, say which
    lines to read."""
    data, ls = program.data, program.line_start
    letter = getattr(program, "line_letter", None)
    number = getattr(program, "line_number", None)
    if letter is None or number is None or len(letter) != program.n_lines:
        found = list(_CMD_RE.finditer(data))
        lines = np.searchsorted(ls, [m.start() for m in found], side="right") - 1
        return list(zip(lines.tolist(), found))
    cand = np.flatnonzero(((letter == ord("M")) & np.isin(number, (201, 203, 204, 205, 566)))
                          | (letter == 64))
    out = []
    match = _CMD_RE.match
    for i in cand.tolist():
        m = match(data, ls[i], ls[i + 1])
        if m is not None:
            out.append((i, m))
    return out


def _flavor(data: bytes) -> str:
    """The slicer's firmware flavor, lower case ('' if none)."""
    m = None
    for chunk, _ in _ends(data):
        m = m or re.search(rb"^; *gcode_flavor *= *([^\r\n]*)", chunk, re.M)
    if m is None:
        m = _FLAVOR_RE.search(data, 0, 4096) or _FIRMWARE_RE.search(data, 0, 8192)
    return m.group(1).decode("ascii", "replace").strip().lower() if m else ""


def _printer_profile(data: bytes, firmware: str) -> tuple[str, str]:
    """(PRINTER_DEFAULTS key, why) for the values the file does not give."""
    head = data[:20000]
    while head.startswith(GATESOPT_PREFIX.encode()):
        # gatesopt's own header lines on a file it rewrote: the slicer's header follows (a
        # CuraEngine file starts with ";FLAVOR:"; re-ordered, it got Marlin's stock junction
        # deviation instead of Cura's classic jerk, so its print time before and after were
        # planned under different rules)
        head = head.split(b"\n", 1)[1] if b"\n" in head else b""
    if b";Generated with Cura" in head or head.startswith(b";FLAVOR:"):
        m = _CURA_MACHINE_RE.search(head)
        if m is not None:       # the Cura front-end names the machine definition it evaluated
            name = m.group(1).decode("ascii", "replace").lower()
            if "creality" in name or "ender" in name:
                return "creality_ender3", f"Cura machine {name!r}: Creality base definition"
            if "mk3" in name or "prusa" in name:
                return "prusa_i3_mk3", f"Cura machine {name!r}"
            return "cura_fdmprinter", f"Cura machine {name!r} not known: fdmprinter defaults"
        if b"G80 ; mesh bed leveling" in head:
            return "prusa_i3_mk3", "Cura header without machine name, Prusa i3 MK3 start G-code"
        return "cura_fdmprinter", "Cura header without machine name: fdmprinter defaults (CuraEngine CLI)"
    return firmware, f"stock {firmware} configuration"


def _line_sets(m, rules, mm_min: bool, legacy_m204: bool, printer) -> tuple[list[tuple[str, float]], bool]:
    """What one limit line of the file sets: ``(key, value)`` pairs in this module's units, and
    whether it set a junction deviation (``M205 J``). Each firmware's reading: Klipper's
    SET_VELOCITY_LIMIT and M204 (S, else min(P, T)), Marlin's legacy and current M204, M203 in
    mm/min where the firmware says so, RepRapFirmware's M566 jerk in mm/min."""
    cmd = m.group(1).upper()
    sets: list[tuple[str, float]] = []
    sets_jd = False
    if cmd == b"SET_VELOCITY_LIMIT":
        p = {k.upper(): float(x) for k, x in _KLIPPER_PARAM_RE.findall(m.group(2))}
        if b"ACCEL" in p:
            sets += [("accel_print", p[b"ACCEL"]), ("accel_travel", p[b"ACCEL"]),
                     ("accel_retract", p[b"ACCEL"])]
        if b"ACCEL_TO_DECEL" in p and printer is None:
            sets.append(("accel_to_decel", p[b"ACCEL_TO_DECEL"]))
        if b"MINIMUM_CRUISE_RATIO" in p:
            sets.append(("min_cruise_ratio", p[b"MINIMUM_CRUISE_RATIO"]))
        if b"SQUARE_CORNER_VELOCITY" in p:
            sets.append(("square_corner_velocity", p[b"SQUARE_CORNER_VELOCITY"]))
        if b"VELOCITY" in p:
            sets.append(("max_velocity", p[b"VELOCITY"]))
    else:
        w = {k.upper(): float(x) for k, x in _WORD_RE.findall(m.group(2))}
        if cmd == b"M201":
            sets += [(f"max_accel_{a.lower()}", w[a.encode()]) for a in "XYZE" if a.encode() in w]
        elif cmd == b"M203":
            f = 1 / 60 if mm_min else 1.0
            sets += [(f"max_feed_{a.lower()}", w[a.encode()] * f) for a in "XYZE" if a.encode() in w]
        elif cmd == b"M566":
            sets += [(f"jerk_{a.lower()}", w[a.encode()] / 60) for a in "XYZE" if a.encode() in w]
        elif cmd == b"M204":
            if rules.m204 == "klipper":
                # Klipper's M204: S sets max_accel; else min(P, T) when both are given; P or T
                # alone is answered 'Invalid M204 command' and changes nothing (klippy/toolhead.py
                # ToolHeadCommandHelper.cmd_M204): PrusaSlicer's per-feature "M204 P800" lines
                acc = w.get(b"S", min(w[b"P"], w[b"T"]) if b"P" in w and b"T" in w else INF)
                if acc < INF:
                    sets += [("accel_print", acc), ("accel_travel", acc), ("accel_retract", acc)]
            elif b"S" in w:
                # legacy format (Marlin 1 / Prusa firmware): S print (and travel), T retract
                sets += [("accel_print", w[b"S"]), ("accel_travel", w[b"S"])]
                if b"T" in w:
                    sets.append(("accel_retract" if legacy_m204 or b"P" not in w else "accel_travel", w[b"T"]))
            else:
                if b"P" in w:
                    sets.append(("accel_print", w[b"P"]))
                if b"R" in w:
                    sets.append(("accel_retract", w[b"R"]))
                if b"T" in w:
                    sets.append(("accel_travel", w[b"T"]))
        elif cmd == b"M205":
            if b"X" in w:   # Marlin: X sets both X and Y jerk
                sets += [("jerk_x", w[b"X"]), ("jerk_y", w[b"X"])]
            if b"Y" in w:
                sets.append(("jerk_y", w[b"Y"]))
            if b"Z" in w:
                sets.append(("jerk_z", w[b"Z"]))
            if b"E" in w:
                sets.append(("jerk_e", w[b"E"]))
            if b"S" in w:
                sets.append(("min_feed", w[b"S"]))
            if b"T" in w:
                sets.append(("min_travel_feed", w[b"T"]))
            if b"B" in w:
                sets.append(("min_segment_time", w[b"B"] * 1e-6))
            if b"J" in w:
                sets.append(("junction_deviation", w[b"J"]))
                sets_jd = True
    return sets, sets_jd


def _apply_config(config: dict, v: np.ndarray, source: dict[str, str], rules, junction: str) -> str:
    """The slicer's config block over the defaults (``v`` and ``source`` updated in place);
    returns the junction model it implies (classic jerk or junction deviation, where the
    firmware's rules let the config choose)."""
    usage = config.get("machine_limits_usage", "").strip()
    if usage != "ignore":
        for key, name in _CONFIG_MAP.items():
            if key in config:
                x = _first_number(config[key])
                if x is None:
                    continue
                if name == "accel_travel" and x == 0:   # 0: "same as extruding" (PrusaSlicer)
                    continue
                if name == "junction_deviation" and x <= 0:
                    continue
                v[K[name]] = x
                source[name] = f"config: {key}"
        if _KISS_ACCEL in config:
            x = _first_number(config[_KISS_ACCEL])
            if x and x > 0:
                for name in ("accel_print", "accel_travel"):
                    v[K[name]] = x
                    source[name] = f"config: {_KISS_ACCEL}"
        if rules.jerk_is_scv and "machine_max_jerk_x" in config:
            # OrcaSlicer writes a Klipper printer's jerk as SET_VELOCITY_LIMIT SQUARE_CORNER_VELOCITY
            x = _first_number(config["machine_max_jerk_x"])
            if x:
                v[K["square_corner_velocity"]] = x
                source["square_corner_velocity"] = "config: machine_max_jerk_x (Klipper SCV)"
        if rules.config_picks_junction and any(k.startswith("machine_max_jerk") for k in config):
            junction = "jerk"
            source["junction"] = "config: machine_max_jerk_* (classic jerk)"
        if rules.config_picks_junction and "machine_max_junction_deviation" in config:
            x = _first_number(config["machine_max_junction_deviation"])
            if x and x > 0:
                junction = "deviation"
                source["junction"] = "config: machine_max_junction_deviation"
    return junction


def default_family(program: Program) -> tuple[str, str]:
    """(planner rules, why) a file is planned by when no one chose: those of the dialect
    ``gatesopt solve --firmware auto`` writes for it (``slicers.read_printer``, read once per
    program: a Klipper command, a printer model, the slicer's flavor setting;
    ``firmware.DIALECT_OF_FAMILY``), so that every command plans one file by one family (an
    ideaMaker file with PRINT_START, Marlin-flavoured: 1,223.7 s by Marlin's rules in ``profile``
    and ``order``, 1,308.6 s by Klipper's in ``solve``). A file that names no firmware gatesopt
    has a dialect for (none, Bambu Lab's, Repetier, ...): its flavor, Klipper with a
    ``SET_VELOCITY_LIMIT`` line, else Marlin."""
    ev = slicers.program_printer(program).firmware
    dialect = firmware.DIALECT_OF_FAMILY.get(ev.family) if ev is not None else None
    rules = firmware.get(dialect).planner if dialect is not None else None
    if rules is not None:
        return rules.family, f"{ev.kind} {ev.where()}: {ev.why}"
    flavor = _flavor(program.data)
    said = f"flavor {flavor!r}" if flavor else "default (no flavor)"
    if "klipper" in flavor or any(m.group(1).upper() == b"SET_VELOCITY_LIMIT"
                                  for _, m in _limit_commands(program)):
        return "klipper", said
    if "reprapfirmware" in flavor or flavor == "rrf":
        # RepRapFirmware (M203 in mm/min, M566 jerk). Slic3r's "reprap" flavor is RepRap/Sprinter,
        # i.e. Marlin-like firmware: planned as Marlin.
        return "reprap", said
    return "marlin", said


def machine_limits(program: Program, profile: str | None = None, *, family: str | None = None,
                   printer=None) -> MachineLimits:
    """Planner limits for ``program``: file lines, then the slicer's config block, then defaults.

    ``profile`` names a ``PRINTER_DEFAULTS`` row for the values the file does not give (default:
    recognised from the header, else the firmware's stock configuration). ``family``: the planner
    rules ("marlin", "klipper", "reprap"; default: ``default_family``, those ``gatesopt solve``
    plans the file by).

    ``printer``: the printer's Klipper config (``gatesopt.printer_config.PrinterConfig``): the
    machine is known, so its values replace the defaults, the slicer's config block (what the
    slicer assumed) is not read, and of the file's lines only those Klipper carries out apply
    (``M204`` and ``SET_VELOCITY_LIMIT`` without the ``ACCEL_TO_DECEL`` that Klipper 84104bb no
    longer has; ``M201``/``M203``/``M205`` are unknown commands there).
    """
    v, source, junction, reading = _settings_limits(program, profile, family, printer)
    changes, jd_from_line = reading.apply(program, v, source)
    return reading.finish(v, source, junction, changes, jd_from_line)


@dataclass(frozen=True, eq=False)
class _Reading:
    """How one file's limit lines read (``machine_limits``): its planner rules, M203's unit,
    Marlin's legacy M204, and the config block's caps on the accelerations lines ask for."""

    rules: object               # firmware.PlannerRules
    family: str
    profile: str
    mm_min: bool
    legacy_m204: bool
    caps: dict
    printer: object = None

    def lines(self, program: Program):
        """Per limit line of ``program``: (line, [(key, value) capped], sets junction deviation,
        its text)."""
        cmds = _limit_commands(program)
        if self.printer is not None:
            cmds = [(line, m) for line, m in cmds
                    if m.group(1).upper() in (b"M204", b"SET_VELOCITY_LIMIT")]
        # a line's reading depends on its text alone: a slicer repeats a few texts (PrusaSlicer's
        # per-feature "M204 P800": 43,000 lines of a 28 MB file, ~1 s a reading)
        read: dict[bytes, tuple] = {}
        for line, m in cmds:
            key = m.group(0)
            got = read.get(key)
            if got is None:
                sets, jd = _line_sets(m, self.rules, self.mm_min, self.legacy_m204, self.printer)
                sets = [(k, min(x, self.caps[k]) if self.caps.get(k, 0) > 0 else x) for k, x in sets]
                got = read[key] = (sets, jd, key.decode("utf-8", "replace").strip())
            yield line, got[0], got[1], got[2]

    def apply(self, program: Program, v, source, initial: bool = True) -> tuple[list, bool]:
        """Source 1 of the module docstring: ``program``'s limit lines before its first motion
        step set the values in force there (``v``, ``source`` in place; none with ``initial``
        False: a later piece of a file, ``PieceLimits``), the later ones are returned as
        ``changes``; and whether a line set a junction deviation."""
        motion = np.isin(program.kind, np.asarray(MOTION_KINDS, dtype=program.kind.dtype))
        first_motion_line = int(program.line[motion][0]) if motion.any() else program.n_lines
        if not initial:
            first_motion_line = -1
        changes: list[tuple[int, str, float]] = []
        jd_from_line = False
        for line, sets, jd, text in self.lines(program):
            jd_from_line |= jd
            for key, x in sets:
                if line < first_motion_line:
                    v[K[key]] = x
                    source[key] = f"line {line + 1}: {text}"
                else:
                    changes.append((line, key, x))
        return changes, jd_from_line

    def finish(self, v, source, junction: str, changes, jd_from_line: bool) -> MachineLimits:
        """The limits from the values ``v`` in force at the first motion and the later
        ``changes``: the junction model the lines and the values imply."""
        if jd_from_line and self.rules.config_picks_junction:
            junction = "deviation"
            source["junction"] = "M205 J (junction deviation)"
        if junction == "jerk" and np.isnan(v[K["jerk_x"]]):
            junction = "deviation"
        if junction == "scv" and np.isnan(v[K["square_corner_velocity"]]):
            # a printer profile without one (Cura's definitions) planned by Klipper's rules:
            # Klipper's own default (klippy/toolhead.py square_corner_velocity 5.0); NaN would
            # leave every junction speed undefined
            v[K["square_corner_velocity"]] = self.rules.defaults.get("square_corner_velocity", 5.0)
            source["square_corner_velocity"] = (f"default: {self.family} (the {self.profile} "
                                                "profile has none)")
        return _from_vector(v, self.family, junction, source, changes, self.profile)


#: program -> {(profile, family, printer): ``_read_settings``}: what a program's settings say
#: (its header, config block and flavor) is read once, and a re-ordered copy of it shares its
#: original's (``same_settings``): the time guard plans several copies of a file, each read
#: ~0.04 s on 200,000 lines
_SETTINGS: "weakref.WeakKeyDictionary[Program, dict]" = weakref.WeakKeyDictionary()


def same_settings(copy: Program, program: Program) -> None:
    """``copy``, parsed from a re-ordered copy of ``program``'s text (its header, config block
    and every line naming the printer kept, the same limit lines re-issued), has ``program``'s
    printer facts (``slicers.same_printer``) and settings, not read again."""
    slicers.same_printer(copy, program)
    _SETTINGS[copy] = _SETTINGS.setdefault(program, {})


def _settings_limits(program: Program, profile, family, printer):
    """Sources 3 and 2 of the module docstring (defaults, then the slicer's config block; the
    printer's config where given): ``(values, sources, junction model, _Reading)``, the values
    and sources the caller's to change (``_SETTINGS``)."""
    key = (profile, family, printer)
    try:
        hash(key)
    except TypeError:           # (a printer config holding a list: read every time)
        return _read_settings(program, profile, family, printer)
    memo = _SETTINGS.setdefault(program, {})
    got = memo.get(key)
    if got is None:
        got = memo[key] = _read_settings(program, profile, family, printer)
    v, source, junction, reading = got
    return v.copy(), dict(source), junction, reading


def _read_settings(program: Program, profile, family, printer):
    """``_settings_limits`` read from ``program``."""
    data = program.data
    said = "requested"
    if printer is not None:
        if family not in (None, "klipper"):
            raise GatesoptError(f"a Klipper printer config plans with Klipper's rules, not {family!r}")
        family = "klipper"
        profile = profile or family
    if family is not None:
        firmware.planner_rules(family)      # an unknown family is an error
    else:
        family, said = default_family(program)
    rules = firmware.planner_rules(family)
    source: dict[str, str] = {"firmware": f"{family}: {said}"}

    # --- 3: defaults --------------------------------------------------------------------------
    if profile is None:
        profile, why = _printer_profile(data, family)
    else:
        why = "requested"
    if profile not in PRINTER_DEFAULTS:
        raise GatesoptError(f"unknown printer profile {profile!r} (known: {', '.join(PRINTER_DEFAULTS)})")
    v = np.array([float(PRINTER_DEFAULTS[profile][k]) for k in KEYS])
    for k in KEYS:
        source[k] = f"default: {profile} ({why})"
    junction = DEFAULT_JUNCTION[profile]
    source["junction"] = f"default: {profile}"
    if rules.junction_fixed:
        junction = rules.junction
        source["junction"] = rules.junction_note

    if printer is not None:
        for k, x in printer.limit_values().items():
            v[K[k]] = x
            source[k] = f"printer config {printer.source}"
        source["firmware"] = f"printer config {printer.source}"

    # --- 2: the slicer's config block ----------------------------------------------------------
    config = _config(data) if printer is None else {}
    junction = _apply_config(config, v, source, rules, junction)
    if rules.one_accel:
        # one acceleration for every move on Klipper (toolhead.py max_accel)
        v[K["accel_travel"]] = v[K["accel_retract"]] = v[K["accel_print"]]
    # the config block's machine maxima also cap what later M204 / SET_VELOCITY_LIMIT lines ask
    # for, as PrusaSlicer's estimator does (GCodeProcessor set_acceleration: "Clamp the
    # acceleration with the maximum")
    caps = {k: v[K[k]] for k in ("accel_print", "accel_travel", "accel_retract")
            if source[k].startswith("config:")}
    flavor = _flavor(data)
    reading = _Reading(rules, family, profile, rules.feed_per_min,
                       flavor in ("marlin", "marlinlegacy", "marlin_legacy"), caps, printer)
    return v, source, junction, reading


@dataclass(frozen=True, eq=False)
class PieceLimits:
    """The limits of a file read in pieces (``gatesopt.stream``): the values in force where the
    next piece starts and how the file's lines read, both from the file's settings (its head and
    tail, where slicers write the config block and the printer, which a piece in the middle does
    not have). ``of_piece`` gives one piece's limits, its own limit lines applying from their
    lines on as in the whole file, and what is in force after it: the next piece's start."""

    start: MachineLimits
    reading: _Reading
    jd_from_line: bool = False
    first: bool = True          # the next piece is the file's first

    @classmethod
    def of_settings(cls, settings: Program, family: str | None = None,
                    printer=None) -> "PieceLimits":
        """Before the file's first line, from ``settings`` (the head and tail of the file,
        parsed: its lines set nothing here, the pieces' own lines do)."""
        v, source, junction, reading = _settings_limits(settings, None, family, printer)
        return cls(_from_vector(v, reading.family, junction, source, (), reading.profile),
                   reading)

    def of_piece(self, program: Program) -> tuple[MachineLimits, "PieceLimits"]:
        """``(limits of the piece, the state after it)``: the first piece's lines before its
        first motion step set the values in force there, as ``machine_limits`` reads a file."""
        v = self.start.vector()
        source = dict(self.start.source)
        changes, jd = self.reading.apply(program, v, source, initial=self.first)
        jd |= self.jd_from_line
        limits = self.reading.finish(v, source, self.start.junction, changes, jd)
        _, table = limits.regimes()
        after = _from_vector(table[-1], limits.firmware, limits.junction, limits.source, (),
                             limits.profile)
        return limits, PieceLimits(after, self.reading, jd, first=False)
