"""Plots of an energy profile: power over time (3DGates Fig. 4) and the energy sectors (Fig. 5).

matplotlib is imported inside the function and drawn through its Agg canvas directly (no pyplot,
no backend selection), so ``import gatesopt`` needs neither matplotlib nor a display.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .energy import SECTORS, EnergyReport
from .errors import GatesoptError

WIDTH_PX, HEIGHT_PX, DPI = 1400, 560, 100
SECTOR_LABELS = {"X": "X motor", "Y": "Y motor", "Z": "Z motor", "E": "E motor",
                 "heater": "heaters", "fans": "fans", "idle": "idle (board)"}
SECTOR_COLORS = {"X": "#1f77b4", "Y": "#6baed6", "Z": "#9467bd", "E": "#c5b0d5",
                 "heater": "#d62728", "fans": "#2ca02c", "idle": "#7f7f7f"}


class PlotError(GatesoptError, ValueError):
    """A plot cannot be written (bad output path, nothing to draw)."""


def power_timeline(report: EnergyReport, bins: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """(edges_s, power_w): the per-step power as a step function over the cumulative timeline.

    With more timed steps than ``bins``, the timeline is cut into ``bins`` equal bins and each
    gets its mean power, energy in the bin / bin width, read exactly off the cumulative energy
    (power is constant within a step, so cumulative energy is piecewise linear in time). Steps
    without duration carry no energy (E = P T, 3DGates Eq. 2) and are left out.
    """
    end_s = np.asarray(report.step_end_s, dtype=float)
    energy_j = np.asarray(report.step_energy_j, dtype=float)
    dur_s = np.diff(end_s, prepend=0.0)
    timed = dur_s > 0
    if not timed.any():
        return np.zeros(1), np.zeros(0)
    if timed.sum() <= bins:
        edges = np.concatenate([[0.0], end_s[timed]])
        return edges, energy_j[timed] / dur_s[timed]
    edges = np.linspace(0.0, end_s[-1], bins + 1)
    cum_j = np.interp(edges, np.concatenate([[0.0], end_s]), np.concatenate([[0.0], np.cumsum(energy_j)]))
    return edges, np.diff(cum_j) / np.diff(edges)


def _time_unit(total_s: float) -> tuple[float, str]:
    if total_s < 180:
        return 1.0, "s"
    if total_s < 3 * 3600:
        return 60.0, "min"
    return 3600.0, "h"


def check_png_path(path) -> Path:
    """``path`` as a Path, if it names a .png in a writable folder (else ``PlotError``)."""
    p = Path(os.fspath(path))
    if p.suffix.lower() != ".png":
        raise PlotError(f"{p}: the plot is written as PNG: give a file name ending in .png")
    if p.is_dir():
        raise PlotError(f"{p}: is a directory: give a .png file name")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise PlotError(f"{p}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise PlotError(f"{p}: folder {parent} is not writable")
    return p


def plot_profile(report: EnergyReport, path, *, bins: int = 2000, title: str | None = None) -> Path:
    """Write a PNG with two panels: power and cumulative energy over time (3DGates Fig. 4) and the
    energy-sector chart (Fig. 5: X/Y/Z/E motors, heaters, fans, idle). Returns the path.

    Large files are binned to ``bins`` time bins (mean power per bin). Raises ``PlotError`` (a
    ``GatesoptError``) for a path that is not a writable ``.png`` or a report with no time.
    """
    p = check_png_path(path)
    if not report.time_s > 0:
        raise PlotError(f"{report.source}: nothing to plot: the print takes no time")
    from matplotlib.backends.backend_agg import FigureCanvasAgg   # lazy: see module docstring
    from matplotlib.figure import Figure

    fig = Figure(figsize=(WIDTH_PX / DPI, HEIGHT_PX / DPI), dpi=DPI)
    FigureCanvasAgg(fig)
    ax_p, ax_s = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.75, 1]})
    name = os.path.basename(str(report.source)) or str(report.source)
    scale, unit = _time_unit(report.time_s)
    fig.suptitle(title or (f"{name}: {report.n_layers} layers, {report.time_s / scale:.3g} {unit}, "
                           f"{report.energy_j / 3600:.3g} Wh (mean {report.mean_power_w:.1f} W), "
                           f"profile '{report.profile}'"), fontsize=12)

    # --- Fig. 4: power over time, cumulative energy on the right axis ----------------------------
    edges, power_w = power_timeline(report, bins)
    binned = int(np.count_nonzero(np.diff(report.step_end_s, prepend=0.0) > 0)) > bins
    ax_p.stairs(power_w, edges / scale, fill=True, color="#1f77b4", alpha=0.35, linewidth=0)
    ax_p.stairs(power_w, edges / scale, color="#1f77b4", linewidth=0.8,
                label=f"power{f' (mean over {bins} bins)' if binned else ' per step'}")
    ax_p.axhline(report.mean_power_w, color="black", linestyle="--", linewidth=0.8,
                 label=f"mean {report.mean_power_w:.1f} W")
    ax_p.set_xlim(0, report.time_s / scale)
    ax_p.set_ylim(0, max(float(power_w.max(initial=0.0)) * 1.12, 1.0))
    ax_p.set_xlabel(f"time ({unit})")
    ax_p.set_ylabel("power (W)")
    ax_p.set_title("Power and energy over time (3DGates Fig. 4)")
    ax_p.grid(True, alpha=0.3)
    ax_e = ax_p.twinx()
    cum_wh = np.cumsum(report.step_energy_j) / 3600.0
    ax_e.plot(np.concatenate([[0.0], report.step_end_s]) / scale, np.concatenate([[0.0], cum_wh]),
              color="#ff7f0e", linewidth=1.6, label="cumulative energy")
    ax_e.set_ylim(0, max(float(cum_wh[-1]) if len(cum_wh) else 0.0, 1e-9) * 1.12)
    ax_e.set_ylabel("cumulative energy (Wh)", color="#ff7f0e")
    ax_e.tick_params(axis="y", colors="#ff7f0e")
    handles, labels = (a + b for a, b in zip(ax_p.get_legend_handles_labels(), ax_e.get_legend_handles_labels()))
    ax_p.legend(handles, labels, loc="lower right", fontsize=9, framealpha=0.9)

    # --- Fig. 5: energy sectors --------------------------------------------------------------------
    sectors = [(k, float(report.sectors_j.get(k, 0.0))) for k in SECTORS]
    total_j = sum(v for _, v in sectors) or 1.0
    shown = [(k, v) for k, v in sectors if v > 0]
    wedges, _ = ax_s.pie([v for _, v in shown], colors=[SECTOR_COLORS[k] for k, _ in shown],
                         startangle=90, counterclock=False,
                         wedgeprops={"width": 0.45, "edgecolor": "white", "linewidth": 1})
    for w, (k, v) in zip(wedges, shown):   # percent on the ring where a wedge is big enough
        if v / total_j >= 0.04:
            ang = np.deg2rad((w.theta1 + w.theta2) / 2)
            ax_s.text(0.775 * np.cos(ang), 0.775 * np.sin(ang), f"{100 * v / total_j:.0f}%",
                      ha="center", va="center", fontsize=9, color="white", fontweight="bold")
    motors_j = sum(v for k, v in sectors if k in ("X", "Y", "Z", "E"))
    ax_s.text(0, 0, f"motors\n{100 * motors_j / total_j:.1f}%", ha="center", va="center", fontsize=11)
    ax_s.legend([_patch(SECTOR_COLORS[k]) for k, _ in sectors],
                [f"{SECTOR_LABELS[k]}: {v / 3600:.3g} Wh ({100 * v / total_j:.1f}%)" for k, v in sectors],
                loc="center left", bbox_to_anchor=(0.98, 0.5), fontsize=9, frameon=False)
    ax_s.set_title("Energy sectors (3DGates Fig. 5)")
    ax_s.set_aspect("equal")

    fig.subplots_adjust(left=0.05, right=0.80, bottom=0.11, top=0.85, wspace=0.28)
    return save_png(fig, p)


def save_png(fig, p: Path, dpi: int = DPI) -> Path:
    """Write ``fig`` to ``p`` (checked by ``check_png_path``) as PNG; ``PlotError`` if it cannot."""
    try:
        fig.savefig(p, format="png", dpi=dpi)
    except OSError as exc:
        raise PlotError(f"{p}: cannot write: {exc.strerror or exc}") from None
    return p


def _patch(color: str):
    from matplotlib.patches import Patch
    return Patch(facecolor=color, edgecolor="none")
