"""One print time and one travel (issue 37): `solve`, `order`, `batch`, `compare`, the library's
``rewrite.run`` and the HTML report give the same figures for one file, each named with its model
(print time: the planner's; travel: measured on the files, never the ordering solver's model).
Before, `solve` said 9,457.1 -> 9,111.2 mm where `batch` said 9,482.0 -> 9,252.2 mm for one file,
the library's ``ordering.solve`` 8,868 mm, and a report showed two different times."""
from __future__ import annotations

import json

import pytest

import gatesopt
from gatesopt import rewrite
from gatesopt.cli import main
from gatesopt.rewrite.figures import PRINT_TIME_MODEL, figures, print_time_s, travel

from conftest import PROJECT_INSTANCES

SRC = PROJECT_INSTANCES / "star_lines_m82.gcode"
FIGURES = ("print_time_before_s", "print_time_after_s", "travel_before_mm", "travel_after_mm",
           "travels_before", "travels_after", "retractions_before", "retractions_after")


def _close(a: dict, b: dict, keys, what: str) -> None:
    for k in keys:
        assert a[k] == pytest.approx(b[k], rel=1e-9, abs=1e-9), (what, k, a[k], b[k])


def test_every_command_gives_the_same_print_time_and_travel(tmp_path, capsys):
    program = gatesopt.parse(SRC)
    # the library: the whole job, without re-ordering (deterministic), and its figures named
    res = rewrite.run(program, order=False)
    s_lib = res.summary()
    assert s_lib["print_time_model"] == PRINT_TIME_MODEL == "planner"
    assert s_lib["print_time_before_s"] == pytest.approx(print_time_s(program, s_lib["firmware"]))
    assert s_lib["travel_before_mm"] == pytest.approx(travel(program)["travel_mm"])
    # gating never changes the travel (a split move is one travel still)
    _close({"a": s_lib["travel_after_mm"]}, {"a": s_lib["travel_before_mm"]}, ("a",), "gated travel")
    assert s_lib["travels_after"] == s_lib["travels_before"]

    # solve --no-order: the library's numbers
    rj = tmp_path / "solve.json"
    assert main(["solve", str(SRC), "-o", str(tmp_path / "s.gcode"), "--no-order", "--json", str(rj)]) == 0
    text = capsys.readouterr().out
    assert "print time" in text and "planner model" in text
    s_cli = json.loads(rj.read_text())
    _close(s_cli, s_lib, FIGURES, "solve vs library")

    # batch: the same row (same defaults), travel included
    bj = tmp_path / "b.json"
    assert main(["batch", str(SRC), "--no-order", "--out", str(bj), "--quiet"]) == 0
    capsys.readouterr()
    rows = json.loads(bj.read_text())
    rows = rows["rows"] if isinstance(rows, dict) else rows
    assert len(rows) == 1 and rows[0]["verified"]
    _close(rows[0], s_lib, FIGURES[:4], "batch vs library")
    assert rows[0]["print_time_model"] == "planner"

    # order (no gating): its "before" figures are the file's, as every command gives them; its
    # "after" is the re-ordered file's, and `solve --no-gating` writes that same file
    oj = tmp_path / "order.json"
    assert main(["order", str(SRC), "-o", str(tmp_path / "o.gcode"), "--json", str(oj)]) == 0
    capsys.readouterr()
    o = json.loads(oj.read_text())
    _close(o, s_lib, ("print_time_before_s", "travel_before_mm", "travels_before", "retractions_before"),
           "order vs library")
    assert o["print_time_model"] == "planner"
    assert "model_travel_after_mm" in o        # the solver's own travel, named as such
    ordered = gatesopt.parse(tmp_path / "o.gcode")
    _close(o, figures(program, ordered), FIGURES, "order's report vs its file")

    # the HTML report names the model of the time it shows
    html = tmp_path / "r.html"
    assert main(["report", str(bj), "-o", str(html)]) == 0
    page = html.read_text()
    assert "print time" in page and "(planner)" in page


def test_wipes_counted_and_the_ones_a_re_ordering_dropped_said():
    """The slicer's wipes (retracting while moving back over the last extrusion) are counted, and
    a re-ordered file that has fewer says so: a rebuilt travel retracts in place (a real Bambu
    Studio cube, default solve: 252 of its 255 wipes gone, said nowhere before)."""
    from gatesopt.rewrite.figures import figure_notes
    head = "G90\nM83\n;LAYER_CHANGE\n;Z:0.2\nG1 Z0.2 F600\nG1 X0 Y0 F6000\n"
    wiped = head + "G1 X10 Y0 E0.5 F1200\nG1 X8 Y0 E-0.4 F6000\nG1 E-0.4\nG1 X30 Y5 F9000\nG1 E0.8\nG1 X40 Y5 E0.5\n"
    plain = head + "G1 X10 Y0 E0.5 F1200\nG1 E-0.8 F2100\nG1 X30 Y5 F9000\nG1 E0.8\nG1 X40 Y5 E0.5\n"
    a, b = gatesopt.parse(wiped), gatesopt.parse(plain)
    assert travel(a)["wipes"] == 1 and travel(a)["retractions"] == 1
    assert travel(b)["wipes"] == 0 and travel(b)["retractions"] == 1
    fig = figures(a, b)
    assert (fig["wipes_before"], fig["wipes_after"]) == (1, 0)
    notes = figure_notes(fig)
    assert len(notes) == 1 and notes[0].startswith("1 fewer wipes than the slicer's 1")
    assert figure_notes(figures(a, a)) == []
    # and more wipes than the slicer's: said too (the usual wipe where the slicer's travel did not)
    notes = figure_notes(figures(b, a))
    assert len(notes) == 1 and notes[0].startswith("1 more wipes than the slicer's 0")
