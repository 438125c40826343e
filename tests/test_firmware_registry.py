"""Firmware dialects as modules (issue 35): each module of ``gatesopt.firmware`` is one dialect,
found by name; the CLI's choices, the scanner's extended-command table, the planner's stock
limits and its non-draining words are read from the dialects, never copied."""
from __future__ import annotations

import pkgutil
import sys
import textwrap

import pytest

from gatesopt import firmware, limits, parse, planner
from gatesopt.cli import build_parser


def test_every_module_is_a_dialect_and_the_registry_lists_them_all():
    modules = [m.name for m in pkgutil.iter_modules(firmware.__path__) if not m.name.startswith("_")]
    dialects = [sys.modules[f"gatesopt.firmware.{m}"].DIALECT for m in modules]
    assert sorted(d.name for d in dialects) == sorted(firmware.names())
    assert firmware.names()[:4] == ("3dgates", "marlin", "klipper", "reprap")
    for d in dialects:
        assert firmware.get(d.name) is d
    # the scanner's table is every dialect's rows, nothing else
    assert firmware.EXTENDED_MOTOR_COMMANDS == tuple(
        c for name in firmware.names() for c in firmware.get(name).motor_commands)


def test_planner_knowledge_comes_from_the_dialects():
    for family in ("marlin", "klipper", "reprap"):
        rules = firmware.planner_rules(family)
        assert limits.PRINTER_DEFAULTS[family] == rules.defaults
        assert limits.DEFAULT_JUNCTION[family] == rules.junction
    assert set(firmware.no_drain_words()) >= {b"S0", b"S1", b"M17"}
    p = parse("G28\nG1 X10 F600\nS0 X\nG1 Y10\nM17 X\nG1 X0\nM18 X\nG1 Y0\n")
    motor = p.kind == 9
    assert planner.drains_queue(p)[motor].tolist() == [False, False, True]


def test_a_dialect_module_added_to_the_package_is_found_and_offered(tmp_path, monkeypatch):
    """Adding a dialect touches one new file: written here into a folder of the package's path, it
    is a choice of every command, its extended command is read as a motor line, its writer writes."""
    (tmp_path / "grbl_test.py").write_text(textwrap.dedent('''
        from dataclasses import dataclass
        from gatesopt.firmware import ExtendedMotorCommand, Firmware

        @dataclass(frozen=True)
        class Mine(Firmware):
            def _lines(self, word, motors, enable):
                return [f"MOTORS_{'ON' if enable else 'OFF'} AXES={''.join(motors)}"]
            def read_extended(self, words):
                if words[0].startswith("MOTORS_") and words[1:] and words[1].startswith("AXES="):
                    return words[0] == "MOTORS_ON", tuple(m for m in "XYZE" if m in words[1][5:])
                return None

        DIALECT = Mine(name="grbl-test", off_word="MOTORS_OFF", on_word="MOTORS_ON", merge_motors=True,
                       stall_off_s=0.0, stall_on_s=0.0, reenable="exact", homing_kept=True,
                       allowed_motors=frozenset("XY"), executes=frozenset({"MOTORS_OFF", "MOTORS_ON"}),
                       motor_commands=(ExtendedMotorCommand("MOTORS_OFF", "AXES", (("X", "X"),)),
                                       ExtendedMotorCommand("MOTORS_ON", "AXES", (("X", "X"),))))
        '''))
    before = dict(firmware.PRESETS)
    monkeypatch.setattr(firmware, "__path__", list(firmware.__path__) + [str(tmp_path)])
    try:
        firmware.discover()
        assert "grbl-test" in firmware.names()
        fw = firmware.get("grbl-test")
        assert fw.off_lines("YX") == ["MOTORS_OFF AXES=XY"] and fw.on_lines("X") == ["MOTORS_ON AXES=X"]
        assert firmware.parse_motor_line("MOTORS_OFF AXES=XY ; gate") == (False, ("X", "Y"))
        assert fw.reads("MOTORS_ON AXES=Y") == (True, ("Y",)) and fw.reads("M18 X") is None
        sub = next(a for a in build_parser("solve")._actions if a.dest == "command")
        opt = next(a for a in sub.choices["solve"]._actions if "--firmware" in a.option_strings)
        assert "grbl-test" in opt.choices
    finally:
        firmware.PRESETS.clear()
        firmware.PRESETS.update(before)
        sys.modules.pop("gatesopt.firmware.grbl_test", None)


def test_unknown_dialect_is_a_clear_error():
    with pytest.raises(firmware.FirmwareError, match="choose one of 3dgates, marlin, klipper, reprap"):
        firmware.get("grbl")
