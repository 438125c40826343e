"""A picture of what the re-ordering did: one layer's travels before and after, and the travel of
every layer (the per-layer view of Fleming et al.'s travel reduction).

Everything is read from the two parsed files, with the report's definition of travel
(``travel.travel_mask``), so the plot and the report's numbers agree. Arcs are drawn as their
chords (the picture is about where the nozzle travels, not the shape of each extrusion).
matplotlib is imported inside ``plot_ordering`` and drawn through its Agg canvas, as in
``gatesopt.plot``.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..plot import DPI, PlotError, check_png_path, save_png
from ..program import Program
from .travel_stats import travel_mask

WIDTH_PX, HEIGHT_PX = 1500, 560
EXTRUSION_COLOR, TRAVEL_COLOR = "#9a9a9a", "#d62728"


def travel_per_layer_mm(program: Program) -> np.ndarray:
    """(n_layers,) travel distance of each layer (the report's travel moves, summed by layer)."""
    m = travel_mask(program)
    return np.bincount(program.layer[m], weights=program.length_mm[m], minlength=program.n_layers)


def layer_segments(program: Program, layer: int) -> tuple[np.ndarray, np.ndarray]:
    """(extrusions, travels) of ``layer``, each (k, 2, 2): start and end XY in print order."""
    on = program.layer == layer
    ext = on & program.extruding
    trv = on & travel_mask(program)

    def seg(m):
        return np.stack([program.start_mm[m, :2], program.end_mm[m, :2]], axis=1).astype(float)
    return seg(ext), seg(trv)


def default_layer(before_mm: np.ndarray, after_mm: np.ndarray) -> int:
    """The layer whose travel the re-ordering cut the most (else the one with the most travel)."""
    cut = before_mm - after_mm
    if len(cut) and cut.max() > 0:
        return int(np.argmax(cut))
    return int(np.argmax(before_mm)) if len(before_mm) else 0


def plot_ordering(original: Program, output: Program, path, *, layer: int | None = None,
                  title: str | None = None) -> Path:
    """Write a PNG with three panels: ``layer`` as the slicer ordered it, the same layer in
    ``output``'s order (extrusions grey, travels red, the travel of each in the title), and the
    travel of every layer before and after. ``layer`` (0-based, as in the JSON report's
    ``per_layer``): default ``default_layer``. Raises ``PlotError`` (a ``GatesoptError``) for a path
    that is not a writable ``.png``, files whose layers differ or a layer out of range."""
    p = check_png_path(path)
    if original.n_layers == 0:
        raise PlotError(f"{original.source}: nothing to plot: no layers found")
    if output.n_layers != original.n_layers:
        raise PlotError(f"{output.source}: {output.n_layers} layers, the original has "
                        f"{original.n_layers}: not a re-ordering of it")
    before, after = travel_per_layer_mm(original), travel_per_layer_mm(output)
    if layer is None:
        layer = default_layer(before, after)
    if not 0 <= layer < original.n_layers:
        raise PlotError(f"{original.source}: layer {layer} does not exist: layers are 0 to "
                        f"{original.n_layers - 1}")
    from matplotlib.backends.backend_agg import FigureCanvasAgg    # lazy: see module docstring
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure

    fig = Figure(figsize=(WIDTH_PX / DPI, HEIGHT_PX / DPI), dpi=DPI)
    FigureCanvasAgg(fig)
    ax_b, ax_a, ax_l = fig.subplots(1, 3, gridspec_kw={"width_ratios": [1, 1, 1.25]})
    name = os.path.basename(str(original.source)) or str(original.source)
    total_b, total_a = float(before.sum()), float(after.sum())
    change = f" ({100.0 * (total_a / total_b - 1.0):+.1f} %)" if total_b > 0 else ""
    fig.suptitle(title or f"{name}: travel {total_b:,.0f} mm -> {total_a:,.0f} mm{change}", fontsize=12)

    panels = [(ax_b, original, "slicer's order", before), (ax_a, output, "re-ordered", after)]
    segs = [layer_segments(prog, layer) for _, prog, _, _ in panels]
    pts = np.concatenate([s.reshape(-1, 2) for pair in segs for s in pair] + [np.zeros((0, 2))])
    for (ax, _, label, mm), (ext, trv) in zip(panels, segs):
        ax.add_collection(LineCollection(ext, colors=EXTRUSION_COLOR, linewidths=0.6))
        ax.add_collection(LineCollection(trv, colors=TRAVEL_COLOR, linewidths=0.9, alpha=0.85))
        ax.set_title(f"layer {layer}, {label}\ntravel {float(mm[layer]):,.1f} mm in {len(trv):,} moves "
                     f"({len(ext):,} extrusions)", fontsize=10)
        if len(pts):
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            pad = 0.03 * max(float((hi - lo).max()), 1.0)
            ax.set_xlim(lo[0] - pad, hi[0] + pad)
            ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_aspect("equal")
        ax.set_xlabel("X (mm)")
    ax_b.set_ylabel("Y (mm)")
    # one legend for both layer panels, under them (equal-aspect axes move with the layer's shape)
    from matplotlib.lines import Line2D
    fig.legend([Line2D([], [], color=EXTRUSION_COLOR, linewidth=1.2), Line2D([], [], color=TRAVEL_COLOR, linewidth=1.2)],
               ["extrusion", "travel"], loc="lower center", bbox_to_anchor=(0.33, 0.01), ncol=2,
               fontsize=9, frameon=False)

    xs = np.arange(original.n_layers)
    ax_l.plot(xs, before, color=EXTRUSION_COLOR, linewidth=1.0, label=f"slicer's order: {total_b:,.0f} mm")
    ax_l.plot(xs, after, color="#1f77b4", linewidth=1.0, label=f"re-ordered: {total_a:,.0f} mm")
    ax_l.axvline(layer, color=TRAVEL_COLOR, linestyle="--", linewidth=0.8, label=f"layer {layer} (left)")
    ax_l.set_xlim(0, max(original.n_layers - 1, 1))
    ax_l.set_ylim(0, max(float(before.max(initial=0.0)), float(after.max(initial=0.0)), 1e-9) * 1.08)
    ax_l.set_xlabel("layer")
    ax_l.set_ylabel("travel (mm)")
    ax_l.set_title("travel per layer", fontsize=10)
    ax_l.grid(True, alpha=0.3)
    ax_l.legend(loc="upper center", bbox_to_anchor=(0.5, -0.11), ncol=3, fontsize=8, frameon=False)

    fig.subplots_adjust(left=0.05, right=0.98, bottom=0.19, top=0.88, wspace=0.25)
    return save_png(fig, p)
