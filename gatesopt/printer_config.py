"""A Klipper ``printer.cfg`` read for what gatesopt models: planner limits, the input shaper's step
window, the gatesopt_gating module's options.

Klipper reads its config with Python's ``configparser`` (klippy/configfile.py: ``RawConfigParser``
with ``strict=False`` and inline comments after ``;`` or ``#``), expands ``[include FILE]`` sections
where they stand (a glob relative to the including file) and applies the ``SAVE_CONFIG`` block at the
end (lines ``#*# ...`` after the ``#*# <--- SAVE_CONFIG --->`` marker, where ``SHAPER_CALIBRATE``
writes the shaper) over the rest. This module does the same and reads:

- ``[printer]``: ``kinematics``, ``max_velocity``, ``max_accel``, ``minimum_cruise_ratio`` (Klipper's
  default 0.5), ``square_corner_velocity`` (default 5), ``max_z_velocity`` / ``max_z_accel``
  (default: max_velocity / max_accel; klippy/kinematics/cartesian.py);
- ``[input_shaper]``: ``shaper_type`` (default mzv), ``shaper_type_x/_y/_z``, ``shaper_freq_x/_y/_z``
  (default 0: no shaping), ``damping_ratio_x/_y/_z`` (default 0.1) -> each axis's step window
  (``gatesopt.shaper``);
- ``[extruder]``: ``max_extrude_only_velocity`` / ``max_extrude_only_accel`` (default: max_velocity
  / max_accel times ``4 nozzle_diameter^2`` over the filament's cross section;
  klippy/kinematics/extruder.py), the limits of extrude-only moves, Z-with-E moves and retractions;
- ``[gcode_arcs]``: ``resolution`` (default 1.0 mm; without the section Klipper has no G2/G3);
- ``[gatesopt_gating]``: ``start_ahead`` (0.0018 s), ``end_late`` (0.0010 s), ``min_off_time``
  (0 s), ``min_pin_spacing`` (0.1 s, 0.025 .. 1), ``pin_queue_slots`` (2; 1 or 2), ``steppers``
  ("stepper_x, stepper_y"): the module's options
  (integrations/klipper/gatesopt_gating.py);
- the stepper sections present (``[stepper_x]``, ...).

``PrinterConfig.limit_values`` gives the planner limits under ``gatesopt.limits``' names.
"""
from __future__ import annotations

import configparser
import glob
import math
import os
from dataclasses import dataclass
from pathlib import Path

from .errors import GatesoptError
from .shaper import DEFAULT_DAMPING_RATIO, Shaper, ShaperError, shaper

SAVE_CONFIG_MARKER = "#*# <---------------------- SAVE_CONFIG ---------------------->"
SAVE_CONFIG_PREFIX = "#*#"
AXES_SHAPED = ("x", "y", "z")
MAX_INCLUDE_DEPTH = 20


class PrinterConfigError(GatesoptError, ValueError):
    """A printer.cfg that cannot be read, or a value out of range (file and option named)."""


@dataclass(frozen=True)
class GatingSection:
    """The ``[gatesopt_gating]`` section (the Klipper module's options)."""

    start_ahead_s: float = 0.0018
    end_late_s: float = 0.0010
    min_off_time_s: float = 0.0
    min_pin_spacing_s: float = 0.100    # least time between two changes of one pin (the module's
                                        # DEFAULT_PIN_SPACING_S; its docstring cites Klipper's source)
    pin_queue_slots: int = 2            # changes of one pin queued on the MCU at once (the module's
                                        # DEFAULT_PIN_QUEUE_SLOTS, "Pin queue")
    steppers: tuple[str, ...] = ("stepper_x", "stepper_y")


@dataclass(frozen=True)
class PrinterConfig:
    """What gatesopt reads from a Klipper config (module docstring); None: not in the file."""

    source: str
    kinematics: str | None = None
    max_velocity_mm_s: float | None = None
    max_accel_mm_s2: float | None = None
    min_cruise_ratio: float = 0.5
    square_corner_velocity_mm_s: float = 5.0
    max_z_velocity_mm_s: float | None = None
    max_z_accel_mm_s2: float | None = None
    max_extrude_only_velocity_mm_s: float | None = None   # [extruder], its default applied
    max_extrude_only_accel_mm_s2: float | None = None
    arc_resolution_mm: float | None = None       # None: no [gcode_arcs]
    shapers: tuple = ()                          # (("x", gatesopt.shaper.Shaper), ...): shaped axes
    gating: GatingSection | None = None          # None: no [gatesopt_gating]
    steppers: tuple[str, ...] = ()               # [stepper_*] / [extruder] sections present

    def limit_values(self) -> dict[str, float]:
        """Planner limits under ``gatesopt.limits.KEYS`` names: what toolhead.py plans with (one
        ``max_accel`` for every move; ``minimum_cruise_ratio``; the kinematics' Z caps)."""
        out: dict[str, float] = {"square_corner_velocity": self.square_corner_velocity_mm_s,
                                 "min_cruise_ratio": self.min_cruise_ratio}
        if self.max_velocity_mm_s is not None:
            out["max_velocity"] = self.max_velocity_mm_s
        if self.max_accel_mm_s2 is not None:
            for k in ("accel_print", "accel_travel", "accel_retract"):
                out[k] = self.max_accel_mm_s2
        zv = self.max_z_velocity_mm_s if self.max_z_velocity_mm_s is not None else self.max_velocity_mm_s
        za = self.max_z_accel_mm_s2 if self.max_z_accel_mm_s2 is not None else self.max_accel_mm_s2
        if zv is not None:
            out["max_feed_z"] = zv
        if za is not None:
            out["max_accel_z"] = za
        if self.max_extrude_only_velocity_mm_s is not None:
            out["max_feed_e"] = self.max_extrude_only_velocity_mm_s
        if self.max_extrude_only_accel_mm_s2 is not None:
            out["max_accel_e"] = self.max_extrude_only_accel_mm_s2
        return out

    def window_s(self, axes: str) -> tuple[float, float]:
        """(pre, post) step window of a stepper active on ``axes`` (e.g. "x", "xy" on corexy):
        the largest of the shaped axes' (``gatesopt.shaper``), (0, 0) without a shaper."""
        pre = post = 0.0
        shaped = dict(self.shapers)
        for a in axes.lower():
            s = shaped.get(a)
            if s is not None:
                p, q = s.window_s()
                pre, post = max(pre, p), max(post, q)
        return pre, post


# ------------------------------------------------------------------------------------------------
def _sections(path: Path, depth: int = 0) -> list[tuple[str, str]]:
    """The config's text as (file name, text) chunks in Klipper's reading order: each [include]
    expanded where it stands; the SAVE_CONFIG block last."""
    if depth > MAX_INCLUDE_DEPTH:
        raise PrinterConfigError(f"{path}: [include] nested more than {MAX_INCLUDE_DEPTH} deep")
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as e:
        raise PrinterConfigError(f"cannot read printer config {path}: {e.strerror or e}") from None
    lines = text.splitlines()
    saved: list[str] = []
    if SAVE_CONFIG_MARKER in (ln.rstrip() for ln in lines):
        at = [ln.rstrip() for ln in lines].index(SAVE_CONFIG_MARKER)
        saved = [ln[len(SAVE_CONFIG_PREFIX):].lstrip(" ") if ln.startswith(SAVE_CONFIG_PREFIX) else ln
                 for ln in lines[at + 1:]]
        # Klipper's AUTOSAVE_HEADER (klippy/configfile.py) is the marker, a "DO NOT EDIT" line and
        # an empty "#*#": the block's data starts at its first section
        first = next((i for i, ln in enumerate(saved) if ln.strip().startswith("[")), len(saved))
        saved = saved[first:]
        lines = lines[:at]
    out: list[tuple[str, str]] = []
    chunk: list[str] = []
    for ln in lines:
        head = ln.strip()
        if head.startswith("[") and head.lower().startswith("[include ") and "]" in head:
            out.append((str(path), "\n".join(chunk)))
            chunk = []
            pattern = head[len("[include "):head.index("]")].strip()
            full = os.path.join(path.parent, pattern)
            matches = sorted(glob.glob(full))
            if not matches and not glob.has_magic(full):
                raise PrinterConfigError(f"{path}: included file {pattern!r} not found")
            for m in matches:
                out += _sections(Path(m), depth + 1)
            continue
        chunk.append(ln)
    out.append((str(path), "\n".join(chunk)))
    if saved:
        out.append((f"{path} (SAVE_CONFIG)", "\n".join(saved)))
    return out


def _float(cp, section, option, default, *, above=None, minval=None, below=None, source=""):
    if not cp.has_option(section, option):
        return default
    text = cp.get(section, option)
    try:
        v = float(text)
    except ValueError:
        raise PrinterConfigError(f"{source}: [{section}] {option}: {text!r} is not a number") from None
    if (not math.isfinite(v) or (above is not None and not v > above) or (minval is not None and v < minval)
            or (below is not None and not v < below)):
        bounds = ", ".join(x for x in (f"> {above}" if above is not None else "",
                                       f">= {minval}" if minval is not None else "",
                                       f"< {below}" if below is not None else "") if x)
        raise PrinterConfigError(f"{source}: [{section}] {option} = {v:g} must be {bounds}")
    return v


def _int(cp, section, option, default, *, minval, maxval, source=""):
    """An integer option as Klipper's ``getint`` reads it (``int(text)``: no "2.0")."""
    if not cp.has_option(section, option):
        return default
    text = cp.get(section, option)
    try:
        v = int(text)
    except ValueError:
        raise PrinterConfigError(f"{source}: [{section}] {option}: {text!r} is not an integer") from None
    if not minval <= v <= maxval:
        raise PrinterConfigError(f"{source}: [{section}] {option} = {v} must be >= {minval} and <= {maxval}")
    return v


def _shapers(cp, source: str) -> tuple:
    if not cp.has_section("input_shaper"):
        return ()
    out: list[tuple[str, Shaper]] = []
    default_type = cp.get("input_shaper", "shaper_type", fallback="mzv").strip().lower()
    for a in AXES_SHAPED:
        ty = cp.get("input_shaper", f"shaper_type_{a}", fallback=default_type).strip().lower()
        freq = _float(cp, "input_shaper", f"shaper_freq_{a}", 0.0, minval=0.0, source=source)
        zeta = _float(cp, "input_shaper", f"damping_ratio_{a}", DEFAULT_DAMPING_RATIO, minval=0.0,
                      source=source)
        try:
            s = shaper(ty, freq, zeta)
        except ShaperError as e:
            raise PrinterConfigError(f"{source}: [input_shaper] axis {a}: {e}") from None
        if s.amplitudes:
            out.append((a, s))
    return tuple(out)


def _gating(cp, source: str) -> GatingSection | None:
    sec = "gatesopt_gating"
    if not cp.has_section(sec):
        return None
    d = GatingSection()
    names = cp.get(sec, "steppers", fallback=", ".join(d.steppers))
    steppers = tuple(dict.fromkeys(n.strip() for n in names.split(",")))
    if not steppers or any(not n for n in steppers):
        raise PrinterConfigError(f"{source}: [{sec}] steppers: expected a comma separated list of "
                                 f"stepper names, got {names!r}")
    return GatingSection(
        start_ahead_s=_float(cp, sec, "start_ahead", d.start_ahead_s, minval=0.0, below=0.05000001,
                             source=source),
        end_late_s=_float(cp, sec, "end_late", d.end_late_s, minval=0.0, below=0.05000001, source=source),
        min_off_time_s=_float(cp, sec, "min_off_time", d.min_off_time_s, minval=0.0, below=3600.000001,
                              source=source),
        min_pin_spacing_s=_float(cp, sec, "min_pin_spacing", d.min_pin_spacing_s, minval=0.025,
                                 below=1.000000001, source=source),
        pin_queue_slots=_int(cp, sec, "pin_queue_slots", d.pin_queue_slots, minval=1, maxval=2, source=source),
        steppers=steppers)


def _extrude_only(cp, max_v, max_a, source: str) -> tuple[float | None, float | None]:
    """[extruder] ``max_extrude_only_velocity`` / ``_accel``, with Klipper's defaults
    (klippy/kinematics/extruder.py ``PrinterExtruder.__init__``: max_velocity / max_accel times
    ``def_max_extrude_ratio = 4 nozzle_diameter^2 / (pi (filament_diameter / 2)^2)``); None where
    neither the option nor what its default needs is in the file."""
    sec = "extruder"
    if not cp.has_section(sec):
        return None, None
    nozzle = _float(cp, sec, "nozzle_diameter", None, above=0.0, source=source)
    filament = _float(cp, sec, "filament_diameter", None, above=0.0, source=source)
    ratio = None
    if nozzle is not None and filament is not None:
        ratio = 4.0 * nozzle ** 2 / (math.pi * (filament / 2.0) ** 2)
    out = []
    for opt, base in (("max_extrude_only_velocity", max_v), ("max_extrude_only_accel", max_a)):
        default = base * ratio if base is not None and ratio is not None else None
        out.append(_float(cp, sec, opt, default, above=0.0, source=source))
    return out[0], out[1]


def read_printer_config(path) -> PrinterConfig:
    """Read a Klipper config file (with its includes and SAVE_CONFIG block)."""
    path = Path(path)
    cp = configparser.RawConfigParser(strict=False, inline_comment_prefixes=(";", "#"))
    for name, text in _sections(path):
        try:
            cp.read_string(text, source=name)
        except configparser.Error as e:
            raise PrinterConfigError(f"{name}: {str(e).splitlines()[0]}") from None
    src = str(path)
    if not cp.has_section("printer"):
        raise PrinterConfigError(f"{src}: no [printer] section: not a Klipper printer config")
    p = "printer"
    max_v = _float(cp, p, "max_velocity", None, above=0.0, source=src)
    max_a = _float(cp, p, "max_accel", None, above=0.0, source=src)
    arcs = None
    if cp.has_section("gcode_arcs"):
        arcs = _float(cp, "gcode_arcs", "resolution", 1.0, above=0.0, source=src)
    steppers = tuple(s for s in cp.sections() if s.startswith("stepper_") or s == "extruder")
    e_v, e_a = _extrude_only(cp, max_v, max_a, src)
    return PrinterConfig(
        source=src, kinematics=cp.get(p, "kinematics", fallback=None),
        max_velocity_mm_s=max_v, max_accel_mm_s2=max_a,
        min_cruise_ratio=_float(cp, p, "minimum_cruise_ratio", 0.5, minval=0.0, below=1.0, source=src),
        square_corner_velocity_mm_s=_float(cp, p, "square_corner_velocity", 5.0, minval=0.0, source=src),
        max_z_velocity_mm_s=_float(cp, p, "max_z_velocity", None, above=0.0, source=src),
        max_z_accel_mm_s2=_float(cp, p, "max_z_accel", None, above=0.0, source=src),
        max_extrude_only_velocity_mm_s=e_v, max_extrude_only_accel_mm_s2=e_a,
        arc_resolution_mm=arcs, shapers=_shapers(cp, src), gating=_gating(cp, src), steppers=steppers)
