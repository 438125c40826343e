"""Check 4b, ``firmware``: every motor line the rewrite added is one the firmware carries out as
gating means it (its dialect, a motor it may gate, the axis kept homed); see ``gatesopt.verify``."""
from __future__ import annotations

import numpy as np

from .. import firmware as fwmod
from .. import kinematics as kinmod
from ..program import AXES, Program
from .finding import Finding
from .motor_lines import added_motor_lines

# M84 is M18 under another number (Marlin's ``GcodeSuite::M18_M84``; the parser reads them alike,
# ``firmware.parse_motor_line``): a line's instruction word is compared as M18.
_SAME_WORD = {"M84": "M18"}
_HOMED = AXES[:3]       # the axes a printer homes (X Y Z); the extruder has no home


def _dialect(fw: fwmod.Firmware) -> tuple[str, ...]:
    """The instruction words ``fw`` gates with (``Firmware.off_word`` / ``on_word``)."""
    return tuple(w for w in (fw.off_word, fw.on_word) if w is not None)


def _motor_word(text: str) -> str:
    """The instruction word of a motor line (``firmware.motor_line_word``: ``S0``, ``M18``,
    ``SET_STEPPER_ENABLE``), ``M84`` read as ``M18``."""
    word = fwmod.motor_line_word(text) or ""
    return _SAME_WORD.get(word, word)


def firmware_problem(text: str, firmware="3dgates") -> str | None:
    """Why ``firmware`` would not carry out the motor enable/disable line ``text`` the way gating
    means it (switch just the named motors, keep the axes homed), or None if it would (or ``text``
    is no motor line). Everything is read from ``gatesopt.firmware``: the dialect
    (``Firmware.off_word`` / ``on_word``), ``allowed_motors`` (with ``refused_note``) and
    ``homing_kept``."""
    fw = fwmod.get(firmware)
    parsed = fwmod.parse_motor_line(text)
    if parsed is None:
        return None
    on, motors = parsed
    shown = text.split(";", 1)[0].strip()
    word = _motor_word(text)
    own = _dialect(fw)
    if word not in own:
        owners = [name for name, p in fwmod.PRESETS.items() if word in _dialect(p)]
        whose = f"{'/'.join(owners)}'s" if owners else "no firmware's"
        return f"{shown} is {whose} motor instruction, not {fw.name}'s ({fw.name} gates with {' / '.join(own)})"
    if on:
        return None
    refused = [m for m in motors if m not in fw.allowed_motors]
    if refused:
        return (f"{shown} switches motor {','.join(refused)} off, which {fw.name} may not gate: "
                f"{fw.refused_note or 'not allowed'}")
    unhomed = [m for m in motors if m in _HOMED]
    if not fw.homing_kept and unhomed:
        return f"{shown} switches axis {','.join(unhomed)} off, and {fw.name} forgets it is homed after a disable"
    return None


def coupled_problem(text: str, kinematics) -> str | None:
    """Why the disable line ``text`` switches off a motor the printer's ``kinematics``
    (``slicers.Kinematics``) moves for another axis too (corexy: X and Y), or None."""
    coupled = kinmod.coupled_motors(kinematics.name if kinematics else None)
    parsed = fwmod.parse_motor_line(text) if coupled else None
    if parsed is None or parsed[0]:
        return None
    bad = [m for m in parsed[1] if m in coupled]
    if not bad:
        return None
    return (f"{text.split(';', 1)[0].strip()} switches {','.join(bad)} off on a {kinematics.name} "
            f"printer ({kinematics.source}): {kinmod.coupled_words(coupled)}, so the next move of "
            f"the other axis steps a motor that is off")


def check_firmware(output: Program, *, firmware="3dgates", original: Program | None = None,
                   max_findings: int = 10, printer=None) -> list[Finding]:
    """Every motor enable/disable line the rewrite added (``added_motor_lines``; the original's own
    lines are not checked) is one ``firmware`` carries out as gating means it
    (``firmware_problem``): its own dialect, a motor it may gate, the axis kept homed; and none
    switches off a motor the printer's kinematics couples to another axis (``coupled_problem``:
    the kinematics of ``printer``, a printer.cfg, else of the printer model the file names)."""
    fw = fwmod.get(firmware)
    rows, inverse, texts = added_motor_lines(original, output)
    kin = kinmod.printer_kinematics(bytes((original or output).data), printer)
    problem = [firmware_problem(t, fw) or coupled_problem(t, kin) for t in texts]
    bad = np.array([p is not None for p in problem], bool)
    if not len(rows) or not bad.any():
        return []
    hit = np.flatnonzero(bad[inverse])[:max_findings]
    return [Finding("firmware", int(output.line[rows[h]]) + 1, problem[inverse[h]]) for h in hit.tolist()]


def detect_firmware(original: Program | None, output: Program, printer=None) -> str:
    """The firmware ``gatesopt verify --firmware auto`` checks ``output`` for (``firmware_of``)."""
    return firmware_of(original, output, printer)[1]


def firmware_of(original: Program | None, output: Program, printer=None) -> tuple[str, str, bool]:
    """(name, dialect, gated) of the firmware ``gatesopt verify --firmware auto`` checks ``output``
    for. ``gated``: the rewrite added motor lines. Then the dialect is the one of the file's
    printer (``rewrite.printer.file_firmware``, as ``gatesopt solve`` reads it) where that
    firmware takes every line the rewrite added, else ``firmware.detect`` (the dialect of the
    output's motor lines) when that firmware takes them all (``firmware_problem``), else the
    first preset that does -- so a start G-code's own ``M17`` does not make S-series output
    Marlin's; when no preset takes them all, ``detect``'s answer stands (and ``check_firmware``
    reports the lines); the name is the dialect's. Without added lines: the firmware of the
    file's printer, named as `solve` and `profile` name it ("none" where gatesopt gates nothing
    on it, checked in the paper's dialect, which prices none of the file's own lines)."""
    from ..rewrite.printer import file_firmware     # the one detection (not at import: a cycle)
    guess = fwmod.detect(output)
    _, inverse, texts = added_motor_lines(original, output)
    texts = [texts[k] for k in np.unique(inverse).tolist()]
    if not texts:
        return (guess, guess, False) if original is None else (*file_firmware(original, printer), False)
    takes = [name for name in fwmod.PRESETS
             if all(firmware_problem(t, name) is None for t in texts)]
    # the dialect the original's printer runs (its slicer's flavour, printer model or Klipper
    # command, as ``gatesopt solve`` reads it) where it takes every added line: RepRapFirmware's
    # M18 / M17 read as Marlin's too, and its rules (stalls, motors) are not Marlin's
    named = None if original is None else file_firmware(original, printer)[1]
    name = named if named in takes else guess if guess in takes or not takes else takes[0]
    return name, name, True
