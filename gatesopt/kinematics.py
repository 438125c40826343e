"""The printer's kinematics: which motors move which axes, as far as gating must know it.

gatesopt's gating model is one motor per axis (the X motor steps when X moves: a cartesian
printer). On corexy (Voron, Creality K1, QIDI, Prusa Core One / XL) both X/Y motors step for every
X or Y move, so a motor switched off while "its" axis rests is stepped by the other axis's next
move; such motors are not gated (``rewrite.printer.choose``) and the verifier reports a line that
gates one (``verify.firmware``). The kinematics is read from the printer.cfg where given (Klipper's
``[printer] kinematics``), else from the printer model the slicer names (``PRINTER_KINEMATICS``);
unknown is taken as cartesian where the firmware enables a motor before a move steps it, and
said where it decides; stock Klipper gates no X/Y motor of an unknown kinematics
(``UNKNOWN_KINEMATICS_UNSAFE``).
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from .firmware import FirmwareError
from .slicers import printer_models

#: printers whose X and Y motors are not one axis each (``model_kinematics``): on corexy both the
#: A and the B motor step for every X or Y move, so a motor gated while "its" axis rests would be
#: stepped by the other axis's moves (Klipper: klippy/kinematics/corexy.py, each stepper's
#: itersolve is active on x and y). Matched like ``PRINTER_MODELS``; the first row that matches
#: decides (Voron's Switchwire is corexz, every other Voron corexy).
PRINTER_KINEMATICS = (
    (r"switchwire", "corexz"),
    # common bed-slingers, one motor per axis (the Ender-3 V3 without SE/KE is corexz: not here;
    # a model not listed is unknown, which stock Klipper does not gate X/Y on)
    (r"ender[- ]?3(?![- ]?v3(?![- ]?(se|ke)))|\bcr-?10\b|prusa i3|^(original prusa )?mk(2|3|4)"
     r"|^(original prusa )?mini\b|sovol sv0[67]\b", "cartesian"),
    (r"voron", "corexy"),
    (r"\bk1\b|k1 ?max|\bk1c\b|cr-k1|\bk2 ?(plus|pro)\b", "corexy"),    # Creality K1 / K2
    (r"v-core", "corexy"),                                            # RatRig V-Core
    (r"qidi|x-(plus|max|smart) ?3|\bq1 ?pro\b", "corexy"),
    (r"sovol sv08\b", "corexy"),
    (r"core ?one", "corexy"),                                          # Prusa Core One
    (r"^(prusa )?xl\d*(is)?$", "corexy"),                             # Prusa XL (PrusaSlicer: XL, XL5...)
    (r"bambu lab (x1|p1)", "corexy"),
)


@dataclass(frozen=True)
class Kinematics:
    """How the printer's motors move the head, where the file's printer model says it
    (``model_kinematics``) or the printer.cfg does: ``name`` as Klipper's ``[printer]
    kinematics`` spells it."""

    name: str
    source: str         # e.g. "printer model '; printer_model = Voron_v2_250' (line 12)"


#: dialects that must know the kinematics before X or Y is gated by default (``rewrite.printer.
#: choose``): stock Klipper enables a disabled stepper when a move has begun stepping it, so on a
#: corexy printer gating X or Y shifts the layer; Marlin and RepRapFirmware enable the motors a
#: move needs before it steps (there gating a coupled motor only counts a saving not made)
UNKNOWN_KINEMATICS_UNSAFE = frozenset({"klipper"})


def model_kinematics(data: bytes) -> Kinematics | None:
    """The kinematics of the printer model the slicer names, where ``PRINTER_KINEMATICS`` knows
    it (None: unknown, which gating takes as one motor per axis, cartesian)."""
    for line, text, value in printer_models(data):
        for pat, name in PRINTER_KINEMATICS:
            if re.search(pat, value.strip(), re.I):
                return Kinematics(name, f"printer model '{text}' (line {line})")
    return None


#: motors that are not one axis each, per kinematics (Klipper's ``[printer] kinematics`` names):
#: gated while "their" axis rests they would still be stepped by the other axis's moves (corexy:
#: klippy/kinematics/corexy.py, stepper A is x + y, B is x - y; corexz likewise in x and z; a
#: delta's towers all move for every axis). Any name not here but "cartesian" couples X, Y, Z.
COUPLED_MOTORS = {"cartesian": "", "corexy": "XY", "hybrid_corexy": "XY", "markforged": "XY",
                  "corexz": "XZ", "hybrid_corexz": "XZ"}


def coupled_motors(kinematics: str | None) -> str:
    """The motors of X, Y, Z that ``kinematics`` moves together (None: one per axis, assumed)."""
    if kinematics is None:
        return ""
    return COUPLED_MOTORS.get(kinematics.lower(), "XYZ")


def coupled_words(coupled: str) -> str:
    """Why motors ``coupled`` (``coupled_motors``) are not gated, in a few words."""
    return f"its {'/'.join(coupled)} motors all step for every move of {' or '.join(coupled)}"


def printer_kinematics(data: bytes, printer=None) -> Kinematics | None:
    """The printer's kinematics: the printer.cfg's (``printer``: a ``PrinterConfig``) where given,
    else the printer model's (``model_kinematics``); None: unknown (one motor per axis assumed)."""
    if printer is not None and printer.kinematics:
        return Kinematics(printer.kinematics, f"--printer-config {printer.source}")
    return model_kinematics(data)


def check_gateable(data: bytes, motors, printer=None, source: str = "<text>") -> None:
    """Raise ``FirmwareError`` (``source`` and what says it) if ``motors`` names a motor the
    printer's kinematics (``printer_kinematics`` of ``data``, a file's bytes or its head and
    tail, and ``printer``) couples to another axis: the firmware choice never picks one; this
    guards a caller that builds its own ``GatingOptions`` (``rewrite.pipeline.run``,
    ``stream.gate_stream``)."""
    refuse_coupled(printer_kinematics(data, printer), motors, source)


def refuse_coupled(kin: Kinematics | None, motors, source: str = "<text>") -> None:
    """``check_gateable`` for kinematics ``kin`` read already (None: unknown, one motor per axis)."""
    coupled = coupled_motors(kin.name if kin else None)
    bad = [m for m in motors if m.upper() in coupled]
    if bad:
        raise FirmwareError(
            f"{source}: {kin.name} kinematics ({kin.source}): {coupled_words(coupled)}, so "
            f"{','.join(bad)} cannot be gated while that axis rests (gatesopt models one motor "
            f"per axis); gate {','.join(m for m in 'ZE' if m not in coupled)} instead")
