"""Firmware dialects: what a motor on/off instruction really does on each firmware.

3DGates (Chen et al., ASPLOS'17) Sections 4.1 and 4.3 assume its own firmware patch: S-series
instructions (Table 3: ``S1 X`` on, ``S0 X`` off) that switch a motor's enable pin at an exact time
without pausing the print. Stock firmware differs; each dialect records what its source code does
(DESIGN.md "Firmware: what really happens"), so that the solver can price a gate, the emitter can
write the right text and the verifier can read it back.

One module per dialect in this package, found by name the way Klipper loads its kinematics
(klippy/toolhead.py imports ``kinematics.<name>``): every public module here defines ``DIALECT``, a
``Firmware`` (or a subclass with its own writer), and is loaded on first use of the registry
(``get``, ``names``, ``PRESETS``). A dialect owns

- its writer (``Firmware.off_lines`` / ``on_lines``);
- its motor-line reader: which lines it carries out (``executes``, ``Firmware.reads``), the extended
  commands the parser reads as motor lines (``motor_commands``: ``ExtendedMotorCommand`` rows, the
  scanner's table ``EXTENDED_MOTOR_COMMANDS`` is all of them) and how it reads them
  (``Firmware.read_extended``);
- its stall model (``stall_off_s`` / ``stall_on_s``; ``stall_is_stop``: the stall is a full stop that
  the planner model can price, ``stall_durations``);
- its planner rules (``planner``: ``PlannerRules``, the stock configuration's limits and the rules
  ``gatesopt.limits`` and ``gatesopt.planner`` apply to a file of that firmware) and which of its
  instructions leave the motion queue alone (``no_drain_words``).

Adding a dialect is one new module here plus its tests. This ``__init__`` holds the registry and
what every dialect shares: the M17/M18/M84 and S-series reading (``parse_motor_line``), the stall
pricing (``stall_durations``) and the detection of a file's dialect (``detect``).

A motor line a firmware does not know (Klipper's missing ``M17``, Marlin's or RepRapFirmware's
``SET_STEPPER_ENABLE``, the S-series on stock firmware) is skipped by it as an unknown command and
stalls nothing; ``stall_durations`` prices every motor line, the file's own and gating's, by that
rule for the solver and the verifier alike.

Costs under the paper's time model (T = L / F, 3DGates Eq. 2, no acceleration): a stall is a fixed
time per instruction line, during which the whole printer keeps drawing power (the energy profile
prices a ``Kind.MOTOR`` row like an extruding step at zero speed, see ``paper.toml`` ``stall_like``).
"""
from __future__ import annotations

import importlib
import pkgutil
from dataclasses import dataclass, field

import numpy as np

from .. import _text
from ..errors import GatesoptError
from ..program import AXES, MOTION_KINDS, Kind, Program


@dataclass(frozen=True)
class ExtendedMotorCommand:
    """An extended (Klipper-style) command that switches motors on or off, read the way Klipper
    reads such a command (klippy/gcode.py ``_get_extended_params``: the first word is the command,
    then ``KEY=VALUE`` parameters separated by blanks, keys in any case, the last of a key counts, a
    word without ``=`` makes the line an error; ``;`` or ``#`` starts a comment). The parser's
    scanner (``gatesopt._scan``, the table packed by ``_scan_tables.pack_motor_commands``) and
    ``parse_motor_line`` (``read``) both read it from this record, the same way:

    - the line's first word is ``word`` (any case);
    - ``motor_param`` names the motors: its value is one name of ``motors`` (``lists``: a comma
      separated list of them), matched whole, in any case; names not in ``motors`` (a stepper the
      model has no axis for, ``stepper_z1``) are passed over; no known name: no motor line;
    - ``enable_param`` ("": the command has none) gives an integer, 0 off and anything else on
      (Klipper's ``get_int``; not an integer: an error, no motor line); absent: ``default_enable``
      (-1: without it the line is no motor line).
    """

    word: str                   # e.g. "SET_STEPPER_ENABLE"
    motor_param: str            # e.g. "STEPPER"
    motors: tuple               # ((name, motor letter), ...), e.g. (("stepper_x", "X"), ...)
    enable_param: str = ""      # e.g. "ENABLE"; "" when the command has none
    default_enable: int = -1    # 0 / 1 when ``enable_param`` is absent; -1: required
    lists: bool = False         # ``motor_param`` takes a comma separated list of names

    def read(self, words: list[str]) -> tuple[bool, tuple[str, ...]] | None:
        """``(on, motors)`` of a line whose upper-case code words are ``words``
        (``_text.code_words``), or None when it is not this command switching a known motor."""
        if not words or words[0] != self.word.upper():
            return None
        names = {n.upper(): m for n, m in self.motors}
        motors: tuple[str, ...] = ()
        enable = self.default_enable
        for w in words[1:]:
            comment = "#" in w
            w = w.split("#", 1)[0]
            if w:
                if "=" not in w:
                    return None                 # Klipper: "Malformed command"
                key, value = w.split("=", 1)
                if key == self.motor_param.upper():
                    got = {names[v] for v in (value.split(",") if self.lists else [value]) if v in names}
                    motors = tuple(m for m in AXES if m in got)
                elif self.enable_param and key == self.enable_param.upper():
                    try:
                        enable = 0 if int(value) == 0 else 1
                    except ValueError:
                        return None             # Klipper's get_int fails: an error
            if comment:
                break
        if not motors or enable < 0:
            return None
        return enable == 1, motors


@dataclass(frozen=True)
class PlannerRules:
    """What a firmware's motion planner does that ``gatesopt.limits`` / ``gatesopt.planner`` model:
    the stock configuration's limits and the rules a file for that firmware is planned by."""

    family: str                 # "marlin" | "klipper" | "reprap": the planner rules' name
    defaults: dict              # the stock configuration's limits (``limits.KEYS`` names)
    junction: str               # "deviation" (Marlin 2 JD) | "jerk" (classic) | "scv" (Klipper)
    junction_fixed: bool = False  # the planner has this junction rule only (Klipper)
    junction_note: str = ""     # where a fixed junction rule comes from (the limits' source)
    config_picks_junction: bool = False  # a slicer config's jerk / JD values say which rule runs
    jerk_is_scv: bool = False   # the slicer's machine_max_jerk_x is square_corner_velocity
    one_accel: bool = False     # one acceleration for every move (Klipper's max_accel)
    m204: str = "marlin"        # "klipper": M204 S, else min(P, T); "marlin": P / R / T (S legacy)
    feed_per_min: bool = False  # M203 feedrates in mm/min (RepRapFirmware)
    smoothed_lookahead: bool = False  # peak speeds capped as with Klipper's max_accel_to_decel
    disable_dwell_s: float = 0.0  # dwelled on top of the queue drain of each disable line


#: ``Firmware.split_moves``: every move may be split; all but extrude-only moves; none
SPLIT_MOVES = ("all", "kinematic", "none")
@dataclass(frozen=True)
class Schedule:
    """Gating the firmware times itself (a dialect's ``Firmware.schedule``; the Klipper module's
    protocol is the example): the dialect writes one off line right after the last step of the
    motors it names before their idle intervals, the firmware switches each motor off and on again
    by itself, and keeps an interval on unless the rules below hold. ``gatesopt.gating`` plans with
    these numbers (formulations/gating.md §9), ``gatesopt.verify`` derives the intervals from the
    lines with them.

    Per motor m (X Y Z E order): off at ``t_end + end_late + off_delay_s[m]`` (``t_end``: the end
    of the steps before the line), on at ``t_next - start_ahead - on_lead_s[m]`` (``t_next``: the
    start of m's next step). With ``gap`` the lower-bound time of the steps between the line and
    that next step (``planner.min_move_time_s``, arcs as the firmware's chords of
    ``arc_segment_mm``): rule A ``gap >= (end_late + off_delay) + (start_ahead + on_lead) +
    min_off_s``; rule B, between m's previous gated interval i and this one j, depends on how many
    changes of one pin the firmware keeps queued (``pin_queue_slots``, K): each change waits for the
    change K before it, and must then still have ``min_spacing_s`` of lead, so a change is at least
    ``min_spacing_s`` after the change K back. K = 1: from i's "on" to j's "off" at least
    ``min_spacing_s``, counted as ``(start_ahead + on_lead) + (lower-bound time from the step that
    ended i to j's line) + (end_late + off_delay)`` (and rule A's ``min_off_s`` carries the spacing
    of one interval's own off and on); K = 2: i's off to j's off and i's on to j's on at least
    ``min_spacing_s`` each, counted as the lower-bound time from i's line to j's line and from the
    step that ended i to the step that ends j (the margins are the same at both ends and cancel;
    the step that ends j is the end of the print when m never steps again). A homing step or one
    of the file's own motor lines the firmware carries out between line and next step: the
    firmware switches its motors itself there, the interval is not gated, and rule B starts over
    after it."""

    off_delay_s: tuple = (0.0, 0.0, 0.0, 0.0)   # beyond end-late, per motor: the firmware's own delay
    on_lead_s: tuple = (0.0, 0.0, 0.0, 0.0)     # beyond start-ahead, per motor: the firmware's own lead
    min_off_s: float = 0.0                      # rule A's floor
    min_spacing_s: float = 0.0                  # rule B
    pin_queue_slots: int = 1                    # rule B's form: changes of one pin queued at once (1, 2)
    arc_segment_mm: float = 1.0                 # the firmware's arc chords (lower bound of an arc's time)

    def __post_init__(self):
        # K >= 3 ties a change to the interval two gated intervals back (off of j to on of j - 2):
        # no longer a chain with one monotone predecessor, which the exact dp needs
        if self.pin_queue_slots not in (1, 2):
            raise FirmwareError(f"Schedule.pin_queue_slots must be 1 or 2, got {self.pin_queue_slots!r}")


class FirmwareError(GatesoptError, ValueError):
    """A gating request the chosen firmware cannot carry out safely."""


@dataclass(frozen=True)
class Firmware:
    """A dialect: what motor on/off instructions look like and cost on one firmware."""

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
    rank: int = 100               # place among the registry's names (the CLI's choices, ``detect``)
    detect_words: tuple = ()      # motor words that say a file is in this dialect (``detect``)
    detect_rank: int = 100        # which dialect ``detect`` tries first (lowest)
    motor_commands: tuple = ()    # ``ExtendedMotorCommand`` rows the parser reads as motor lines
    no_drain_words: frozenset = frozenset()   # motor words it carries out without draining the queue
    stall_is_stop: bool = False   # the disable stall is a full stop (priced by the planner when given)
    drains_on_disable: bool = True  # a disable brings the head to rest (``planner.Plan.stop_cost_s``)
    enable_is_stop: bool = False  # an enable line is a full stop priced per move where the caller
                                  # has a planner (``stall_durations(enable_price=...)``): then
                                  # ``enable_restart_s`` + the stop, instead of ``stall_on_s``
    enable_restart_s: float = 0.0  # what an enable line costs on top of its stop (Klipper's restart)
    disable_is_stop: bool = False  # the same for a disable line: ``disable_fixed_s`` + the stop,
                                   # instead of ``stall_off_s``, where the caller has a planner
    disable_fixed_s: float = 0.0   # what a disable line costs on top of its stop (Klipper's dwells)
    start_lead_s: float = 0.0     # counted on top of the start-ahead: the firmware steps this much
                                  # before a move's nominal start (Klipper's input shaper)
    note: str = ""                # what gating in this dialect cannot honour (said with the choice)
    split_moves: str = "all"      # which moves a gating line may split: "all", "kinematic" (not an
                                  # extrude-only move), "none"; a line that falls inside another
                                  # goes before (on) or after (off) the whole move
                                  # (``gating.timeline.whole_steps``, ``SPLIT_MOVES``)
    word_stalls: tuple = ()       # (word, off s, on s): a stall of its own for a word it carries out
    time_model: str = "paper"     # "planner": gating is priced with the planner (its limits, printer.cfg)
    planner: PlannerRules | None = field(default=None, repr=False)   # None: the file's own rules
    rotation_max_added_time_pct: float | None = None   # a rotation chosen by --rotate auto may make
                                  # the print (first extrusion to end, time model) at most this much
                                  # longer (``GatingOptions.max_rotation_added_time_pct``)

    # -- text -------------------------------------------------------------------------------------
    def off_lines(self, motors) -> list[str]:
        """Instruction lines (no line ending) that switch ``motors`` (letters) off."""
        motors = [m for m in AXES if m in set(motors)]
        return self._lines(self.off_word, motors, 0) if motors else []

    def on_lines(self, motors) -> list[str]:
        """Lines that switch ``motors`` on; empty when re-enable is automatic at the first step."""
        motors = [m for m in AXES if m in set(motors)]
        if self.on_word is None or not motors:
            return []
        return self._lines(self.on_word, motors, 1)

    def _lines(self, word: str, motors: list[str], enable: int) -> list[str]:
        """The dialect's writer: the lines switching ``motors`` (letters in X Y Z E order, at least
        one) off (``enable`` 0, ``word`` = ``off_word``) or on."""
        if self.merge_motors:
            return [f"{word} {' '.join(motors)}"]
        return [f"{word} {m}" for m in motors]

    def check_motors(self, motors) -> None:
        """Raise ``FirmwareError`` if this firmware must not gate one of ``motors``."""
        bad = [m for m in motors if m not in self.allowed_motors]
        if bad:
            raise FirmwareError(f"firmware {self.name!r} cannot gate motor(s) {','.join(bad)}: "
                                f"{self.refused_note or 'not allowed'}")

    # -- reading ------------------------------------------------------------------------------------
    def read_extended(self, words: list[str]) -> tuple[bool, tuple[str, ...]] | None:
        """``(on, motors)`` of an extended command line of this dialect (``words``: the line's
        upper-case code words, ``_text.code_words``), else None: its ``motor_commands`` read as
        the parser's scanner reads them (``ExtendedMotorCommand.read``)."""
        for c in self.motor_commands:
            if words and words[0] == c.word.upper():
                return c.read(words)
        return None

    def reads(self, text: str) -> tuple[bool, tuple[str, ...]] | None:
        """``parse_motor_line(text)`` if this firmware carries the line out, else None (an unknown
        command to it)."""
        parsed = parse_motor_line(text)
        if parsed is None or _words(text)[0] not in self.executes:
            return None
        return parsed

    # -- gating the firmware times itself ---------------------------------------------------------
    def schedule(self, printer=None, *, start_ahead_s: float, end_late_s: float) -> Schedule | None:
        """The firmware's own timing of its switches (``Schedule``), for a printer described by
        ``printer`` (``gatesopt.printer_config.PrinterConfig`` or None); None: the lines switch at
        the moment they are written (every stock dialect)."""
        return None

    def start_lead(self, printer=None) -> float:
        """What is counted on top of the start-ahead on a printer described by ``printer``
        (``gatesopt.printer_config.PrinterConfig`` or None): ``start_lead_s`` unless the dialect
        reads it from the printer (Klipper: its input shaper)."""
        return self.start_lead_s

    def enable_fixed_s(self, printer=None) -> float:
        """What an enable line that is a stop (``enable_is_stop``) costs on top of its stop, on a
        printer described by ``printer`` (or None): ``enable_restart_s`` unless the dialect reads
        it from the printer (Klipper: its input shaper's step window)."""
        return self.enable_restart_s

    def disable_fixed_s_at(self, printer=None) -> float:
        """``disable_fixed_s`` on a printer described by ``printer`` (or None), as ``enable_fixed_s``."""
        return self.disable_fixed_s

    def gating_defaults(self, printer=None) -> dict:
        """Gating options the printer's config fixes for this dialect (``GatingOptions`` field
        names, and ``gateable``: the motors it may gate there); none for a stock dialect."""
        return {}

    # -- costs -------------------------------------------------------------------------------------
    def n_off_lines(self, n_motors: int) -> int:
        return 0 if n_motors == 0 else (1 if self.merge_motors else n_motors)

    def n_on_lines(self, n_motors: int) -> int:
        if self.on_word is None or n_motors == 0:
            return 0
        return 1 if self.merge_motors else n_motors


Dialect = Firmware


# ------------------------------------------------------------------------------------------------
# the registry
PRESETS: dict[str, Firmware] = {}


def discover() -> None:
    """Load every dialect module of this package (each a ``DIALECT``) into ``PRESETS``, in ``rank``
    order; called once when the package is imported (again after ``__path__`` grows)."""
    found = list(PRESETS.values())
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        dialect = getattr(module, "DIALECT", None)
        if isinstance(dialect, Firmware):
            found.append(dialect)
    PRESETS.clear()
    for d in sorted({d.name: d for d in found}.values(), key=lambda d: (d.rank, d.name)):
        PRESETS[d.name] = d


def names() -> tuple[str, ...]:
    """The dialects' names, in the registry's order (the CLI's choices)."""
    return tuple(PRESETS)


def get(name: str | Firmware) -> Firmware:
    """The dialect called ``name`` (``3dgates``, ``marlin``, ``klipper``, ``reprap``, ...)."""
    if isinstance(name, Firmware):
        return name
    try:
        return PRESETS[str(name).lower()]
    except KeyError:
        raise FirmwareError(f"unknown firmware {name!r}: choose one of {', '.join(PRESETS)}") from None


_NO_RULES = object()


def planner_rules(family: str, default=_NO_RULES) -> PlannerRules:
    """The planner rules called ``family`` ("marlin", "klipper", "reprap"): those of the first
    dialect in the registry that has them (``default`` if none has, else ``FirmwareError``)."""
    for d in PRESETS.values():
        if d.planner is not None and d.planner.family == family:
            return d.planner
    if default is not _NO_RULES:
        return default
    raise FirmwareError(f"no dialect has the planner rules {family!r}")


def planner_families() -> tuple[str, ...]:
    """Every planner rules' name, in registry order."""
    return tuple(dict.fromkeys(d.planner.family for d in PRESETS.values() if d.planner is not None))


def no_drain_words() -> tuple[bytes, ...]:
    """Motor instruction words some dialect carries out without draining the motion queue (the
    3DGates patch's S0/S1, Marlin's M17), as ``planner.drains_queue`` reads them (bytes)."""
    words = dict.fromkeys(w for d in PRESETS.values() for w in sorted(d.no_drain_words))
    return tuple(w.encode() for w in words)


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


# ------------------------------------------------------------------------------------------------
# reading motor lines (every dialect's)
_words = _text.code_words      # a line's upper-case code words (comment, line number dropped)
_M_AND_S = ("S0", "S1", "M17", "M18", "M84")


def motor_line_word(text: str) -> str | None:
    """The instruction word of a motor enable/disable line (``"S0"``, ``"M17"``,
    ``"SET_STEPPER_ENABLE"``, ...: what ``Firmware.executes`` lists), None for any other line."""
    if parse_motor_line(text) is None:
        return None
    return _words(text)[0]


def parse_motor_line(text: str) -> tuple[bool, tuple[str, ...]] | None:
    """``(on, motors)`` for a motor enable/disable line of any dialect, else None.

    Understands ``S0``/``S1`` (3DGates Table 3) and ``M17``/``M18``/``M84`` (no axis word: all
    motors; ``M18 S<sec>``/``M84 S<sec>`` only sets the idle timeout and is not a disable) here, and
    each dialect's extended commands through its reader (``Firmware.read_extended``). Whether a given
    firmware carries the line out at all is ``Firmware.executes`` (``Firmware.reads``).
    """
    words = _words(text)
    if not words:
        return None
    head = words[0]
    if head in _M_AND_S:
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
    for d in PRESETS.values():
        if any(c.word.upper() == head for c in d.motor_commands):
            return d.read_extended(words)
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


#: lines where the machine is handed to the user or to a macro whose moves gatesopt does not
#: know: stops and pauses (M0 / M1, M25, M125 park, M226, M601, Klipper's PAUSE), filament change
#: and load / unload (M600, M602, M701, M702), tool changes (T<n>: on an IDEX or tool-changer
#: printer they move X). No motor is switched off across one (``gating.problem``; the verifier
#: checks it): during a pause the user may move the head by hand, and a motor without holding
#: torque loses its position. The curve ordering keeps such a layer's order (``ordering.layout``)
HANDOFF_M = (0, 1, 25, 125, 226, 600, 601, 602, 701, 702)
HANDOFF_COMMANDS = ("PAUSE",)


def handoff_lines(program: Program) -> np.ndarray:
    """Lines of ``program`` that hand the machine over (``HANDOFF_M``: M-codes, T tool changes,
    ``HANDOFF_COMMANDS``), ascending."""
    letter, number = program.line_letter, program.line_number
    out = ((letter == ord("M")) & np.isin(number, HANDOFF_M)) | (letter == ord("T"))
    ext = np.flatnonzero(letter == ord("@"))
    if len(ext):
        inverse, texts = _text.distinct_lines(program, ext)
        hit = np.array([(_text.code_words(t) or [""])[0] in HANDOFF_COMMANDS for t in texts],
                       bool)
        out[ext[hit[inverse]]] = True
    return np.flatnonzero(out)


def motor_line_is_on(text: str) -> bool | None:
    """True for an enable line, False for a disable line, None if ``text`` is neither."""
    r = parse_motor_line(text)
    return None if r is None else r[0]


# ------------------------------------------------------------------------------------------------
# the stall model
def stall_durations(program: Program, firmware: str | Firmware = "3dgates", *, planner=None,
                    enable_price=None, printer=None) -> np.ndarray:
    """Per-step stall time (s) of ``program``'s motor instructions under ``firmware``.

    Rows of ``Kind.MOTOR`` are enable/disable lines; every other row gets 0. A stall delays the
    moves after it, so an instruction after the last move (the slicer's closing ``M84``) costs none:
    the print is over. ``planner``, if given, is a callable ``planner(program, row) -> seconds`` used
    for a dialect whose disable stall is a full stop (``stall_is_stop``: Marlin's) instead of its
    fixed ``stall_off_s``. Under the acceleration-aware time model (``gatesopt.planner``), whose
    durations already bring the head to rest at every line that drains the queue
    (``planner.drains_queue``: M18/M84, SET_STEPPER_ENABLE), pass ``planner=lambda p, r: 0.0``
    so the stop is not counted twice; Klipper's two 0.1 s dwells stay. ``enable_price``, if given,
    is a callable ``enable_price(program, rows) -> seconds`` (one per row: the full stop at that
    line, ``planner.stop_restart_s``) used for a dialect whose enable line is a stop
    (``enable_is_stop``: Klipper's ``ENABLE=1`` flush), plus its ``enable_restart_s``, and whose
    disable line is one (``disable_is_stop``: Klipper's ``ENABLE=0``), plus its ``disable_fixed_s``
    (both fixed parts on the printer ``printer`` describes, ``Firmware.enable_fixed_s``: Klipper's
    restart grows with its input shaper's step window).
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
    heads = [_words(t)[0] if k else "" for k, t in zip(ok, texts)]
    ok &= np.array([h in fw.executes for h in heads], bool)
    own = dict((w, (off_s, on_s)) for w, off_s, on_s in fw.word_stalls)
    off_s = np.array([own.get(h, (fw.stall_off_s, fw.stall_on_s))[0] for h in heads], float)
    on_s = np.array([own.get(h, (fw.stall_off_s, fw.stall_on_s))[1] for h in heads], float)
    ok, on, off_s, on_s = ok[inverse], on[inverse], off_s[inverse], on_s[inverse]
    # an enable line stalls by its own price (Klipper's ENABLE=1: a look-ahead flush, no dwell)
    out[rows[ok]] = np.where(on[ok], on_s[ok], off_s[ok])
    if planner is not None and fw.stall_is_stop:
        for r in rows[ok & ~on]:
            out[r] = float(planner(program, int(r)))
    if enable_price is not None and fw.enable_is_stop and np.any(ok & on):
        r_on = rows[ok & on]
        out[r_on] = fw.enable_fixed_s(printer) + np.asarray(enable_price(program, r_on), float)
    if enable_price is not None and fw.disable_is_stop and np.any(ok & ~on):
        r_off = rows[ok & ~on]
        out[r_off] = fw.disable_fixed_s_at(printer) + np.asarray(enable_price(program, r_off), float)
    return out


#: the dialect written for each firmware family a file names (``slicers.FAMILIES``): what
#: ``gatesopt solve`` writes for it (``rewrite.printer.choose``) and ``gatesopt verify`` checks
DIALECT_OF_FAMILY = {"marlin": "marlin", "klipper": "klipper", "reprapfirmware": "reprap"}


def detect(program) -> str:
    """The dialect a file's own motor enable/disable lines are written in: the first dialect (by
    ``detect_rank``) one of whose ``detect_words`` a motor line starts with ("klipper" for
    SET_STEPPER_ENABLE, "marlin" for M17/M18 naming axes), else "3dgates" (also the answer when the
    file has none). M84 at the end of a print says nothing: every dialect has it."""
    rows = program.line[program.kind == Kind.MOTOR]
    if not len(rows):
        return "3dgates"
    present: set[str] = set()
    letters = program.line_letter[rows]
    numbers = program.line_number[rows]
    for letter, number in set(zip(letters.tolist(), numbers.tolist())):
        if letter == ord("@"):
            continue
        if letter in (ord("M"), ord("S")) and number == number and number == int(number):
            present.add(f"{chr(letter)}{int(number)}")
    ext = np.flatnonzero(letters == ord("@"))
    if len(ext):
        _, texts = _text.distinct_lines(program, rows[ext])
        present |= {_words(t)[0] for t in texts if _words(t)}
    for d in sorted(PRESETS.values(), key=lambda d: d.detect_rank):
        if present & set(d.detect_words):
            return d.name
    return "3dgates"


discover()

#: the extended commands the parser reads as motor lines (``Kind.MOTOR`` rows, the motor enables
#: they set): every dialect's ``motor_commands``, in the registry's order
EXTENDED_MOTOR_COMMANDS: tuple[ExtendedMotorCommand, ...] = tuple(
    c for d in PRESETS.values() for c in d.motor_commands)
