"""Defaults that fit the file's printer (issue 37): which firmware dialect gating writes, the time
budget a stock firmware gets, and the one line that says so.

``choose(program, "auto")`` reads the file (``gatesopt.slicers.read_printer``: a Klipper command,
a printer model, the slicer's flavor setting) and picks the dialect that printer's firmware runs:

- Marlin -> ``marlin`` (``M18 X Y`` / ``M17 X Y``), Klipper -> ``klipper``
  (``SET_STEPPER_ENABLE``), RepRapFirmware -> ``reprap`` (E only: its ``M18 X`` unhomes X);
- a firmware gatesopt has no dialect for (Bambu Lab's, whose ``M17 X`` sets motor currents;
  Repetier, Smoothieware, Makerbot, Ultimaker's Griffin) -> no gating, said so;
- nothing in the file -> ``marlin``, the most common stock firmware, said so with the choices.

The paper's ``S0``/``S1`` (``3dgates``) are written only when asked for by name: stock firmware
skips them as unknown commands. A dialect whose off line is ``M18`` is refused for a file made for
Klipper (klippy/extras/stepper_enable.py ``cmd_M18`` -> ``motor_off`` turns every stepper off and
``clear_homing_state("xyz")``: the next move fails "Must home axis first" and the print stops) or
for RepRapFirmware (``M18 X`` marks X not homed, the next X move is refused), unless forced by
name (``force=True``: ``--force-firmware NAME``).

A firmware whose motor lines stall the print (Marlin's queue drain, Klipper's dwells; ``stall_off_s``
or ``stall_on_s`` of its preset) gets ``STOCK_BUDGET_PCT`` of added print time as a budget unless
one is given: without it ``--firmware klipper`` added 0.3-11.9 % print time on fresh slices.
"""
from __future__ import annotations

from dataclasses import dataclass

from .. import firmware as fwmod
from .. import kinematics, slicers
from ..gating.options import GatingOptions

#: the dialect written for each firmware family a file names (``firmware.DIALECT_OF_FAMILY``)
DIALECT_OF_FAMILY = fwmod.DIALECT_OF_FAMILY
#: the dialect assumed when the file names no firmware: the most common stock firmware
ASSUMED_DIALECT = "marlin"
#: the print time a stock firmware's stalls may add by default, in % (``--max-added-time-pct``)
STOCK_BUDGET_PCT = 1.0
#: off-line words that stop a print on Klipper and on RepRapFirmware (see the module text)
_M18_WORDS = ("M18", "M84")
#: families whose firmware stops the print on an ``M18`` line
_M18_STOPS = {"klipper": "Klipper's M18 turns every motor off and clears homing, which stops the print",
              "reprapfirmware": "RepRapFirmware's M18 unhomes the axis and refuses its next move"}


class _Default:
    """The ``max_added_time_pct`` a caller did not give (None is "no budget", given)."""

    def __repr__(self) -> str:
        return "DEFAULT"


DEFAULT = _Default()


@dataclass(frozen=True)
class FirmwareChoice:
    """What gating writes for a file, and why (``choose``)."""

    firmware: str | None        # the dialect written (``gatesopt.firmware`` name); None: not gated
    requested: str              # "auto" or the name asked for
    max_added_time_pct: float | None
    budget_is_default: bool     # the budget is the stock-firmware default, not the caller's
    motors: tuple
    facts: slicers.PrinterFacts
    line: str                   # the one line that says it (``gatesopt solve``'s "firmware" line)
    options: GatingOptions | None = None

    def summary(self) -> dict:
        ev = self.facts.firmware
        return {"firmware": self.firmware, "requested": self.requested,
                "read": None if ev is None else {"family": ev.family, "kind": ev.kind, "line": ev.line,
                                                 "text": ev.text},
                "max_added_time_pct": self.max_added_time_pct, "budget_is_default": self.budget_is_default,
                "motors": list(self.motors), "line": self.line}


#: the name every report gives the firmware of a file whose printer gatesopt writes no motor line
#: for (``choose``: None, e.g. Bambu Lab's), and the dialect its own motor lines are priced and
#: checked in then: the paper's S0 / S1, which no stock firmware's line is, so none of them stalls
NOT_GATED, NOT_GATED_DIALECT = "none", "3dgates"


def file_firmware(program, printer=None) -> tuple[str, str]:
    """(name, dialect) of the firmware of ``program``'s printer: ``choose(program, "auto")`` (with
    ``printer``, a ``--printer-config``), the one detection every command reports: `solve`,
    `compare` and `batch` (their firmware line), `profile` and `order` (the stalls of the file's
    own motor lines, the print time) and `verify` (an output with no added motor line). The name
    is the dialect, or ``NOT_GATED`` where gatesopt gates nothing on that printer; the dialect,
    ``NOT_GATED_DIALECT`` there."""
    try:
        name = choose(program, printer=printer).firmware
    except fwmod.FirmwareError:
        name = None
    return (name or NOT_GATED, name or NOT_GATED_DIALECT)


def _stalls(name: str) -> bool:
    fw = fwmod.get(name)
    return fw.stall_off_s > 0 or fw.stall_on_s > 0


def _dialect_words(name: str) -> str:
    fw = fwmod.get(name)
    on = f"/{fw.on_word}" if fw.on_word and fw.on_word != fw.off_word else ""
    return f"{fw.off_word}{on} lines"


def _from_printer_config(facts: slicers.PrinterFacts, printer) -> tuple[str, str]:
    """(dialect, what was read) for ``--firmware auto`` with ``--printer-config``: a printer.cfg
    is Klipper's own config, so the printer runs Klipper whatever the slicer wrote (Klipper's
    docs/Slicers.md tells Cura and PrusaSlicer users to slice with the Marlin flavour, so a plain
    Cura file for a Klipper printer says "Marlin"; Marlin's ``M18`` would stop that print). With
    the module's ``[gatesopt_gating]`` section in it (the module is installed) and a printer
    klipper-gating models (cartesian): ``klipper-gating``, whose switches add no time; else stock
    ``klipper``."""
    from ..firmware.klipper_gating import kinematics_refusal
    name, how = "klipper", "a Klipper config"
    if printer.gating is not None:
        kin = printer.kinematics or "cartesian"
        if kin == "cartesian":
            name, how = "klipper-gating", "a Klipper config with gatesopt's [gatesopt_gating] module"
        else:
            how = (f"a Klipper config with [gatesopt_gating], but {kinematics_refusal(printer.source, kin)}"
                   "; stock SET_STEPPER_ENABLE lines instead")
    said = f"{name}: read --printer-config {printer.source}, {how} (the printer runs Klipper)"
    ev = facts.firmware
    if ev is not None and ev.family and ev.family != "klipper":
        said += f"; the file says {ev.family} ({ev.kind} {ev.where()}), as Klipper's docs have slicers write"
    return name, said


def _auto(facts: slicers.PrinterFacts, printer=None) -> tuple[str | None, str]:
    """(dialect, what was read) for ``--firmware auto``; ``printer``: the ``--printer-config``
    given, which decides (``_from_printer_config``)."""
    if printer is not None:
        return _from_printer_config(facts, printer)
    ev = facts.firmware
    if ev is None:
        names = "|".join(n for n in fwmod.PRESETS)
        return ASSUMED_DIALECT, (f"{ASSUMED_DIALECT} assumed: the file names no firmware (no flavor "
                                 f"setting, printer model or Klipper command); choose with --firmware {names}")
    name = DIALECT_OF_FAMILY.get(ev.family)
    if name is None:
        return None, (f"none: {ev.why} ({ev.kind} {ev.where()}) has no motor on/off line gatesopt "
                      "knows to be safe, so nothing is gated (--force-firmware NAME to gate anyway)")
    return name, f"{name}: read {ev.kind} {ev.where()}, {ev.why}"


def choose(program, requested: str = "auto", *, force: bool = False, max_added_time_pct=DEFAULT,
           motors: tuple | None = None, **gating) -> FirmwareChoice:
    """The dialect, budget and motors gating uses for ``program`` (a ``Program``, or a file's
    bytes), and the line that says so. ``requested``: "auto" or a ``gatesopt.firmware`` name;
    ``force``: write that dialect whatever the file says; ``max_added_time_pct``: DEFAULT (a
    stall-free dialect: none; a stock firmware: ``STOCK_BUDGET_PCT``), None (no budget) or a
    number; ``motors``: None for the default (X, Y; what the dialect may gate of them) or the
    motors asked for; ``gating``: other ``GatingOptions`` fields (rotate, profile, bed_size_mm,
    ...). Raises ``firmware.FirmwareError`` (one line) for a dialect that would stop the file's
    printer."""
    data = program if isinstance(program, (bytes, bytearray)) else program.data
    source = "<text>" if isinstance(program, (bytes, bytearray)) else program.source
    facts = (slicers.read_printer(bytes(data)) if isinstance(program, (bytes, bytearray))
             else slicers.program_printer(program))
    ev = facts.firmware
    printer_cfg = gating.get("printer")
    if requested == "auto":
        name, said = _auto(facts, printer_cfg)
    else:
        name = fwmod.get(requested).name
        said = f"{name} (--{'force-' if force else ''}firmware {name})"
        fw = fwmod.get(name)
        if printer_cfg is not None and fw.off_word in _M18_WORDS and not force:
            # the printer runs Klipper (its printer.cfg was given): Klipper would run the M18
            raise fwmod.FirmwareError(
                f"--printer-config {printer_cfg.source} is a Klipper config, so the printer runs "
                f"Klipper; {_M18_STOPS['klipper']}: use --firmware auto, klipper or klipper-gating")
        if ev is not None and ev.family in _M18_STOPS and fw.off_word in _M18_WORDS and not force:
            raise fwmod.FirmwareError(
                f"{source}:{ev.line}: the file is for {ev.family} ({ev.text!r}); {_M18_STOPS[ev.family]}: "
                f"use --firmware {DIALECT_OF_FAMILY[ev.family]} (or auto), or --force-firmware {name} "
                f"if it goes to a {name} printer")
        if name == "3dgates":
            said += ": carried out only by the paper's patched firmware (stock firmware skips them)"
        elif ev is not None and ev.family and DIALECT_OF_FAMILY.get(ev.family) != name:
            said += f"; the file says {ev.family or ev.why} ({ev.kind} {ev.where()})"
    if name is None:
        return FirmwareChoice(None, requested, None, False, (), facts, said)
    fw = fwmod.get(name)
    kin = kinematics.printer_kinematics(bytes(data), printer_cfg)
    coupled = kinematics.coupled_motors(kin.name if kin else None)
    if motors is None:
        motors = tuple(m for m in ("X", "Y") if m in fw.allowed_motors) or tuple(
            m for m in ("X", "Y", "Z", "E") if m in fw.allowed_motors)
        if kin is None and name in kinematics.UNKNOWN_KINEMATICS_UNSAFE:
            # stock Klipper re-enables a motor only after a move has begun stepping it: on a
            # corexy printer (most Klipper machines: Voron, RatRig, K1) a gated X or Y motor would
            # be stepped by the other axis's move (a layer shift; measured in Klipper's own host,
            # docs/RESULTS.md "Klipper replay: X/Y gating on a corexy printer"), so X/Y are gated
            # only where the kinematics is known
            kept = tuple(m for m in motors if m not in "XY")
            said += ("; kinematics unknown (no --printer-config, no printer model gatesopt knows): "
                     f"{','.join(m for m in motors if m in 'XY')} not gated (on a corexy printer "
                     "Klipper re-enables a motor after the other axis's move has begun stepping "
                     "it: a layer shift); --printer-config printer.cfg reads its [printer] "
                     "kinematics, --motors X,Y gates them on a cartesian printer")
            motors = kept
            if not motors:
                return FirmwareChoice(name, requested, None, False, (), facts, said)
        elif kin is not None and name in kinematics.UNKNOWN_KINEMATICS_UNSAFE and not coupled:
            said += f"; {kin.name} kinematics ({kin.source})"
        if any(m in coupled for m in motors):
            # gating models one motor per axis; on these printers it would switch off a motor the
            # other axis's next move steps (with an input shaper Klipper's automatic re-enable
            # comes after the first steps: a layer shift), and its saving would be counted wrong
            kept = tuple(m for m in motors if m not in coupled)
            said += (f"; {kin.name} kinematics ({kin.source}): {kinematics.coupled_words(coupled)}, so "
                     f"{','.join(m for m in motors if m in coupled)} are not gated")
            motors = kept
            if not motors:
                said += ("; nothing is gated (--motors E, or Z where the Z axis holds unpowered, "
                         "to gate those)")
                return FirmwareChoice(name, requested, None, False, (), facts, said)
        elif motors != ("X", "Y"):
            said += f"; gates {','.join(motors)} only ({fw.refused_note or 'the firmware allows no other'})"
    else:
        kinematics.refuse_coupled(kin, motors, source)
    default_budget = max_added_time_pct is DEFAULT
    if default_budget:
        max_added_time_pct = STOCK_BUDGET_PCT if _stalls(name) else None
    budget_words = ("no time budget" if max_added_time_pct is None
                    else f"the print takes at most {max_added_time_pct:g} % longer than as sliced "
                         "(planner model; stalls, re-ordering and rotation together)")
    if default_budget and max_added_time_pct is not None:
        budget_words += " (the default for stock firmware; --max-added-time-pct P or none to change)"
    said += f"; {_dialect_words(name)}, {budget_words}"
    if fw.note:
        said += f"; {fw.note}"
    if (requested == "auto" and name == "marlin" and printer_cfg is None
            and (ev is None or ev.kind == "flavor setting")):
        # a Marlin flavour is what Klipper's docs tell Cura and PrusaSlicer users to set: nothing
        # in such a file tells a Klipper printer from a Marlin one, and M18 stops a Klipper print
        said += ("; if the printer runs Klipper, pass its printer.cfg (--printer-config): "
                 "Klipper's M18 turns every motor off and the print stops")
    if name == "klipper" and "klipper-gating" in fwmod.PRESETS:
        said += ("; with gatesopt's Klipper module installed (integrations/klipper), --firmware "
                 "klipper-gating switches motors without stalls")
    opts = GatingOptions.for_firmware(name, motors=tuple(motors), max_added_time_pct=max_added_time_pct,
                                      **gating)
    return FirmwareChoice(name, requested, max_added_time_pct, default_budget and max_added_time_pct is not None,
                          tuple(opts.motors), facts, said, opts)
