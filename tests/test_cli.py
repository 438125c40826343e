"""The command line's shape: choices read from the library's registries, command modules that import
no other command, and a command that does not load what only the others need."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import gatesopt.cli
from gatesopt import firmware
from gatesopt.cli import build_parser
from gatesopt.gating import FORMULATIONS as GATING_FORMULATIONS

CLI = Path(gatesopt.cli.__file__).parent
#: the modules of what commands share; a command module imports from the CLI only these
SHARED = {"files", "options", "progress", "summary"}


def _option(command: str, flag: str):
    sub = next(a for a in build_parser(command)._actions if a.dest == "command")
    return next(a for a in sub.choices[command]._actions if flag in a.option_strings)


@pytest.mark.parametrize("command", ["solve", "compare", "batch"])
def test_every_firmware_preset_is_a_choice(command):
    """`--firmware reprap` was refused by solve, compare and batch while verify offered it."""
    assert tuple(_option(command, "--firmware").choices) == ("auto",) + tuple(firmware.PRESETS)
    assert tuple(_option("verify", "--firmware").choices) == ("auto",) + tuple(firmware.PRESETS)


def test_a_registry_entry_added_in_the_library_is_a_choice(monkeypatch):
    monkeypatch.setitem(firmware.PRESETS, "myfirmware", firmware.PRESETS["marlin"])
    monkeypatch.setitem(GATING_FORMULATIONS, "mine", GATING_FORMULATIONS["dp"])
    args = build_parser("solve").parse_args(["solve", "in.gcode", "--firmware", "myfirmware",
                                             "--formulation", "mine"])
    assert (args.firmware, args.formulation) == ("myfirmware", "mine")


def test_ordering_choices_are_the_registry_without_the_small_group_dp():
    from gatesopt.ordering import FORMULATIONS
    choices = tuple(_option("order", "--formulation").choices)
    assert "dp" in FORMULATIONS and "dp" not in choices
    assert set(choices) == set(FORMULATIONS) - {"dp"}
    assert tuple(_option("solve", "--order-formulation").choices) == choices


def test_solve_with_reprap_says_which_motors_it_cannot_gate(capsys):
    from conftest import PROJECT_INSTANCES
    src = str(PROJECT_INSTANCES / "square_lines.gcode")
    assert gatesopt.cli.main(["solve", src, "-o", "-", "--firmware", "reprap", "--no-order",
                              "--motors", "X,Y"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot gate motor(s) X,Y" in err[0]
    # without --motors it gates what RepRapFirmware may gate, and says why
    assert gatesopt.cli.main(["solve", src, "-o", "-", "--firmware", "reprap", "--no-order"]) == 0
    report = capsys.readouterr().err
    assert "gates E only (RepRapFirmware's M18 marks X/Y/Z not homed" in report


def test_no_command_module_imports_another():
    for path in sorted(CLI.glob("*.py")):
        if path.name == "__init__.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                names = {node.module} if node.module else {a.name for a in node.names}
                assert names <= SHARED, f"{path.name} imports {names - SHARED} from the CLI"


def test_a_command_loads_only_what_it_needs():
    """Building `profile`'s parser imports neither gating nor ordering (their registries are read
    by the commands that offer their choices)."""
    code = ("import sys; from gatesopt.cli import build_parser; build_parser('profile'); "
            "print(sorted(m for m in sys.modules if m.startswith(('gatesopt.gating', 'gatesopt.ordering'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
