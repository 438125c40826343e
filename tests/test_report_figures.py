"""The HTML report reads at a glance (issue 37): whole-number "files" counts, each file labelled,
legends beside the data (never over a bar or a point), the results table first, and the rotation
sweep at the angles ``--rotate auto`` really tries."""
from __future__ import annotations

import numpy as np
import pytest

from gatesopt import report

from conftest import PROJECT_INSTANCES

# the 12 rows of a real 6-file batch (`gatesopt batch <6 fresh files> --formulation greedy,dp`):
# file, formulation, saving %, size +%, rotation deg, travel -%, infill, slicer, curves, wall s
SURVEY_ROWS = [
    ("cube__prusa_mk3s.gcode", "greedy", 19.38, 27.0, 0.0, 0.0, "gyroid", "PrusaSlicer", 5, 1.8),
    ("cube__prusa_mk3s.gcode", "dp", 19.68, 29.4, 0.0, 0.0, "gyroid", "PrusaSlicer", 5, 1.0),
    ("cube__cura_ender3.gcode", "greedy", 17.93, 53.5, 0.0, 20.9, "", "Cura_SteamEngine", 69, 0.3),
    ("cube__cura_ender3.gcode", "dp", 18.14, 56.0, 0.0, 24.0, "", "Cura_SteamEngine", 69, 2.9),
    ("phonecase__prusa_klipper.gcode", "greedy", 11.54, 26.7, 0.0, 0.0, "gyroid", "PrusaSlicer", 46, 0.6),
    ("phonecase__prusa_klipper.gcode", "dp", 18.52, 43.6, 45.0, -1.5, "gyroid", "PrusaSlicer", 46, 3.3),
    ("holes__slic3r.gcode", "greedy", 6.9, 4.6, 0.0, 26.0, "stars", "Slic3r", 94, 2.5),
    ("holes__slic3r.gcode", "dp", 14.33, 15.4, 45.0, 28.4, "stars", "Slic3r", 94, 12.3),
    ("tall__cura_mk3.gcode", "greedy", 0.88, -2.7, 30.0, 38.9, "", "Cura_SteamEngine", 41, 1.2),
    ("tall__cura_mk3.gcode", "dp", 7.52, 24.2, 45.0, 39.0, "", "Cura_SteamEngine", 41, 1.2),
    ("plate__prusa_mk3s.gcode", "greedy", 7.61, 8.2, 0.0, 6.0, "gyroid", "PrusaSlicer", 24, 1.0),
    ("plate__prusa_mk3s.gcode", "dp", 10.18, 23.9, 45.0, 6.0, "gyroid", "PrusaSlicer", 24, 4.0),
]


def rows_of(table):
    return [dict(file=f"/x/{f}", formulation=fm, verified=True, error="", saving_pct=s, size_change_pct=z,
                 rotation_deg=a, travel_reduction_pct=t, ordered=True, infill_pattern=i, slicer=sl,
                 max_curves_per_layer=c, wall_s=w, status="optimal", gap=0.0, added_time_pct=0.0)
            for f, fm, s, z, a, t, i, sl, c, w in table]


def many_rows(n_files=40):
    rng = np.random.default_rng(7)
    return rows_of([(f"part{k:02d}.gcode", fm, float(rng.uniform(0, 30)), float(rng.uniform(0, 3)), 0.0,
                     10.0, "grid", "PrusaSlicer", 10, 1.0) for k in range(n_files) for fm in ("greedy", "dp")])


@pytest.fixture
def figures(monkeypatch):
    """The matplotlib figures ``build_figures`` makes (by name), kept open."""
    made = []
    monkeypatch.setattr(report, "_png", lambda fig: made.append(fig) or b"png")

    def build(rows, sweeps=None):
        made.clear()
        names = [f[0] for f in report.build_figures(rows, sweeps)]
        return dict(zip(names, made))
    yield build
    import matplotlib.pyplot as plt
    plt.close("all")


def _overlaps_data(fig) -> list[str]:
    """What of each axes' data (bars, points, lines' markers) lies under a legend."""
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    hits = []
    for ax in fig.axes:
        legends = [leg for leg in (ax.get_legend(), *fig.legends) if leg is not None]
        for leg in legends:
            box = leg.get_window_extent(r)
            for p in ax.patches:
                if p.get_window_extent(r).overlaps(box):
                    hits.append(f"bar {p.get_window_extent(r)}")
            for c in ax.collections:
                for xy in c.get_offset_transform().transform(c.get_offsets()):
                    if box.contains(*xy):
                        hits.append(f"point {xy}")
            for line in ax.lines:
                if line.get_marker() not in (None, "None", ""):
                    for xy in line.get_transform().transform(line.get_xydata()):
                        if box.contains(*xy):
                            hits.append(f"marker {xy}")
    return hits


def test_files_are_labelled_and_legends_cover_nothing(figures):
    figs = figures(rows_of(SURVEY_ROWS))
    labels = {f.split(".")[0] for f, *_ in SURVEY_ROWS}
    for name in ("Energy saving per file", "File size increase"):
        ax = figs[name].axes[0]
        assert {t.get_text() for t in ax.get_yticklabels()} == labels, name
    for name, fig in figs.items():
        assert _overlaps_data(fig) == [], name


def test_file_counts_are_whole_numbers(figures):
    figs = figures(many_rows())            # beyond PER_FILE_MAX: histograms of files
    for name in ("Energy saving per file", "File size increase"):
        ax = figs[name].axes[0]
        assert ax.get_ylabel() == "files"
        ticks = [t for t in ax.get_yticks() if ax.get_ylim()[0] <= t <= ax.get_ylim()[1]]
        assert len(ticks) >= 2 and all(float(t).is_integer() for t in ticks), (name, ticks)
        assert _overlaps_data(figs[name]) == [], name


def test_the_results_table_comes_first():
    rows = rows_of(SURVEY_ROWS)
    text = report.render_html(rows, report.build_figures(rows))
    assert text.index("<table id='results'>") < text.index("<figure")
    assert text.count("<tr>") == 1 + len(rows)


def test_the_sweep_is_at_the_angles_rotate_auto_tries(figures):
    from dataclasses import replace
    from gatesopt import parse
    from gatesopt.gating.options import GatingOptions
    from gatesopt.gating.problem import build
    from gatesopt.gating.solve import solve
    program = parse(PROJECT_INSTANCES / "star_triangles.gcode")
    sweep = report.rotation_sweep(program)
    auto = build(program, replace(GatingOptions(), rotate="auto"))
    tried = sorted(float(a) for a in auto.angles_deg)
    assert list(sweep.angles_deg) == tried and len(tried) > 3
    assert sweep.chosen_deg == solve(auto, "dp").rotation_deg
    # dp solves each angle exactly and auto keeps the best: the star is the sweep's lowest point
    assert sweep.energy_j[tried.index(sweep.chosen_deg)] == pytest.approx(min(sweep.energy_j), rel=1e-9)
    fig = figures(rows_of(SURVEY_ROWS), {"star_triangles.gcode": sweep})["Energy vs model rotation"]
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_xticklabels()] == report._angle_labels(tried)
    assert any(a % 30 for a in tried)           # not the paper's fixed 30-degree steps
    assert f"chose {sweep.chosen_deg:.6g}" in ax.get_title()


def test_a_saving_over_its_time_budget_is_marked(figures):
    """greedy (the paper's Algorithm 1) takes no time budget: a row over it (status infeasible)
    is hatched and said, not drawn as an equal of the rows that kept the budget."""
    rows = rows_of(SURVEY_ROWS)
    for r in rows:
        if r["formulation"] == "greedy":
            r.update(status="infeasible", added_time_pct=6.7)
    ax = figures(rows)["Energy saving per file"].axes[0]
    hatched = [p for p in ax.patches if p.get_hatch()]
    assert len(hatched) == len(SURVEY_ROWS) // 2
    assert sum("(over budget)" in t.get_text() for t in ax.texts) == len(SURVEY_ROWS) // 2
    text = report.render_html(rows, [])
    assert "6 verified rows broke their time budget" in text
