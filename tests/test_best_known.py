"""The bundled instances still reach their recorded best-known values (instances/best_known.tsv)."""
from __future__ import annotations

import csv

import pytest

import gatesopt
from gatesopt import gating, ordering
from gatesopt.rewrite.figures import travel

from conftest import PROJECT_INSTANCES

with open(PROJECT_INSTANCES / "best_known.tsv", newline="") as f:
    ROWS = list(csv.DictReader(f, delimiter="\t"))


@pytest.mark.parametrize("row", ROWS, ids=[r["file"] for r in ROWS])
def test_gating_reaches_the_best_known_energy(row):
    program = gatesopt.parse(PROJECT_INSTANCES / row["file"])
    sol = gating.solve(gating.build(program, gating.GatingOptions()), "dp")
    assert sol.status == "optimal"
    assert sol.energy_before_j == pytest.approx(float(row["energy_before_j"]), rel=1e-9)
    assert sol.energy_j == pytest.approx(float(row["gated_energy_j"]), rel=1e-9)


@pytest.mark.parametrize("name", ["cyl_grid.gcode", "square_triangles_zhop.gcode", "star_lines_m82.gcode"])
def test_ordering_reaches_the_best_known_travel(name):
    row = next(r for r in ROWS if r["file"] == name)
    program = gatesopt.parse(PROJECT_INSTANCES / name)
    prob = ordering.build(program, ordering.OrderingOptions(objective="travel"))    # (recorded in mm)
    sol = ordering.solve(prob, "auto", time_limit_s=10)
    assert all(g.status == "optimal" for g in sol.groups)
    out = gatesopt.parse(ordering.emit(program, prob, sol))
    assert travel(out)["travel_mm"] == pytest.approx(float(row["travel_after_mm"]), abs=1e-3)
    assert travel(out)["travel_mm"] < float(row["travel_before_mm"])
