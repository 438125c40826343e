"""The README's library example runs as written (on a bundled instance instead of print.gcode), and
leads with the whole job (``rewrite.run``), which verifies where the step-by-step path cannot (a
rotated print, issue 37)."""
from __future__ import annotations

import re

import pytest

from conftest import PROJECT_INSTANCES, REPO as ROOT, SHARED_INSTANCES


def _block() -> str:
    text = (ROOT / "README.md").read_text()
    return re.search(r"## Library\s+```python\n(.*?)```", text, re.S).group(1)


def test_the_library_example_runs(capsys):
    block = _block()
    assert "ordering.solve" in block and "gating.solve" in block
    # the whole job leads; the step-by-step gating comes after it
    assert block.index("rewrite.run(") < block.index("gating.solve(")
    code = block.replace('"print.gcode"', repr(str(PROJECT_INSTANCES / "star_lines_m82.gcode")))
    exec(compile(code, "README.md (## Library)", "exec"), {})
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("marlin: read flavor setting '; gcode_flavor = marlin2' (line 5)")
    assert "candidate angles" in out[1] or out[1].startswith("none")
    assert out[2].startswith("True ")                       # the whole job verified
    assert out[-1] == "[0 2 1] [False False  True]"     # the polyline example's order


@pytest.mark.skipif(not (SHARED_INSTANCES / "prusa25_star_rect15_m82.gcode.gz").exists(),
                    reason="development corpus not found")
def test_the_whole_job_verifies_a_rotated_prusaslicer_file(tmp_path):
    """The survey's case: the old README steps (build -> solve -> emit) on this rotated file gave
    output `gatesopt verify` refused (end-late 0.967 ms); the whole job solves the rotated print
    again, and its output verifies on its own."""
    import gatesopt
    from gatesopt import rewrite
    from gatesopt.cli import main
    src = SHARED_INSTANCES / "prusa25_star_rect15_m82.gcode.gz"
    program = gatesopt.parse(src)
    res = rewrite.run(program, choice=rewrite.choose(program, "3dgates"), order=False)
    assert res.summary()["rotation_deg"] != 0.0 and res.report.ok
    out = tmp_path / "star.gcode"
    out.write_text(res.text)
    assert main(["verify", str(src), str(out)]) == 0


# -- the first hour: "For your printer" ------------------------------------------------------------
FRESH = ROOT.parent / "fresh"


def _printer_blocks() -> list[tuple[list[str], list[str]]]:
    """(the command's words, the lines shown) of each ``$ gatesopt solve ...`` block of the
    README's "For your printer" section."""
    text = (ROOT / "README.md").read_text()
    section = re.search(r"## For your printer\n(.*?)\n## ", text, re.S).group(1)
    blocks = []
    for body in re.findall(r"```\n(\$ gatesopt solve .*?)```", section, re.S):
        first, *shown = body.rstrip("\n").splitlines()
        blocks.append((first[2:].split(), shown))
    return blocks


def test_the_recipes_show_a_prusaslicer_a_cura_and_a_klipper_file():
    names = [words[2] for words, _ in _printer_blocks()]
    assert any(n.startswith("prusa25_") for n in names)
    assert any(n.startswith("cura413_") for n in names)
    assert any("orca" in n for n in names)
    # the rotation is shown on and off, and the paper's firmware by name
    assert any("--bed" in words for words, _ in _printer_blocks())
    assert any(words[-2:] == ["--firmware", "3dgates"] for words, _ in _printer_blocks())


@pytest.mark.parametrize("index", range(len(_printer_blocks())))
def test_solve_prints_what_the_readme_says(index, tmp_path, capsys, monkeypatch):
    """The first-hour walk: each README recipe run as written on the file it names prints the
    firmware, budget and rotation lines the README shows (a shown line ending in "..." is a
    prefix: what follows depends on the ordering's wall-clock budget)."""
    from gatesopt.cli import main
    words, shown = _printer_blocks()[index]
    name = words[2]
    path = next((d / name for d in (SHARED_INSTANCES, FRESH) if (d / name).exists()), None)
    if path is None:
        pytest.skip(f"{name}: not in ../shared/instances or ../fresh")
    args = [w if w != name else str(path) for w in words[1:]]
    args[args.index("-o") + 1] = str(tmp_path / args[args.index("-o") + 1])
    if "--printer-config" in args:
        # "your printer.cfg": a cartesian Klipper printer's (the replay bench's), read from the
        # folder the command runs in, as the README shows it
        (tmp_path / "printer.cfg").write_text((ROOT / "bench" / "klipper" / "printer.cfg").read_text())
        assert args[args.index("--printer-config") + 1] == "printer.cfg"
        monkeypatch.chdir(tmp_path)
    assert main(args) == 0
    printed = {ln[:14].strip(): ln for ln in capsys.readouterr().out.splitlines()}
    assert shown
    for line in shown:
        label = line[:14].strip()
        assert label in printed, f"{name}: no {label!r} line printed"
        if line.endswith("..."):
            assert printed[label].startswith(line[:-3]), (line, printed[label])
        else:
            assert printed[label] == line
