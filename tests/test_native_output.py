"""Native solver output never reaches standard output (which carries G-code with `-o -`)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np


def test_c_printf_inside_the_guard_goes_to_stderr():
    code = ("import ctypes, sys\n"
            "from gatesopt._native import native_stdout_to_stderr\n"
            "libc = ctypes.CDLL(None)\n"
            "print('before', flush=True)\n"
            "with native_stdout_to_stderr():\n"
            "    libc.printf(b'native debug line\\n')\n"
            "print('after', flush=True)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout == "before\nafter\n"
    assert "native debug line" in r.stderr


def test_run_highs_deadline_is_not_eaten_by_earlier_runs():
    """HiGHS checks time_limit against the run time its instance accumulated over *all* runs: a
    model re-solved after cuts or bound changes stopped at "time limit" long before the deadline
    (and a node LP stopped that way was once taken for a pruned node). run_highs must give each
    run the time to its deadline."""
    import time
    import highspy
    from gatesopt._native import run_highs
    rng = np.random.default_rng(0)
    n_rows, n_cols = 400, 4000
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.addRows(n_rows, np.full(n_rows, -np.inf), np.ones(n_rows), 0, np.zeros(n_rows, np.int32),
              np.zeros(0, np.int32), np.zeros(0))
    for j in range(n_cols):
        rows = np.sort(rng.choice(n_rows, 8, replace=False)).astype(np.int32)
        h.addCols(1, np.array([-rng.random()]), np.zeros(1), np.ones(1), 8, np.zeros(1, np.int32),
                  rows, rng.random(8))
    for _ in range(6):                          # six solves from scratch: run time accumulates
        h.clearSolver()
        h.run()
    one = h.getRunTime() / 6
    # a solve from scratch with a deadline 3x what one takes, far less than what the instance
    # has run in all
    h.clearSolver()
    assert run_highs(h, time.perf_counter() + 3.0 * one)
    assert h.getModelStatus() == highspy.HighsModelStatus.kOptimal, h.getModelStatus()
