"""The parser's scanner and ``firmware.parse_motor_line`` read an extended motor command alike,
from the dialect's ``ExtendedMotorCommand`` record, the way Klipper reads it.

Regression: the scanner took ``SET_STEPPER_ENABLE STEPPER=extruder ENABLE=0`` -- what gatesopt
itself writes to gate E on Klipper -- for no motor line, and ``STEPPER=stepper_xyz`` for X (a
prefix match), while ``parse_motor_line`` read them right; the reader read ``STEPPERS=a,b`` lists,
which Klipper 84104bb's SET_STEPPER_ENABLE (a mux command on one STEPPER) answers with an error.
"""
from __future__ import annotations

import itertools
import random

import pytest

from gatesopt import Kind, firmware, parse
from gatesopt.program import AXES

LINES = [
    ("SET_STEPPER_ENABLE STEPPER=extruder ENABLE=0", (False, ("E",))),
    ("SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=0", (False, ("X",))),
    ("SET_STEPPER_ENABLE STEPPER=stepper_z ENABLE=1", (True, ("Z",))),
    ("SET_STEPPER_ENABLE STEPPER=stepper_x", (True, ("X",))),               # ENABLE defaults to 1
    ("set_stepper_enable stepper=stepper_y enable=0 ; note", (False, ("Y",))),
    ("SET_STEPPER_ENABLE STEPPER=stepper_y ENABLE=0 STEPPER=stepper_x", (False, ("X",))),  # the last
    ("SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=2", (True, ("X",))),      # get_int: not 0 is on
    ("SET_STEPPER_ENABLE STEPPER=stepper_xyz ENABLE=0", None),              # no such stepper
    ("SET_STEPPER_ENABLE STEPPER=stepper_z1 ENABLE=0", None),               # not an axis of the model
    ("SET_STEPPER_ENABLE STEPPERS=stepper_x,stepper_y ENABLE=0", None),     # an error in Klipper
    ("SET_STEPPER_ENABLE STEPPER=stepper_x,stepper_y ENABLE=0", None),
    ("SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=off", None),              # get_int fails
    ("SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=0 junk", None),           # malformed
    ("SET_STEPPER_ENABLEX STEPPER=stepper_x ENABLE=0", None),               # another command
    ("SET_STEPPER_ENABLE ENABLE=0", None),
    ("SET_STEPPER_ENABLE STEPPER=stepper_x # ENABLE=0", (True, ("X",))),    # '#' starts a comment
]


def _scanned(line: str):
    """(a motor row?, on, motors) as the parser's scanner read ``line``: the state of every motor
    after it, against a state where all are on (X Y Z E stepped first)."""
    p = parse(f"G28\nG1 X1 Y1 Z1 E1 F600\n{line}\nG4 P1\n")
    rows = [r for r in range(p.n_steps) if int(p.line[r]) == 2]
    if not rows or p.kind[rows[0]] != Kind.MOTOR:
        return None
    en = p.enabled[rows[0]]
    off = tuple(m for i, m in enumerate(AXES) if not en[i])
    return (False, off) if off else (True, None)


@pytest.mark.parametrize("line,want", LINES)
def test_scanner_and_reader_agree_with_klipper(line, want):
    assert firmware.parse_motor_line(line) == want
    got = _scanned(line)
    if want is None:
        assert got is None
    elif want[0]:
        assert got == (True, None)
    else:
        assert got == want


def test_random_extended_lines_are_read_alike():
    """Words drawn from what such lines contain, any order and case: both readers agree."""
    rng = random.Random(7)
    words = ["STEPPER=stepper_x", "STEPPER=extruder", "stepper=stepper_y", "STEPPERS=stepper_x,stepper_z",
             "STEPPER=stepper_zz", "ENABLE=0", "ENABLE=1", "enable=0", "ENABLE=x", "X1", "FOO=1",
             "STEPPER=", "ENABLE=", ";c", "#c"]
    seen = set()
    for _ in range(300):
        line = " ".join(["SET_STEPPER_ENABLE"] + rng.sample(words, rng.randint(0, 4)))
        if line in seen:
            continue
        seen.add(line)
        want = firmware.parse_motor_line(line)
        got = _scanned(line)
        if want is None or want[0]:
            assert got == (None if want is None else (True, None)), line
        else:
            assert got == want, line


def test_klipper_e_gating_output_is_read_back_as_a_motor_line():
    fw = firmware.get("klipper")
    for motors in itertools.chain.from_iterable(itertools.combinations("XYZE", k) for k in (1, 2)):
        for text in fw.off_lines(motors):
            parsed = firmware.parse_motor_line(text)
            assert parsed is not None and parsed[0] is False, text
            assert _scanned(text) == parsed, text
