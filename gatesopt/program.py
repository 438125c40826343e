"""The Program: a lossless parse of a G-code file.

Units, written once (Klipper's toolhead.py convention): ``_mm`` distance in millimetres, ``_mm_s``
speed in mm/s, ``_s`` time in seconds, ``_w`` power in watts, ``_j`` energy in joules, ``_c``
temperature in degrees Celsius.

A Program keeps the original bytes (so ``to_gcode()`` is byte-identical to the input) and one row
of numpy arrays per *timed step*: every motion (G0/G1/G2/G3 with an axis word) plus every
instruction that takes time without moving (G4 dwell, M109/M190 heat waits, G28 homing).
Modal G-code state (G90/G91, M82/M83, G92, G20/G21, F) is resolved once, in ``gatesopt.parse``,
and nowhere else: positions here are absolute machine millimetres, and E is the cumulative
filament position (it keeps counting across ``G92 E0`` resets). The per-step ``offset_mm``,
``relative_xyz``, ``relative_e`` and ``inch`` columns say how the step was written, so an emitter
can write a new move in the file's own modal state.

Axis order everywhere: X, Y, Z, E (``AXES``).
"""
from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass, field

import numpy as np

AXES = ("X", "Y", "Z", "E")
X, Y, Z, E = 0, 1, 2, 3


class Kind(enum.IntEnum):
    """What a timed step is. Stored as ``int8`` in ``Program.kind``."""

    TRAVEL = 0      # XY(Z) motion, no extrusion (ΔE == 0)
    EXTRUDE = 1     # linear motion with XY or Z displacement and ΔE > 0
    RETRACT = 2     # ΔE < 0 (E-only, or a wipe that moves XY while retracting)
    UNRETRACT = 3   # E-only, ΔE > 0
    Z_ONLY = 4      # Z motion without XY or E (layer change, z-hop)
    ARC = 5         # G2/G3 (extruding or not: see ``extruding``)
    DWELL = 6       # G4 P<ms> / S<s>
    WAIT = 7        # M109 / M190 / M116 / TEMPERATURE_WAIT: heat-up wait
    HOME = 8        # G28
    MOTOR = 9       # motor enable/disable instruction (S0/S1, M17/M18/M84, SET_STEPPER_ENABLE):
                    # no motion; its firmware stall time is set by gatesopt.firmware


MOTION_KINDS = (Kind.TRAVEL, Kind.EXTRUDE, Kind.RETRACT, Kind.UNRETRACT, Kind.Z_ONLY, Kind.ARC)


@dataclass(frozen=True, eq=False)
class Program:
    """Lossless G-code program: original bytes + per-step numpy arrays.

    Arrays are read-only views; a Program is never mutated (rewrites build new text, see
    ``gatesopt.gating.emit`` and ``gatesopt.ordering.emit``).
    """

    source: str                 # file name, or "<text>"
    data: bytes                 # the original bytes, exactly
    line_start: np.ndarray      # int64 (n_lines + 1,): byte offset where each line starts; last = len(data)

    # --- one row per timed step (n_steps) -------------------------------------------------------
    line: np.ndarray            # int64: 0-based source line of the step
    kind: np.ndarray            # int8: Kind
    start_mm: np.ndarray        # float64 (n, 4): X Y Z E before the step (absolute machine mm, E cumulative)
    end_mm: np.ndarray          # float64 (n, 4): X Y Z E after the step
    feed_mm_s: np.ndarray       # float64: modal feedrate in force for the step (mm/s)
    length_mm: np.ndarray       # float64: XYZ path length (true arc length for G2/G3); |ΔE| for E-only steps
    duration_s: np.ndarray      # float64: paper time model T = L / F (3DGates Eq. 2); dwell/wait/home times
    layer: np.ndarray           # int32: layer index (-1 before the first layer)
    feature: np.ndarray         # int16: index into ``feature_names`` (-1 where the slicer marks none)
    fan: np.ndarray             # float32: part-cooling fan duty 0..1 (M106 S/255, M107 = 0)
    hotend_c: np.ndarray        # float32: hotend target temperature in force (M104/M109)
    bed_c: np.ndarray           # float32: bed target temperature in force (M140/M190)
    arc_center_mm: np.ndarray   # float64 (n, 2): arc centre X Y (NaN for non-arcs)
    arc_ccw: np.ndarray         # bool: G3 (counter-clockwise) vs G2
    offset_mm: np.ndarray       # float64 (n, 4): G92 offset in force: machine = logical*scale + offset
    relative_xyz: np.ndarray    # bool: G91 in force
    relative_e: np.ndarray      # bool: M83 (or G91) in force for E
    inch: np.ndarray            # bool: G20 in force (logical units are inches)
    enabled: np.ndarray         # bool (n, 4): motor enable state in force during the step, from the
                                # file's own enable/disable instructions; a step on an axis enables
                                # its motor (as every firmware does) and it stays on

    # --- one entry per source line (n_lines) ------------------------------------------------------
    line_letter: np.ndarray     # uint8: ASCII of the line's command letter ('G', 'M', 'T', 'S'), 64 ('@')
                                # for an extended command word (SET_VELOCITY_LIMIT ...), 0 if none
    line_number: np.ndarray     # float32: the command's number (G1 -> 1.0, M104 -> 104.0), NaN if none

    # --- per program ------------------------------------------------------------------------------
    feature_names: tuple[str, ...] = ()
    layer_z_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))  # float64 (n_layers,): print Z of each layer
    layer_line: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # int64: first line of each layer
    layer_method: str = "none"  # how layers were found: "marker:<name>" or "z-change"
    line_ending: str = "\n"
    header: dict = field(default_factory=dict)   # facts read from the slicer's header/config (see parse.py)
    warnings: tuple[str, ...] = ()               # non-fatal findings, each "file:line: message"
    # 0-based lines of moves that carry an axis the model has not got (A B C U V W: Mach3 and
    # machinekit write the extruder as A): profiled without it, never rewritten (check_rewritable)
    foreign_axis_lines: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    # 0-based lines of M106 / M107 that set the part-cooling fan ``fan`` follows (no P word, or
    # P0; the parser's rule, recorded where it applies it): other fans (Bambu's auxiliary
    # ``M106 P2``) are not modelled. Re-ordering treats these lines as state, the rest as barriers
    part_fan_lines: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    # ------------------------------------------------------------------------------------------
    @property
    def n_lines(self) -> int:
        return len(self.line_start) - 1

    @property
    def n_steps(self) -> int:
        return len(self.line)

    @property
    def n_layers(self) -> int:
        return len(self.layer_z_mm)

    @property
    def delta_mm(self) -> np.ndarray:
        """(n, 4) displacement per step, X Y Z E."""
        return self.end_mm - self.start_mm

    @property
    def extruding(self) -> np.ndarray:
        """Steps that deposit material: positive ΔE together with XY(Z) motion (lines and arcs)."""
        d = self.delta_mm
        return (d[:, E] > 0) & ((self.kind == Kind.EXTRUDE) | (self.kind == Kind.ARC))

    def steps_motor(self) -> np.ndarray:
        """(n, 4) bool: which motors step during each row (any nonzero displacement on the axis).

        Arcs step both X and Y (the firmware interpolates both), whatever their end points.
        Homing steps X, Y and Z.
        """
        d = self.delta_mm
        moving = d != 0.0
        arc = self.kind == Kind.ARC
        moving[arc, X] = True
        moving[arc, Y] = True
        home = self.kind == Kind.HOME
        moving[home, :3] = True
        return moving

    def is_command(self, letter: str, number: float) -> np.ndarray:
        """(n_lines,) bool: lines whose command is ``letter`` ``number`` (e.g. ``("M", 104)``)."""
        return (self.line_letter == ord(letter)) & (self.line_number == number)

    def line_text(self, i: int) -> str:
        """Line ``i`` (0-based) with its line ending, as in the file."""
        return self.data[self.line_start[i]:self.line_start[i + 1]].decode("utf-8", "surrogateescape")

    def lines(self) -> list[str]:
        """All lines with their endings (``"".join(lines()) == to_gcode()``)."""
        text = self.to_gcode()
        return text.splitlines(keepends=True)

    def check_rewritable(self, line_offset: int = 0) -> None:
        """Raise ``GcodeError`` (file:line of the first one) if a move carries an axis the model
        has not got: a rewrite splits and re-orders moves by X Y Z E only, so such a word would
        land on the wrong piece (a Mach3 extruder on A: all the filament in the first 0.03 mm)."""
        if len(self.foreign_axis_lines):
            from .errors import GcodeError
            ln = int(self.foreign_axis_lines[0])
            raise GcodeError(self.source, ln + 1 + line_offset,
                             "a move on an axis gatesopt does not model (A B C U V W; Mach3 and "
                             "machinekit write the extruder as A): not rewritten. Slice with E "
                             "as the extruder axis", text=self.line_text(ln))

    def to_gcode(self) -> str:
        """The program as text, byte-identical to the input (undecodable bytes round-trip too)."""
        return self.data.decode("utf-8", "surrogateescape")

    def to_bytes(self) -> bytes:
        return self.data

    def replace(self, **changes) -> "Program":
        return dataclasses.replace(self, **changes)

    def __repr__(self) -> str:  # arrays would flood a REPL
        return (f"Program({self.source!r}, lines={self.n_lines}, steps={self.n_steps}, "
                f"layers={self.n_layers}, layer_method={self.layer_method!r})")
