"""Formulations side by side: one file through every gating (or curve-ordering) formulation, each
run verified, one row each (``gatesopt compare``; nothing is written).

A row is a dict of the run's report values; a formulation that is unknown, whose backend is not
installed or whose run fails is a row saying so, and never stops the others.
"""
from __future__ import annotations

import os

from .errors import GatesoptError

#: the values of a gating run (``RunResult.summary()``) a row keeps
GATING_KEYS = ("saving_pct", "energy_before_j", "energy_after_j", "lines_added", "instruction_lines",
               "size_change_pct", "added_time_pct", "print_time_before_s", "print_time_after_s",
               "print_time_change_pct", "paper_added_time_pct", "travel_before_mm", "travel_after_mm",
               "ordered", "firmware", "status", "stopped", "gap", "bound", "solve_s", "wall_s",
               "rotation_deg", "verified", "message")
#: the values of an ordering run (``OrderResult.summary``) a row keeps
ORDERING_KEYS = ("travel_before_mm", "travel_after_mm", "travel_change_pct", "model_travel_after_mm",
                 "print_time_before_s", "print_time_after_s", "print_time_model", "groups_reordered",
                 "groups_optimal", "groups_feasible", "groups_fallback", "worst_gap", "solve_s", "wall_s",
                 # issue 36: what the ordering optimises
                 "objective", "print_time_change_pct", "layers_kept_slower", "layers_reorderable")


def formulation_rows(program, formulations, known, solve_row, installed=lambda name: True) -> list[dict]:
    """One row per formulation, greedy first; ``solve_row(name)`` gives a solved row's values. An
    unknown name, a backend not installed or a run that fails is a row saying so."""
    rows = []
    for name in ["greedy"] + [f for f in formulations if f != "greedy"]:
        row = {"file": os.path.basename(program.source), "formulation": name}
        if name not in known:
            row.update(status="unknown", error=f"unknown formulation {name!r}")
        elif not installed(name):
            row.update(status="unavailable", error="backend not installed")
        else:
            try:
                row.update(solve_row(name))
            except ModuleNotFoundError as exc:
                row.update(status="unavailable", error=str(exc))
            except GatesoptError as exc:
                row.update(status="error", error=str(exc))
        rows.append(row)
    return rows


def gating_rows(program, options, formulations, time_limit_s, *, order: bool = False,
                budget_s: float | None = None, order_options=None, workers: int = 1,
                choice=None, read_s: float = 0.0) -> list[dict]:
    """One row per gating formulation (greedy first), each a verified run: with ``order``, the run
    ``gatesopt solve --formulation F`` makes (``rewrite.run``: the curve ordering the formulation
    names, ``order_formulation_of``, within the whole-run ``budget_s``, counted as if the file had
    just been read in ``read_s``), so that a row gives the figures `solve` gives; without, the
    slicer's order gated."""
    import time
    from .rewrite import run
    from .rewrite.pipeline import order_formulation_of
    from .gating.solve import FORMULATIONS, is_installed

    def solve_row(name):
        r = run(program, options, formulation=name, time_limit_s=time_limit_s, order=order,
                budget_s=budget_s if order else None, order_options=order_options,
                order_formulation=order_formulation_of(name), order_workers=workers, choice=choice,
                started_s=time.perf_counter() - read_s, cpu_started_s=time.process_time() - read_s)
        s = r.summary()
        row = {k: s[k] for k in GATING_KEYS}
        if not r.report.ok:
            row["findings"] = [str(f) for f in r.report.findings[:3]]
        return row
    return formulation_rows(program, formulations, FORMULATIONS, solve_row, is_installed)


def ordering_rows(program, options, formulations, known, budget_s: float, workers: int) -> list[dict]:
    """One row per curve-ordering formulation in ``known`` (greedy, the Fleming et al. baseline,
    first), each a verified run with ``budget_s`` for the whole of it."""
    from .rewrite.order import order_program

    def solve_row(name):
        r = order_program(program, options, formulation=name, budget_s=budget_s, workers=workers)
        row = {k: r.summary[k] for k in ORDERING_KEYS}
        row["verified"] = bool(r.ok)
        if not r.ok:
            row["findings"] = [str(f) for f in r.findings[:3]]
        return row
    return formulation_rows(program, formulations, known, solve_row)
