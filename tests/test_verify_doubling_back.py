"""Paths that double back on themselves, where the verifier's joining of split pieces can read a run
of pieces two ways (both found by the pipeline fuzz):
- A then B collinear, then C back over both: A and B must not be merged into "C reversed";
- a move that retraces the one before it and beyond, split by gating exactly where that move
  started: its first piece is an original move too, and the pieces must still be joined."""
from __future__ import annotations

import pytest

import gatesopt
from gatesopt.gating import GatingOptions
from gatesopt.rewrite import run
from gatesopt.verify import verify

TEXT = ("G21\nG90\nM83\nM104 S200\nM109 S200\nG28\nG92 E0\n;LAYER_CHANGE\n;Z:0.2\nG1 Z0.200 F600\n"
        "G1 E-0.80000 F2100\nG1 X80.000 Y80.000 F9000\nG1 E0.80000 F2100\nG1 F1800\n"
        "G1 X80.000 Y80.000 E0.00000\n;LAYER_CHANGE\n;Z:0.4\nG1 Z0.400 F600\nM106 S255\n"
        "G1 E-0.80000 F2100\nG1 X80.000 Y80.000 F9000\nG1 E0.80000 F2100\nG1 F1800\n"
        "G1 X80.000 Y81.000 E0.03300\nG1 X80.000 Y82.000 E0.03300\nG1 X80.000 Y80.000 E0.06600\n"
        "G1 E-0.80000 F2100\nG1 Z10 F600\nM104 S0\nM107\nM84\n")


@pytest.mark.parametrize("firmware", ["marlin", "klipper"])
@pytest.mark.parametrize("rotate", ["none", "auto"])
def test_gated_output_of_a_path_that_doubles_back_verifies(firmware, rotate):
    prog = gatesopt.parse(TEXT.encode())
    res = run(prog, GatingOptions.for_firmware(firmware, rotate=rotate, num_workers=1),
              formulation="dp", time_limit_s=10.0, order=False)
    assert res.report.ok, [str(f) for f in res.report.findings]


def test_a_missing_piece_of_that_path_is_still_caught():
    prog = gatesopt.parse(TEXT.encode())
    bad = gatesopt.parse(TEXT.replace("G1 X80.000 Y81.000 E0.03300\n", "G1 X80.000 Y81.000\n").encode())
    rep = verify(prog, bad)
    assert not rep.ok
    assert any(f.check in ("geometry", "extrusion") for f in rep.findings)


# Y 93.031 -> 94 -> 92.977 at X 81: greedy gating splits the move 94 -> 92.977 at 93.031 (its
# start-ahead point happens to fall there), so the first piece, 94 -> 93.031, is the previous move
# reversed. Before session 10 the verifier left such a piece unjoined and reported the geometry
# changed on a correct output.
RETRACED_PATH = (
    "G21\nG90\nM83\nM104 S200\nM109 S200\nG28\nG92 E0\n;LAYER_CHANGE\n;Z:0.2\nG1 Z0.200 F600\n"
    "G1 E-0.80000 F2100\nG1 X80.000 Y80.000 F9000\nG1 E0.80000 F2100\nG1 F1800\n"
    "G2 X82.000 Y80.000 I1.000 J0 E0.10367\nG1 E-0.80000 F2100\nG1 X80.000 Y80.000 F9000\n"
    "G1 E0.80000 F2100\nG1 F1800\n"
    "G1 X80.000 Y93.031 E0.43003\nG1 X81.000 Y93.031 E0.03300\nG1 X81.000 Y94.000 E0.03197\n"
    "G1 X81.000 Y92.977 E0.03377\nG1 X80.000 Y92.977 E0.03300\nG1 E-0.80000 F2100\n"
    "G1 Z10 F600\nM104 S0\nM107\nM84\n")


def test_a_path_that_retraces_its_last_segment_gates_and_verifies():
    opts = GatingOptions.for_firmware("3dgates", rotate="none", num_workers=1)
    res = run(gatesopt.parse(RETRACED_PATH), opts, formulation="greedy", time_limit_s=10.0, order=False)
    assert res.report.ok, [str(f) for f in res.report.findings[:3]]
    # the case is the one described: some move comes out split where an earlier move started
    after = res.text.split("G1 X81.000 Y94.000")[1].splitlines()
    assert after[1].startswith("G1 X81 Y93.031 E"), after[:3]


RETRACE = "G90\nM83\nG1 X0 Y2\nG1 X0 Y10 E0.8\nG1 X0 Y0 E1\nG1 X5 Y0 E0.5\n"


def test_a_retracing_move_split_where_the_move_before_started_verifies():
    # B (10 -> 0) retraces A (2 -> 10) and goes on; split at Y2, its first piece is A reversed
    ok = "G90\nM83\nG1 X0 Y2\nG1 X0 Y10 E0.8\nG1 X0 Y2 E0.8\nS1 X\nG1 X0 Y0 E0.2\nG1 X5 Y0 E0.5\n"
    rep = verify(gatesopt.parse(RETRACE), gatesopt.parse(ok), start_ahead_s=0, end_late_s=0)
    assert not [f for f in rep.findings if f.check == "geometry"], [str(f) for f in rep.findings]


@pytest.mark.parametrize("bad_tail", ["G1 X0.05 Y0 E0.2\nG1 X5 Y0 E0.5\n",   # bent last piece
                                      "G1 X0 Y0\nG1 X5 Y0 E0.5\n"])           # last piece not printed
def test_a_wrong_piece_of_that_split_is_still_caught(bad_tail):
    bad = "G90\nM83\nG1 X0 Y2\nG1 X0 Y10 E0.8\nG1 X0 Y2 E0.8\nS1 X\n" + bad_tail
    rep = verify(gatesopt.parse(RETRACE), gatesopt.parse(bad), start_ahead_s=0, end_late_s=0)
    assert any(f.check == "geometry" for f in rep.findings)


def test_many_ambiguous_runs_are_looked_up_in_one_batch(monkeypatch):
    # a verify of a real Cura file (0.05 mm layers) took 11 s instead of 2 s when each ambiguous
    # run made its own lookup (a hash and a k-d tree over all the original's moves, every time)
    import gatesopt.verify.geometry as v
    orig, out = ["G90", "M83"], ["G90", "M83"]
    for k in range(200):        # 200 retracing moves, each split where the move before started
        x = 10 + k
        orig += [f"G1 X{x} Y2", f"G1 X{x} Y10 E0.8", f"G1 X{x} Y0 E1"]
        out += [f"G1 X{x} Y2", f"G1 X{x} Y10 E0.8", f"G1 X{x} Y2 E0.8", "S1 X", f"G1 X{x} Y0 E0.2"]
    calls = []
    real_near = v._near
    monkeypatch.setattr(v, "_near", lambda *a: calls.append(1) or real_near(*a))
    rep = verify(gatesopt.parse("\n".join(orig) + "\n"), gatesopt.parse("\n".join(out) + "\n"),
                 start_ahead_s=0, end_late_s=0)
    assert not [f for f in rep.findings if f.check == "geometry"], [str(f) for f in rep.findings[:3]]
    assert len(calls) <= 6


def _greedy_reading_reference(original_moves, s, e, k, j_end, tol_mm, join):
    """The long runs' greedy reading as it was written first: one k-d tree query per (i, j)."""
    import numpy as np
    from scipy.spatial import cKDTree
    tree = cKDTree(original_moves)
    i = k
    while i < j_end:
        best = None
        for j in range(j_end, i, -1):
            d, _ = tree.query(np.concatenate([s[i], e[j]]), k=1, p=np.inf, distance_upper_bound=tol_mm)
            if np.isfinite(d):
                best = j
                break
        if best is None:
            i += 1
            continue
        join[i:best] = True
        i = best + 1


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_long_runs_greedy_reading_is_the_per_query_one(seed):
    """``_read_runs`` on runs longer than ``PARTITION_MAX_PIECES`` (a real Simplify3D 4.0 file's
    verify took 19 s there, one tree query per pair of pieces) reads them as before: the same
    joins on random runs of collinear pieces, some of them splits of an original move."""
    import numpy as np
    from gatesopt.verify.geometry import PARTITION_MAX_PIECES, _read_runs
    rng = np.random.default_rng(seed)
    n = 3 * PARTITION_MAX_PIECES
    pts = np.zeros((n + 1, 3))
    pts[:, 0] = np.cumsum(np.concatenate([[0.0], rng.uniform(0.1, 1.0, n)]))
    s, e = pts[:-1].copy(), pts[1:].copy()
    # the original: some single pieces, some stretches of pieces joined, both directions
    moves = []
    i = 0
    while i < n:
        j = min(n - 1, i + int(rng.integers(0, 4)))
        if rng.random() < 0.8:
            moves.append(np.concatenate([s[i], e[j]]))
            if j > i + 1 and rng.random() < 0.5:
                # a shorter original move from the same start: the reading takes the longest
                moves.append(np.concatenate([s[i], e[i + 1]]))
        i = j + 1
    moves = np.asarray(moves)
    moves = np.concatenate([moves, np.concatenate([moves[:, 3:], moves[:, :3]], axis=1)])
    runs = [(0, n - 1), (5, 5 + PARTITION_MAX_PIECES + 7)]
    for k, j_end in runs:
        got, want = np.zeros(n, bool), np.zeros(n, bool)
        _read_runs(moves, s, e, [(k, j_end)], 1e-6, got)
        _greedy_reading_reference(moves, s, e, k, j_end, 1e-6, want)
        assert np.array_equal(got, want)
        assert got.any()
