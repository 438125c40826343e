"""The whole run's budget (``rewrite.budget``, `gatesopt solve`'s default 10 s): the curve ordering
gets what the rest is estimated to leave, and on a machine other work shares (the run measures its
own wall / CPU seconds before the ordering) the rest is estimated that much slower, so the ordering
gets less. Clocks are injected: nothing here is timed."""
from __future__ import annotations

import pytest

import gatesopt
from gatesopt.gating import GatingOptions
from gatesopt.rewrite import budget, pipeline

from conftest import PROJECT_INSTANCES


def _ordering_budget_seen(monkeypatch) -> dict:
    """A dict that gets the budget ``pipeline.run`` hands the curve ordering (``"budget_s"``)."""
    seen = {}
    real = pipeline._order_curves

    def spy(program, time_limit_s, workers=1, budget_s=None, *a, **kw):
        seen["budget_s"] = budget_s
        return real(program, time_limit_s, workers, budget_s, *a, **kw)
    monkeypatch.setattr(pipeline, "_order_curves", spy)
    return seen


def test_slowdown_is_wall_over_cpu_clipped():
    f = budget.slowdown_factor
    assert f(10.0, 2.0, wall_now_s=13.0, cpu_now_s=3.0) == pytest.approx(3.0)
    assert f(10.0, 2.0, wall_now_s=13.0, cpu_now_s=5.0) == 1.0          # never below 1
    assert f(0.0, 0.0, wall_now_s=100.0, cpu_now_s=1.0) == budget.MAX_SLOWDOWN
    assert f(0.0, 0.0, wall_now_s=0.2, cpu_now_s=0.01) == 1.0           # too short to tell
    assert f(0.0, None, wall_now_s=3.0, cpu_now_s=1.0) == 1.0           # no CPU reading: unknown


def test_a_slower_machine_leaves_the_ordering_less():
    program = gatesopt.parse(PROJECT_INSTANCES / "star_lines_m82.gcode")
    o = GatingOptions(rotate="none")
    quiet = budget.ordering_budget_s(10.0, program, o, "dp", True, 1.0, None, 1.0)
    loaded = budget.ordering_budget_s(10.0, program, o, "dp", True, 1.0, None, 3.0)
    rest = budget.after_order_s(max(program.n_lines, program.n_steps), False)
    assert quiet == pytest.approx(10.0 - 1.0 - rest)
    assert loaded < quiet - 2.0 * rest + 1e-9       # the rest counted three times, its emit too


def test_run_measures_the_slowdown_and_the_ordering_gets_the_smaller_budget(monkeypatch):
    seen = _ordering_budget_seen(monkeypatch)
    monkeypatch.setattr(budget, "slowdown_factor", lambda *clocks: 2.5)
    program = gatesopt.parse(PROJECT_INSTANCES / "star_lines_m82.gcode")
    o = GatingOptions(rotate="none")
    res = pipeline.run(program, o, budget_s=10.0, cpu_started_s=0.0)
    assert res.report.ok and res.summary()["slowdown"] == 2.5
    quiet = budget.ordering_budget_s(10.0, program, o, "dp", True, res.times["read_s"], None, 1.0)
    assert seen["budget_s"] < quiet


def test_no_time_left_keeps_the_slicers_order_and_says_so(monkeypatch):
    monkeypatch.setattr(budget, "slowdown_factor", lambda *clocks: budget.MAX_SLOWDOWN)
    program = gatesopt.parse(PROJECT_INSTANCES / "star_lines_m82.gcode")
    res = pipeline.run(program, GatingOptions(rotate="none"), budget_s=0.5, cpu_started_s=0.0)
    assert res.report.ok and not res.ordered and "ordering_s" not in res.times
    assert any("curve ordering skipped" in n and "1/4.0 of a core" in n for n in res.notes)


def test_a_first_run_counts_its_reading_at_the_quiet_rate():
    # a first run (kernels compiled before the ordering) that read for 100 s at 1/50 of a core:
    # counted as a quiet machine's reading, slowdown 1 (``budget_clock``)
    t, slow = budget.budget_clock(0.0, 0.0, 100_000, now_s=100.0, compiled_s=35.0, cpu_now_s=2.0)
    assert slow == 1.0
    assert t == pytest.approx(100.0 - budget.READ_FIXED_S - 100_000 * budget.READ_S_PER_LINE)
    # a later run (nothing compiled): as measured
    t, slow = budget.budget_clock(0.0, 0.0, 100_000, now_s=100.0, compiled_s=0.0, cpu_now_s=2.0,
                                  fresh=False)
    assert (t, slow) == (0.0, budget.MAX_SLOWDOWN)
    # a first run after an install whose kernels were cached already (README's first command
    # after `.ci/run`, in a fresh venv: 62.6 s of first imports at 1/4 of a core): quiet rate
    t, slow = budget.budget_clock(0.0, 0.0, 100_000, now_s=100.0, compiled_s=0.0, cpu_now_s=2.0,
                                  fresh=True)
    assert slow == 1.0
    assert t == pytest.approx(100.0 - budget.READ_FIXED_S - 100_000 * budget.READ_S_PER_LINE)


def test_a_fresh_install_is_told_by_the_bytecode_its_imports_wrote(tmp_path, monkeypatch):
    import importlib
    import sys
    import time
    (tmp_path / "gs_fresh_dep.py").write_text("X = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delenv("PYTHONDONTWRITEBYTECODE", raising=False)
    monkeypatch.setattr(sys, "dont_write_bytecode", False)
    started = time.perf_counter()
    importlib.import_module("gs_fresh_dep")                 # writes its bytecode now
    try:
        assert budget.fresh_install(started, modules=("gs_fresh_dep",))
        # a process started after that bytecode was written: a later run
        assert not budget.fresh_install(time.perf_counter() + 5.0, modules=("gs_fresh_dep",))
        # the project's test process imported numpy long after its bytecode was written
        assert not budget.fresh_install(time.perf_counter(), modules=("numpy",))
    finally:
        sys.modules.pop("gs_fresh_dep", None)


def test_a_first_run_stalled_before_the_ordering_still_orders(monkeypatch):
    # README's first command on a fresh clone: 106 s of reading (35 s compiling, the rest
    # waiting) made the run skip its ordering; a first run orders as a later quiet one does
    import time
    program = gatesopt.parse(PROJECT_INSTANCES / "square_grid_m82.gcode")
    o = GatingOptions(rotate="none")
    started = time.perf_counter() - 106.0
    cpu = time.process_time() - 38.0
    real = budget._jit.compile_s_since
    for compiled_s, ordered in ((35.0, True), (0.0, False)):
        monkeypatch.setattr(budget._jit, "compile_s_since",
                            lambda t, c=compiled_s: c if t == started else real(t))
        res = pipeline.run(program, o, budget_s=10.0, started_s=started, cpu_started_s=cpu)
        assert res.report.ok and res.ordered == ordered, compiled_s
        # the first run: no load read from its reading; the later one: 106 / 38 s as measured
        assert res.summary()["slowdown"] == pytest.approx(1.0 if ordered else 106.0 / 38.0, rel=0.05)


def test_an_ordering_that_costs_energy_is_not_applied(monkeypatch):
    """A re-ordering priced in print time can lengthen the travel; where the re-ordered, gated
    print uses more energy than the file as given (a RepRapFirmware file: E-only gating saves
    next to nothing), the run is made again in the slicer's order and says so: never a negative
    saving from a default run. The "re-ordering" here is the file with one long detour added."""
    import re
    text = (PROJECT_INSTANCES / "star_lines_m82.gcode").read_text().replace(
        "; gcode_flavor = marlin2", "; gcode_flavor = reprapfirmware")
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if i > len(lines) // 2
             and re.match(r"G1 X[\d.]+ Y[\d.]+ E", ln))
    x, y = re.match(r"G1 X([\d.]+) Y([\d.]+)", lines[k]).groups()
    detour = lines[:k + 1] + ["G0 X0 Y0", f"G0 X{x} Y{y}"] + lines[k + 1:]
    program = gatesopt.parse(text, source="star (rrf)")
    longer = gatesopt.parse("\n".join(detour) + "\n", source="star (detour)")
    monkeypatch.setattr(pipeline, "_order_curves",
                        lambda program, *a, **kw: (longer, True, None, None, None, 0.0))
    res = pipeline.run(program, order=True)
    assert res.report.ok and not res.ordered
    assert res.report.energy_j <= res.report.energy_before_j
    assert any("curve ordering not applied" in n for n in res.notes)
    # gating alone, as the run again made it: the same energy
    plain = pipeline.run(program, order=False)
    assert res.report.energy_j == pytest.approx(plain.report.energy_j)


@pytest.mark.parametrize("formulation", ["dp", "milp", "cpsat"])
def test_an_exact_gating_formulation_never_takes_the_orderings_floor(monkeypatch, formulation):
    # the exact gating's share comes out of what the ordering has beyond its floor: where dp's run
    # re-orders, milp's and cpsat's do too (a 121k-line Cura file was re-ordered under dp, 3.90 %,
    # and not under milp, 1.47 % reported "optimal")
    seen = _ordering_budget_seen(monkeypatch)
    floor_s, share_s = 2.0, 3.0
    monkeypatch.setattr(pipeline, "stage_floor_s", lambda program, slow=1.0: floor_s)
    monkeypatch.setattr(pipeline, "ordering_budget_s", lambda *a, **k: share_s)
    program = gatesopt.parse(PROJECT_INSTANCES / "star_lines_m82.gcode")
    res = pipeline.run(program, GatingOptions(rotate="none"), formulation=formulation,
                       budget_s=10.0, time_limit_s=10.0)
    assert res.report.ok and res.ordered
    want = share_s if formulation == "dp" else (
        floor_s + (1.0 - budget.EXACT_GATING_SHARE) * (share_s - floor_s))
    assert seen["budget_s"] == pytest.approx(want)


def test_an_exact_gating_formulation_keeps_at_most_its_reserve(monkeypatch):
    # milp's gating solves take hundredths of a second where the ordering gains percents: of a
    # 10 s share above a 2 s floor the ordering keeps all but EXACT_GATING_RESERVE_S
    seen = _ordering_budget_seen(monkeypatch)
    monkeypatch.setattr(pipeline, "stage_floor_s", lambda program, slow=1.0: 2.0)
    monkeypatch.setattr(pipeline, "ordering_budget_s", lambda *a, **k: 10.0)
    program = gatesopt.parse(PROJECT_INSTANCES / "star_lines_m82.gcode")
    res = pipeline.run(program, GatingOptions(rotate="none"), formulation="milp",
                       budget_s=20.0, time_limit_s=10.0)
    assert res.report.ok and res.ordered
    assert seen["budget_s"] == pytest.approx(10.0 - budget.EXACT_GATING_RESERVE_S)
