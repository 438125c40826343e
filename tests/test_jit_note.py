"""Compile time of numba kernels (gatesopt/_jit.py): counted per span, not charged to a budget,
and noted by the CLI on stderr, for what that command compiled only."""
from __future__ import annotations

import time

import numba
import numpy as np
import pytest

from gatesopt import _jit
from gatesopt.cli import main


def _fresh_kernel():
    seed = int(np.random.default_rng().integers(1 << 30))

    @numba.njit
    def made_up(x):                 # a new function: compiled here, whatever any cache holds
        return x * 2 + seed
    return made_up, seed


def test_compile_spans_are_counted_from_a_given_time():
    kernel, seed = _fresh_kernel()
    t_before = time.perf_counter()
    total_before = _jit.compile_s()
    assert kernel(3) == 6 + seed
    t_after = time.perf_counter()
    took = _jit.compile_s() - total_before
    assert 0 < took <= t_after - t_before
    assert _jit.compile_s_since(t_before) == pytest.approx(took)
    assert _jit.compile_s_since(t_after) == 0.0
    assert _jit.compile_s_since(-1.0) == pytest.approx(_jit.compile_s())
    # from inside the span: only its part after that time
    mid = 0.5 * (_jit._spans.starts[-1] + _jit._spans.ends[-1])
    assert _jit.compile_s_since(mid) == pytest.approx(_jit._spans.ends[-1] - mid)


def test_a_budget_does_not_count_time_spent_compiling(monkeypatch):
    """A group's limit under a budget is what is left of it; seconds the process spent compiling
    kernels since the solve began are not gone (as if a first run were a later one)."""
    from gatesopt.ordering import runner as runner_module
    from gatesopt.ordering.polylines import from_polylines
    from gatesopt.ordering.problem import GroupSolution, OrderingOptions
    rng = np.random.default_rng(3)
    prob = from_polylines([[rng.uniform(0, 60, (2, 2)) for _ in range(n)] for n in (150, 3, 3)],
                          options=OrderingOptions(mode="free"))
    given = []

    def record(grp, *, time_limit_s, **kw):
        given.append(time_limit_s)
        order = np.arange(grp.n_curves) * 2
        return GroupSolution.make(order, grp.path_cost(order), 0.0, "fallback", 0.0, "stand-in")

    for compiling in (False, True):
        t0 = time.perf_counter() - 0.3          # 0.3 s of a 0.5 s budget gone, to compiling or not
        monkeypatch.setattr(_jit, "compile_s_since",
                            (lambda t: time.perf_counter() - t) if compiling else (lambda t: 0.0))
        runner = runner_module.GroupRunner(prob, record, 5.0, 0.5, t0, {}, other_alive=lambda: True)
        runner.run(0, prob.group(0, prob.origin_xy))
    assert given[0] < 0.21 and given[1] > 0.4, given


def test_the_cli_notes_what_a_command_compiled_on_stderr_only(monkeypatch, tmp_path, capsys):
    gcode = tmp_path / "a.gcode"
    gcode.write_text("G28\nG1 X10 Y10 F3000\nG1 X20 E1 F1200\n")
    assert main(["profile", str(gcode)]) == 0       # may compile the parser (a cold cache)
    capsys.readouterr()
    assert main(["profile", str(gcode)]) == 0       # all loaded by now: nothing to say
    out = capsys.readouterr()
    assert "numba" not in out.err and "numba" not in out.out
    monkeypatch.setattr(_jit, "NOTE_MIN_S", -1.0)   # every command passes the threshold
    assert main(["profile", str(gcode)]) == 0
    out = capsys.readouterr()
    assert "gatesopt: note:" in out.err and "compiling numba kernels" in out.err
    assert "numba" not in out.out                    # stdout stays the report


def test_a_group_whose_limit_went_to_compiling_is_solved_again(monkeypatch):
    """A group solve that compiled kernels (a first run) and did not prove its group runs once
    more; one that compiled nothing, or proved its group, does not."""
    from gatesopt.ordering.polylines import from_polylines
    from gatesopt.ordering.problem import GroupSolution, OrderingOptions
    from gatesopt.ordering.runner import GroupRunner
    rng = np.random.default_rng(4)
    prob = from_polylines([[rng.uniform(0, 60, (2, 2)) for _ in range(20)] for _ in range(3)],
                          options=OrderingOptions(mode="free"))
    calls = []
    compiling = iter([1.0, 0.0, 1.0])          # the first solve compiled, the second not, the third did
    monkeypatch.setattr(_jit, "compile_s_since", lambda t: next(compiling))

    def solver(grp, *, time_limit_s, **kw):
        calls.append(grp.n_curves)
        order = np.arange(grp.n_curves) * 2
        status = "optimal" if len(calls) == 3 else "feasible"
        return GroupSolution.make(order, grp.path_cost(order), 0.0, status, 0.0, "stand-in")

    runner = GroupRunner(prob, solver, 1.0, None, time.perf_counter(), {})
    assert runner.run(0, prob.group(0, prob.origin_xy)).status == "feasible"
    assert len(calls) == 2                  # compiled 1 s, not proven: solved again
    assert runner.run(1, prob.group(1, prob.origin_xy)).status == "optimal"
    assert len(calls) == 3                  # compiled 1 s but proven: kept
