"""Firmware models: what a motor on/off instruction really does on each firmware.

3DGates (Chen et al., ASPLOS'17) Sections 4.1 and 4.3 assume its own firmware patch: S-series
instructions (Table 3: ``S1 X`` on, ``S0 X`` off) that switch a motor's enable pin at an exact time
without pausing the print. Stock firmware differs; each ``Firmware`` preset below records what its
source code does (DESIGN.md "Firmware: what really happens"), so that the solver can price a gate and
the emitter can write the right text:

``3dgates``
    The paper's patch: ``S0 X Y`` / ``S1 X Y``, exact timing, no stall, homing kept.
``marlin``
    Marlin 2.x ``Marlin/src/gcode/control/M17_M18_M84.cpp`` (read at MarlinFirmware/Marlin@008dcb7):
    ``GcodeSuite::M18_M84()`` with axis words calls ``planner.synchronize()`` -- it waits until the
    motion queue is empty, i.e. the head decelerates to a full stop -- and then
    ``stepper.disable_axis(X_AXIS)``. ``GcodeSuite::M17()`` calls ``stepper.enable_axis`` at once,
    without draining, so it takes effect when the command is *parsed*, up to a queue of moves
    (``BLOCK_BUFFER_SIZE``, 16 by default) before the moves around it run. A move with X steps
    re-enables X by itself when the planner queues it. Disabling marks the axis position untrusted;
    moves are refused only with ``NO_MOTION_BEFORE_HOMING`` + ``HOME_AFTER_DEACTIVATE``.
``klipper``
    Klipper ``klippy/extras/stepper_enable.py`` (read at Klipper3d/klipper@0e30b86 and a 2025 copy):
    ``cmd_SET_STEPPER_ENABLE`` -> ``motor_debug_enable`` runs ``toolhead.dwell(DISABLE_STALL_TIME)``
    (0.100 s), flushes the look-ahead (``get_last_move_time``), switches the pin, and dwells 0.100 s
    again: ~0.2 s of dwell plus the flush, 0.22 s measured. Klipper has no ``M17``: ``klippy/gcode.py``
    ``cmd_default`` answers 'Unknown command:"M17"' and goes on (no dwell, nothing switched). Re-enable is automatic: ``motor_disable``
    re-registers ``add_active_callback(self.motor_enable)``, so the first step of that stepper turns
    it back on at the step's own print time. Old versions take one ``STEPPER=`` per command (newer
    ones also accept ``STEPPERS=a,b`` and call ``STEPPER=`` deprecated), so we write one line per
    stepper, each with its own stall. ``M18``/``M84`` go to ``motor_off()``/``axes_off()``, which on
    most versions disable *all* steppers and send ``stepper_enable:motor_off`` (homing cleared):
    never emitted for Klipper.
``reprap``
    RepRapFirmware: ``M18 X`` waits for standstill and marks X not homed; the next X move is refused
    by default. X/Y/Z gating is refused with a message; only E may be gated.

A motor line a firmware does not know (``Firmware.executes``: Klipper's missing ``M17``, Marlin's or
RepRapFirmware's ``SET_STEPPER_ENABLE``, the S-series on stock firmware) is skipped by it as an
unknown command and stalls nothing; ``stall_durations`` prices every motor line, the file's own and
gating's, by that rule for the solver and the verifier alike.

Costs under the paper's time model (T = L / F, 3DGates Eq. 2, no acceleration): a stall is a fixed
time per instruction line, during which the whole printer keeps drawing power (the energy profile
prices a ``Kind.MOTOR`` row like an extruding step at zero speed, see ``paper.toml`` ``stall_like``).
Marlin's full stop has no meaning without acceleration; we use ``MARLIN_STOP_S`` (documented below),
and ``stall_durations(..., planner=...)`` takes a hook for the acceleration-aware planner model
(``gatesopt.planner``) when the caller has one.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _text
from .errors import GatesoptError
from .program import AXES, MOTION_KINDS, Kind, Program

# A full stop on Marlin under the paper's time model: decelerating from v to 0 and accelerating
# back costs v/(2a) + v/(2a) = v/a over moving at v throughout. At a typical print speed of
# 50 mm/s and Marlin's common printing acceleration of 1000 mm/s^2 that is 0.05 s. (An assumption,
# stated once; the planner hook below replaces it with the real speeds where available.)
MARLIN_STOP_S = 0.05
MARLIN_ACCEL_MM_S2 = 1000.0
# Klipper: DISABLE_STALL_TIME = 0.100 s dwelled before and after the pin change, plus the look-ahead
# flush: 0.22 s measured (DESIGN.md).
KLIPPER_STALL_S = 0.22

KLIPPER_STEPPER = {"X": "stepper_x", "Y": "stepper_y", "Z": "stepper_z", "E": "extruder"}


@dataclass(frozen=True)
class ExtendedMotorCommand:
    """An extended (Klipper-style) command that switches one motor on or off, as the parser's
    scanner reads it (``gatesopt._scan``, packed by ``_scan.pack_motor_commands``): the line
    starts with ``word``; ``motor_param`` followed by one of ``motors``' names (a prefix of the
    value, any case) names the motor; ``enable_param`` followed by 0 or 1 says off or on. The last
    motor named and the last enable value on the line count; a line without both is no motor line.
    """

    word: str                   # e.g. "SET_STEPPER_ENABLE"
    motor_param: str            # e.g. "STEPPER="
    motors: tuple               # ((name, motor letter), ...), e.g. (("STEPPER_X", "X"), ...)
    enable_param: str           # e.g. "ENABLE="


#: the extended commands the parser reads as motor lines (``Kind.MOTOR`` rows, the motor enables
#: they set). Klipper's ``SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=0`` (klippy/extras/
#: stepper_enable.py ``cmd_SET_STEPPER_ENABLE``); a dialect that writes its own command adds a row
#: here. (The scanner reads one ``STEPPER=`` name per line and ``stepper_<letter>`` names;
#: ``parse_motor_line`` below also reads ``STEPPERS=a,b`` and ``extruder``.)
EXTENDED_MOTOR_COMMANDS = (
    ExtendedMotorCommand("SET_STEPPER_ENABLE", "STEPPER=",
                         tuple((f"STEPPER_{m}", m) for m in AXES), "ENABLE="),
)


class FirmwareError(GatesoptError, ValueError):
    """A gating request the chosen firmware cannot carry out safely."""


@dataclass(frozen=True)
class Firmware:
    """What motor on/off instructions look like and cost on one firmware."""

    name: str
    off_word: str                 # instruction text before the motor letters, e.g. "S0" or "M18"
    on_word: str | None           # None: no on instruction is written (re-enable is automatic)
    merge_motors: bool            # several motors in one line ("S0 X Y"); False: one line each
    stall_off_s: float            # stall per disable line (whole printer keeps drawing power)
    stall_on_s: float             # stall per enable line
    reenable: str                 # "exact" | "auto-first-step" | "early-by-queue"
    homing_kept: bool             # does the axis stay homed after a disable
    allowed_motors: frozenset     # motors this firmware may gate
    executes: frozenset           # motor instruction words (``motor_line_word``) it carries out; any
                                  # other motor line is an unknown command to it: skipped, no stall
    refused_note: str = ""        # why other motors are refused
    description: str = ""

    # -- text -------------------------------------------------------------------------------------
    def off_lines(self, motors) -> list[str]:
        """Instruction lines (no line ending) that switch ``motors`` (letters, X Y Z E order) off."""
        return self._lines(self.off_word, motors, 0)

    def on_lines(self, motors) -> list[str]:
        """Lines that switch ``motors`` on; empty when re-enable is automatic at the first step."""
        if self.on_word is None:
            return []
        return self._lines(self.on_word, motors, 1)

    def _lines(self, word: str, motors, enable: int) -> list[str]:
        motors = [m for m in AXES if m in set(motors)]
        if not motors:
            return []
        if self.name == "klipper":
            return [f"SET_STEPPER_ENABLE STEPPER={KLIPPER_STEPPER[m]} ENABLE={enable}" for m in motors]
        if self.merge_motors:
            return [f"{word} {' '.join(motors)}"]
        return [f"{word} {m}" for m in motors]

    def check_motors(self, motors) -> None:
        """Raise ``FirmwareError`` if this firmware must not gate one of ``motors``."""
        bad = [m for m in motors if m not in self.allowed_motors]
        if bad:
            raise FirmwareError(f"firmware {self.name!r} cannot gate motor(s) {','.join(bad)}: "
                                f"{self.refused_note or 'not allowed'}")

    # -- costs -------------------------------------------------------------------------------------
    def n_off_lines(self, n_motors: int) -> int:
        return 0 if n_motors == 0 else (1 if self.merge_motors else n_motors)

    def n_on_lines(self, n_motors: int) -> int:
        if self.on_word is None or n_motors == 0:
            return 0
        return 1 if self.merge_motors else n_motors


PRESETS: dict[str, Firmware] = {
    "3dgates": Firmware(
        name="3dgates", off_word="S0", on_word="S1", merge_motors=True, stall_off_s=0.0,
        stall_on_s=0.0, reenable="exact", homing_kept=True, allowed_motors=frozenset(AXES),
        executes=frozenset({"S0", "S1", "M17", "M18", "M84"}),
        description="3DGates firmware patch (paper Table 3): S0/S1, exact, no stall"),
    "marlin": Firmware(
        name="marlin", off_word="M18", on_word="M17", merge_motors=True, stall_off_s=MARLIN_STOP_S,
        stall_on_s=0.0, reenable="early-by-queue", homing_kept=True, allowed_motors=frozenset(AXES),
        executes=frozenset({"M17", "M18", "M84"}),
        description="Marlin 2.x: M18 drains the queue (full stop), M17 enables at parse time"),
    "klipper": Firmware(
        name="klipper", off_word="SET_STEPPER_ENABLE", on_word=None, merge_motors=False,
        stall_off_s=KLIPPER_STALL_S, stall_on_s=KLIPPER_STALL_S, reenable="auto-first-step",
        homing_kept=True, allowed_motors=frozenset(AXES),
        executes=frozenset({"SET_STEPPER_ENABLE", "M18", "M84"}),
        description="Klipper: SET_STEPPER_ENABLE per stepper, ~0.22 s stall, auto re-enable"),
    "reprap": Firmware(
        name="reprap", off_word="M18", on_word="M17", merge_motors=True, stall_off_s=MARLIN_STOP_S,
        stall_on_s=0.0, reenable="exact", homing_kept=False, allowed_motors=frozenset({"E"}),
        executes=frozenset({"M17", "M18", "M84"}),
        refused_note="RepRapFirmware's M18 marks X/Y/Z not homed and refuses the next move on them",
        description="RepRapFirmware: M18 waits for standstill and unhomes the axis"),
}


def get(name: str | Firmware) -> Firmware:
    """The preset called ``name`` (``3dgates``, ``marlin``, ``klipper``, ``reprap``)."""
    if isinstance(name, Firmware):
        return name
    try:
        return PRESETS[str(name).lower()]
    except KeyError:
        raise FirmwareError(f"unknown firmware {name!r}: choose one of {', '.join(PRESETS)}") from None


@dataclass(frozen=True)
class GatingCosts:
    """The numbers a gating problem needs from a firmware (see ``gating_costs``)."""

    firmware: str
    stall_off_s: float        # stall per off line
    stall_on_s: float         # stall per on line
    off_lines_merged: bool    # motors switched at the same moment share one off line
    on_lines_per_gate: int    # 0 when re-enable is automatic (Klipper), else 1 per on moment
    allowed_motors: tuple


def gating_costs(name: str | Firmware) -> GatingCosts:
    """Costs for the solver: stall seconds per off/on line and how lines are counted."""
    fw = get(name)
    return GatingCosts(firmware=fw.name, stall_off_s=fw.stall_off_s,
                       stall_on_s=fw.stall_on_s if fw.on_word is not None else 0.0,
                       off_lines_merged=fw.merge_motors,
                       on_lines_per_gate=0 if fw.on_word is None else 1,
                       allowed_motors=tuple(m for m in AXES if m in fw.allowed_motors))




_words = _text.code_words      # a line's upper-case code words (comment, line number dropped)


def motor_line_word(text: str) -> str | None:
    """The instruction word of a motor enable/disable line (``"S0"``, ``"M17"``,
    ``"SET_STEPPER_ENABLE"``, ...: what ``Firmware.executes`` lists), None for any other line."""
    if parse_motor_line(text) is None:
        return None
    return _words(text)[0]


def parse_motor_line(text: str) -> tuple[bool, tuple[str, ...]] | None:
    """``(on, motors)`` for a motor enable/disable line, else None.

    Understands ``S0``/``S1`` (3DGates Table 3), ``M17``/``M18``/``M84`` (no axis word: all motors;
    ``M18 S<sec>``/``M84 S<sec>`` only sets the idle timeout and is not a disable) and Klipper's
    ``SET_STEPPER_ENABLE STEPPER=stepper_x[,..]|STEPPERS=.. ENABLE=0|1`` (ENABLE defaults to 1).
    Whether a given firmware carries the line out at all is ``Firmware.executes``.
    """
    words = _words(text)
    if not words:
        return None
    head = words[0]
    if head in ("S0", "S1", "M17", "M18", "M84"):
        on = head in ("S1", "M17")
        letters: list[str] = []
        for w in words[1:]:
            if w.startswith("*"):
                break
            if head in ("M18", "M84") and w.startswith("S"):
                return None          # M18 S<sec>: idle timeout, not a disable
            for ch in w:
                if ch in AXES and ch not in letters:
                    letters.append(ch)
        motors = tuple(m for m in AXES if m in letters) or AXES
        return on, motors
    if head == "SET_STEPPER_ENABLE":
        on, names = True, []
        for w in words[1:]:
            if w.startswith("ENABLE="):
                on = w[7:] != "0"
            elif w.startswith("STEPPER=") or w.startswith("STEPPERS="):
                names += w.split("=", 1)[1].lower().split(",")
        motors = tuple(m for m in AXES if KLIPPER_STEPPER[m] in names)
        return (on, motors) if motors else None
    return None


def parse_motor_lines(texts) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``parse_motor_line`` of each text, as arrays: (a motor line, on, motors as a mask with
    bit m for ``AXES[m]``)."""
    parsed = [parse_motor_line(t) for t in texts]
    ok = np.array([p is not None for p in parsed], bool)
    on = np.array([p is not None and p[0] for p in parsed], bool)
    mask = np.array([0 if p is None else sum(1 << AXES.index(m) for m in p[1]) for p in parsed], np.uint8)
    return ok, on, mask


def xy_disable_rows(program: Program) -> np.ndarray:
    """Rows of ``program``'s own motor lines that switch the X or Y motor off (``M18``, ``M18 X``,
    ``S0 X Y``, ...), ascending; each distinct text parsed once (a gated file has many such lines,
    a few texts). Where a file has them inside its print it is already gated: they were placed
    for the moves around them (``gating.rotation.own_xy_disable``, ``ordering.layout.layout``)."""
    rows = np.flatnonzero(program.kind == Kind.MOTOR)
    if not len(rows):
        return rows
    inverse, texts = _text.distinct_lines(program, program.line[rows])
    ok, on, mask = parse_motor_lines(texts)
    xy = (1 << AXES.index("X")) | (1 << AXES.index("Y"))
    off_xy = ok & ~on & ((mask & xy) != 0)
    return rows[off_xy[inverse]]


def motor_line_is_on(text: str) -> bool | None:
    """True for an enable line, False for a disable line, None if ``text`` is neither."""
    r = parse_motor_line(text)
    return None if r is None else r[0]


def stall_durations(program: Program, firmware: str | Firmware = "3dgates", *, planner=None) -> np.ndarray:
    """Per-step stall time (s) of ``program``'s motor instructions under ``firmware``.

    Rows of ``Kind.MOTOR`` are enable/disable lines; every other row gets 0. A stall delays the
    moves after it, so an instruction after the last move (the slicer's closing ``M84``) costs none:
    the print is over. ``planner``, if given,
    is a callable ``planner(program, row) -> seconds`` used for Marlin's full stop instead of
    ``MARLIN_STOP_S``. Under the acceleration-aware time model (``gatesopt.planner``), whose
    durations already bring the head to rest at every line that drains the queue
    (``planner.drains_queue``: M18/M84, SET_STEPPER_ENABLE), pass ``planner=lambda p, r: 0.0``
    so the stop is not counted twice; Klipper's two 0.1 s dwells stay.
    """
    fw = get(firmware)
    out = np.zeros(program.n_steps)
    rows = np.flatnonzero(program.kind == Kind.MOTOR)
    motion = np.flatnonzero(np.isin(program.kind, MOTION_KINDS))
    last_motion = int(motion[-1]) if len(motion) else -1
    rows = rows[rows < last_motion]
    # each distinct text parsed once: a gated file has millions of instruction lines, a few texts
    inverse, texts = _text.distinct_lines(program, program.line[rows])
    ok, on, _ = parse_motor_lines(texts)
    # Only an instruction the firmware carries out stalls it. Any other motor line is an unknown
    # command to it, answered with a message and skipped: no dwell, no queue drain. Klipper has no
    # M17 (klippy/gcode.py ``cmd_default``: respond_info 'Unknown command:"M17"'; M18/M84 are
    # registered by klippy/extras/stepper_enable.py and dwell like SET_STEPPER_ENABLE), and
    # Marlin / RepRapFirmware know neither SET_STEPPER_ENABLE nor the S-series. A file's own
    # start G-code ``M17`` therefore costs nothing on Klipper. This is the one place a motor
    # line's stall is decided: the verifier (``verify.energy_of``) and the gating problem
    # (``gating.problem.build``, for the file's own lines) both read it from here.
    ok &= np.array([bool(k) and _words(t)[0] in fw.executes for k, t in zip(ok, texts)], bool)
    ok, on = ok[inverse], on[inverse]
    # Klipper's ENABLE=1 dwells too, though we never write it
    out[rows[ok]] = np.where(on[ok], fw.stall_on_s, fw.stall_off_s)
    if planner is not None and fw.name in ("marlin", "reprap"):
        for r in rows[ok & ~on]:
            out[r] = float(planner(program, int(r)))
    return out


def detect(program) -> str:
    """The dialect a file's own motor enable/disable lines are written in: "klipper" for
    SET_STEPPER_ENABLE, "marlin" for M17/M18 naming axes, "3dgates" for the S-series (also the
    answer when the file has none). M84 at the end of a print says nothing: every dialect has it."""
    import numpy as np
    from .program import Kind
    rows = program.line[program.kind == Kind.MOTOR]
    letters = program.line_letter[rows]
    numbers = program.line_number[rows]
    if np.any(letters == ord("@")):
        return "klipper"
    if np.any((letters == ord("M")) & ((numbers == 17) | (numbers == 18))):
        return "marlin"
    return "3dgates"
