"""The re-ordering check's geometry matching (``verify.ordering.check_geometry``): moves whose
text rounding puts them a little off the original's (within ``tol_mm``) still match, one for one;
moves further off are reported. The near-miss matching searches a window of the sorted first
column instead of scanning every pair (95 s on a refused fresh Slic3r slice with merged layers);
these tests pin what it matches."""
from __future__ import annotations

import gatesopt
from gatesopt.verify.ordering import check_geometry


def _layer(moves, *, shift=lambda k: (0.0, 0.0)) -> str:
    """One layer of separate extruded segments (each after its own travel), relative E."""
    out = ["G21", "G90", "M83", ";LAYER:0", "G1 Z0.2 F600"]
    for k, (x, y) in enumerate(moves):
        dx, dy = shift(k)
        out += [f"G0 X{x + dx:.4f} Y{y + dy:.4f} F6000",
                f"G1 X{x + 3 + dx:.4f} Y{y + dy:.4f} E0.1 F1200"]
    return "\n".join(out) + "\n"


GRID = [(5.0 * (k % 40), 5.0 * (k // 40)) for k in range(1600)]


def test_moves_within_tolerance_match_one_for_one():
    a = gatesopt.parse(_layer(GRID))
    # every move 0.4 um off in x (within 1 um; on the other side of the 0.1 um grid for half)
    b = gatesopt.parse(_layer(GRID, shift=lambda k: (0.0004 if k % 2 else -0.0004, 0.0)))
    assert check_geometry(a, b) == []


def test_moves_off_by_more_than_tolerance_are_reported():
    a = gatesopt.parse(_layer(GRID))
    b = gatesopt.parse(_layer(GRID, shift=lambda k: (0.01, 0.0) if k == 7 else (0.0004, 0.0)))
    found = check_geometry(a, b)
    assert len(found) == 2
    texts = " ".join(str(f) for f in found)
    assert "(35.000,0.000)-(38.000,0.000) of the original is not in the output" in texts
    assert "(35.010,0.000)-(38.010,0.000) is not in the original" in texts


def test_two_near_copies_take_one_original_each():
    """Two output moves near one original move: one matches, the other is reported (a match
    is taken once)."""
    a = gatesopt.parse(_layer([(0.0, 0.0), (50.0, 0.0)]))
    b = gatesopt.parse(_layer([(0.0, 0.0), (0.0, 0.0)], shift=lambda k: (0.0004 * k, 0.0)))
    found = [str(f) for f in check_geometry(a, b)]
    assert len(found) == 2
    assert any("(50.000,0.000)-(53.000,0.000) of the original is not in the output" in f for f in found)
    assert any("is not in the original" in f for f in found)
