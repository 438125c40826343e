"""A self-contained HTML report of batch results, with the papers' figures drawn from real rows.

3DGates (ASPLOS'17): Fig. 11 energy-saving histogram, Fig. 13 saving by infill pattern, Fig. 14
energy vs model rotation, Fig. 15 file-size increase. Fleming et al.: Fig. 2 travel reduction by
slicer and pattern, Fig. 3 ordering runtime vs curves per layer. Plus greedy vs exact formulations.
Every figure is a PNG embedded as a data URI, so the page is one file that opens anywhere.
"""
from __future__ import annotations

import base64
import html
import io
import math
from collections import defaultdict
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .errors import GatesoptError
from .program import Program


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _num(v):
    try:
        x = float(v)
    except (TypeError, ValueError):
        return math.nan
    return x


def _ok(rows):
    return [r for r in rows if r.get("verified") in (True, "True", 1.0) and not r.get("error")]


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    _plt().close(fig)
    return buf.getvalue()


def _slicer(r) -> str:
    s = str(r.get("slicer") or "unknown").split()
    return s[0] if s else "unknown"


def _label(r) -> str:
    return str(r.get("infill_pattern") or "unknown")


#: up to this many files, a per-file quantity is drawn as one labelled bar per file (read at a
#: glance); beyond, as a histogram (the paper's Fig. 11 has 338 files)
PER_FILE_MAX = 30


def _file_label(r) -> str:
    """A row's file as a short label: its name without the G-code suffixes."""
    name = Path(str(r.get("file"))).name
    for suffix in (".gz", ".gcode", ".gco", ".g"):
        name = name.removesuffix(suffix)
    return name


def _legend_outside(ax) -> None:
    """The legend beside the axes (right), where it covers no bar or point."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=8, frameon=False)


def _annotate(ax, points) -> None:
    """Label each (text, x, y) beside its point: right of it in the left half of the data, left
    of it in the right half (labels stay inside the axes, off the legend)."""
    if not points:
        return
    mid = 0.5 * (min(p[1] for p in points) + max(p[1] for p in points))
    for text, x, y in points:
        right = x <= mid
        ax.annotate(text, (x, y), fontsize=6, xytext=(5 if right else -5, 0), textcoords="offset points",
                    va="center", ha="left" if right else "right")


def _integer_counts(ax, axis: str = "y") -> None:
    """Whole numbers only on a count axis ("files")."""
    from matplotlib.ticker import MaxNLocator
    (ax.yaxis if axis == "y" else ax.xaxis).set_major_locator(MaxNLocator(integer=True))


def _per_file(rows, key):
    """({file label: {formulation: value}}, formulations) over the verified rows with ``key``."""
    by = defaultdict(dict)
    for r in _ok(rows):
        v = _num(r.get(key))
        if not math.isnan(v):
            by[_file_label(r)][str(r.get("formulation", ""))] = v
    forms = sorted({f for d in by.values() for f in d})
    return dict(by), forms


def _over_budget(rows) -> set:
    """(file label, formulation) of the verified rows whose answer broke its budget (status
    ``infeasible``: greedy, the paper's Algorithm 1, takes no budget): their saving is bought
    with print time the user did not allow."""
    return {(_file_label(r), str(r.get("formulation", ""))) for r in _ok(rows)
            if str(r.get("status") or "") == "infeasible"}


def _file_bars(plt, by, forms, xlabel, value_fmt="{:.1f}", over=frozenset()):
    """Horizontal bars, one row per file (labelled, the largest first), one bar per formulation,
    each with its value written at its end; the legend beside the axes. A bar of ``over``
    (``_over_budget``) is hatched and its value marked."""
    files = sorted(by, key=lambda f: -max(by[f].values()))[::-1]      # largest at the top
    h = 0.8 / max(len(forms), 1)
    fig, ax = plt.subplots(figsize=(7.5, 1.2 + 0.32 * len(files) * max(1, len(forms))))
    y = np.arange(len(files))
    for k, fm in enumerate(forms):
        vals = [by[f].get(fm, math.nan) for f in files]
        bars = ax.barh(y + (len(forms) - 1 - k) * h - 0.4 + h / 2, vals, h, label=fm or None)
        for b, v, f in zip(bars, vals, files):
            if not math.isnan(v):
                broke = (f, fm) in over
                if broke:
                    b.set_hatch("///")
                    b.set_edgecolor("white")
                ax.text(b.get_width(), b.get_y() + b.get_height() / 2,
                        " " + value_fmt.format(v) + (" (over budget)" if broke else ""),
                        va="center", ha="left" if v >= 0 else "right", fontsize=7)
    ax.set_yticks(y, files, fontsize=8)
    ax.set_xlabel(xlabel)
    ax.margins(x=0.15)
    if len(forms) > 1:
        _legend_outside(ax)
    return fig, ax


def fig_saving_per_file(rows):
    plt = _plt()
    by, forms = _per_file(rows, "saving_pct")
    if not by:
        return None
    n = sum(len(d) for d in by.values())
    means = ", ".join(f"{fm} {np.mean([d[fm] for d in by.values() if fm in d]):.1f} %" for fm in forms)
    if len(by) <= PER_FILE_MAX:
        fig, ax = _file_bars(plt, by, forms, "energy saving (%)", over=_over_budget(rows))
        ax.set_title("Energy saving per file")
    else:
        fig, ax = plt.subplots(figsize=(7.5, 3.6))
        vals = {fm: [d[fm] for d in by.values() if fm in d] for fm in forms}
        top = max(5.0, max(max(v) for v in vals.values()) * 1.1)
        bins = np.linspace(min(0.0, min(min(v) for v in vals.values())), top, 21)
        for fm in forms:
            ax.hist(vals[fm], bins=bins, alpha=0.6, label=f"{fm} (mean {np.mean(vals[fm]):.1f} %)")
        ax.set_xlabel("energy saving (%)")
        ax.set_ylabel("files")
        _integer_counts(ax)
        _legend_outside(ax)
        ax.set_title("Energy saving per file (3DGates Fig. 11)")
    over = _over_budget(rows)
    broke = (f" {len(over)} of them broke their time budget (status infeasible: greedy, the paper's "
             "Algorithm 1, takes none), hatched where drawn per file: their saving costs print time "
             "the others were not allowed.") if over else ""
    return ("Energy saving per file", f"{n} verified rows; mean saving {means}.{broke} The paper reports a "
            "25 % mean over 338 files (its Fig. 11) on its own firmware and benchmark set.", _png(fig))


def fig_saving_by_pattern(rows):
    plt = _plt()
    ok = [r for r in _ok(rows) if not math.isnan(_num(r.get("saving_pct")))]
    if not ok:
        return None
    groups = defaultdict(list)
    for r in ok:
        groups[_label(r)].append(_num(r["saving_pct"]))
    names = sorted(groups, key=lambda k: -np.mean(groups[k]))
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.bar(range(len(names)), [np.mean(groups[n]) for n in names],
           yerr=[np.std(groups[n]) for n in names], capsize=3, color="#4c72b0")
    ax.set_xticks(range(len(names)), [f"{n}\n(n={len(groups[n])})" for n in names], fontsize=8)
    ax.set_ylabel("mean energy saving (%)")
    ax.set_xlabel("infill pattern (from the file's own settings; n rows)")
    ax.set_title("Saving by infill pattern (3DGates Fig. 13)")
    return ("Saving by infill pattern", "Mean and standard deviation over the rows of each pattern.", _png(fig))


def fig_rotation(rows, sweeps: dict | None):
    plt = _plt()
    if sweeps:
        return _fig_sweeps(plt, sweeps)
    ok = [r for r in _ok(rows) if not math.isnan(_num(r.get("rotation_deg")))]
    if not ok:
        return None
    fig, ax = plt.subplots(figsize=(7.5, 3.8))
    xs = [_num(r["rotation_deg"]) for r in ok]
    for fm in sorted({str(r.get("formulation")) for r in ok}):
        sel = [i for i, r in enumerate(ok) if str(r.get("formulation")) == fm]
        ax.scatter([xs[i] for i in sel], [_num(ok[i]["saving_pct"]) for i in sel], s=18, label=fm)
    ax.set_xticks(sorted(set(xs)), [f"{a:.6g}" for a in sorted(set(xs))])
    ax.margins(x=0.25)
    ax.set_xlabel("rotation chosen (degrees)")
    ax.set_ylabel("energy saving (%)")
    _legend_outside(ax)
    ax.set_title("Energy vs rotation (3DGates Fig. 14)")
    cap = ("Rotation each run chose and the saving it reached (each file's angle is in the table; "
           "`gatesopt report --sweep FILE` draws the paper's curve at the angles --rotate auto tries).")
    return ("Energy vs model rotation", cap, _png(fig))


def _angle_labels(angles) -> list[str]:
    """The angles as tick labels, with as many digits as it takes to tell them apart."""
    for digits in range(6, 12):
        labels = [f"{a:.{digits}g}" for a in angles]
        if len(set(labels)) == len(labels):
            return labels
    return labels


def _fig_sweeps(plt, sweeps: dict):
    """One panel per swept file: the gated energy at each angle ``--rotate auto`` tried, one slot
    per angle in increasing order (angles a thousandth of a degree apart stay apart), relative to
    0° (as sliced), the chosen angle starred."""
    fig, axes = plt.subplots(len(sweeps), 1, figsize=(7.5, 0.6 + 2.4 * len(sweeps)), squeeze=False)
    for ax, (name, sw) in zip(axes[:, 0], sweeps.items()):
        ang = np.asarray(sw.angles_deg, float)
        e = np.asarray(sw.energy_j, float)
        at0 = np.flatnonzero(np.abs(ang) < 1e-9)
        rel = e / (e[at0[0]] if len(at0) else e[0])
        x = np.arange(len(ang))
        ax.plot(x, rel, marker="o", color="#4c72b0", linewidth=0.8)
        c = int(np.argmin(np.abs(ang - sw.chosen_deg)))
        ax.plot([x[c]], [rel[c]], marker="*", markersize=16, color="#dd8452", linestyle="none")
        ax.axhline(1.0, color="#999", linewidth=0.6, linestyle="--")
        ax.set_xticks(x, _angle_labels(ang), rotation=45, ha="right", fontsize=7)
        ax.set_ylabel("energy / at 0°", fontsize=8)
        said = "chose" if sw.bed_checked else "would choose on a bed it fits (the file names no bed)"
        ax.set_title(f"{name}: --rotate auto {said} {sw.chosen_deg:.6g}° ({sw.formulation})", fontsize=9)
    axes[-1, 0].set_xlabel("the angles --rotate auto tries (degrees, counter-clockwise; one slot each)")
    fig.suptitle("Energy vs rotation (3DGates Fig. 14)")
    fig.tight_layout()
    forms = sorted({sw.formulation for sw in sweeps.values()})
    cap = (f"Gated energy ({', '.join(forms)}) with the print fixed at each angle --rotate auto tries "
           "(0, 30 and 60 as in the paper's sweep, and the angles that put the most moves on one "
           "axis), relative to 0° (as sliced); the star is the angle it chose.")
    if not all(sw.bed_checked for sw in sweeps.values()):
        cap += (" A file that names no bed is not rotated by the command (--bed WxD allows it): its "
                "panel is the model's what-if, unchecked against a bed.")
    return ("Energy vs model rotation", cap, _png(fig))


def fig_size_increase(rows):
    plt = _plt()
    by, forms = _per_file(rows, "size_change_pct")
    if not by:
        return None
    vals = [v for d in by.values() for v in d.values()]
    if len(by) <= PER_FILE_MAX:
        fig, ax = _file_bars(plt, by, forms, "file size increase (%)", over=_over_budget(rows))
        ax.set_title("File size increase per file (3DGates Fig. 15)")
    else:
        fig, ax = plt.subplots(figsize=(7, 3.6))
        ax.hist(vals, bins=20, color="#55a868")
        ax.set_xlabel("file size increase (%)")
        ax.set_ylabel("files")
        _integer_counts(ax)
        ax.set_title("File size increase (3DGates Fig. 15)")
    return ("File size increase", f"Mean {np.mean(vals):.2f} %, max {np.max(vals):.2f} % (the paper: about "
            "0.5 % mean, < 2 % max, for gating alone: a re-ordered file is rewritten too).", _png(fig))


def fig_travel(rows):
    plt = _plt()
    ok = [r for r in _ok(rows) if not math.isnan(_num(r.get("travel_reduction_pct")))
          and r.get("ordered") in (True, "True", 1.0)]
    if not ok:
        return None
    groups = defaultdict(list)
    for r in ok:
        groups[f"{_slicer(r)} / {_label(r)}"].append(_num(r["travel_reduction_pct"]))
    names = sorted(groups, key=lambda n: np.mean(groups[n]))
    fig, ax = plt.subplots(figsize=(7.5, 1.2 + 0.35 * len(names)))
    bars = ax.barh(range(len(names)), [np.mean(groups[n]) for n in names], color="#c44e52")
    for b, n in zip(bars, names):
        ax.text(b.get_width(), b.get_y() + b.get_height() / 2, f" {b.get_width():.1f} % (n={len(groups[n])})",
                va="center", fontsize=7)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.margins(x=0.2)
    ax.set_xlabel("travel reduction (%)")
    ax.set_title("Travel reduction by slicer and pattern (Fleming et al. Fig. 2)")
    return ("Travel reduction", "Non-extruding XY travel after curve ordering vs the slicer's own order "
            "(mean over the n rows of each slicer and infill pattern).", _png(fig))


def fig_ordering_runtime(rows):
    plt = _plt()
    ok = [r for r in _ok(rows) if not math.isnan(_num(r.get("max_curves_per_layer")))]
    if not ok:
        return None
    fig, ax = plt.subplots(figsize=(7, 3.6))
    for fm in sorted({str(r.get("formulation")) for r in ok}):
        sel = [r for r in ok if str(r.get("formulation")) == fm]
        ax.scatter([_num(r["max_curves_per_layer"]) for r in sel], [_num(r.get("wall_s")) for r in sel],
                   s=16, label=fm)
    if len({_file_label(r) for r in ok}) <= PER_FILE_MAX:
        top = {}
        for r in ok:        # each file labelled once, at its slowest row
            if _num(r.get("wall_s")) >= _num(top.get(_file_label(r), {}).get("wall_s", -1)):
                top[_file_label(r)] = r
        _annotate(ax, [(f, _num(r["max_curves_per_layer"]), _num(r["wall_s"])) for f, r in top.items()])
    _legend_outside(ax)
    ax.set_xlabel("curves in the largest layer")
    ax.set_ylabel("wall time per file (s)")
    ax.set_title("Runtime vs curves per layer (Fleming et al. Fig. 3)")
    return ("Runtime vs curves per layer", "Whole-file wall time (ordering + gating + verify).", _png(fig))


def fig_formulations(rows):
    """Greedy (the paper's Algorithm 1) against each other formulation, file by file: a point per
    file, above the diagonal where the other one saves more."""
    plt = _plt()
    by, forms = _per_file(rows, "saving_pct")
    if len(forms) < 2 or "greedy" not in forms:
        return None
    others = [f for f in forms if f != "greedy"]
    fig, ax = plt.subplots(figsize=(6.5, 5))
    lo, hi = math.inf, -math.inf
    for fm in others:
        files = [f for f in by if "greedy" in by[f] and fm in by[f]]
        xs = [by[f]["greedy"] for f in files]
        ys = [by[f][fm] for f in files]
        if not files:
            continue
        ax.scatter(xs, ys, s=18, label=fm)
        lo, hi = min(lo, *xs, *ys), max(hi, *xs, *ys)
        if len(files) <= PER_FILE_MAX:
            _annotate(ax, list(zip(files, xs, ys)))
    if not math.isfinite(lo):
        plt.close(fig)
        return None
    pad = 0.05 * max(hi - lo, 1.0)
    ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], color="#999", linewidth=0.8, label="equal")
    ax.set_xlabel("greedy: energy saving (%)")
    ax.set_ylabel("other formulation: energy saving (%)")
    _legend_outside(ax)
    ax.set_title("Greedy (the paper's Algorithm 1) vs the others")
    return ("Greedy vs exact", "Each file's saving with greedy (x) and with each other formulation (y): "
            "above the diagonal, that formulation saves more. Same files, same energy model, each "
            "formulation's verified output.", _png(fig))


# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Sweep:
    """Gated energy of one file at each angle ``--rotate auto`` tries (``rotation_sweep``)."""

    angles_deg: tuple[float, ...]       # the candidate angles, as the gating problem has them
    energy_j: tuple[float, ...]         # gated energy with the print fixed at each angle
    chosen_deg: float                   # the angle --rotate auto chose among them
    formulation: str
    bed_checked: bool = True            # False: the file names no bed, so the command would not
                                        # rotate it; the angles are those it would try on a bed


def rotation_sweep(program_or_path, formulation: str = "dp", options=None) -> Sweep:
    """The paper's Fig. 14 experiment for one file (a ``Program`` or a path), at the angles
    ``--rotate auto`` really tries: the gating problem's candidates (``gating.rotation``), each
    solved with the print fixed at that angle, and the angle auto chose. ``options``: the
    ``GatingOptions`` (default: the defaults; ``rotate`` is set here)."""
    from .gating.options import GatingOptions
    from .gating.problem import build
    from .gating.solve import solve
    from .parse import parse
    program = program_or_path if isinstance(program_or_path, Program) else parse(program_or_path)
    base = options or GatingOptions()
    auto = build(program, replace(base, rotate="auto"))
    plan = auto.rotation_plan
    bed_checked = True
    if len(auto.angles_deg) < 2 and plan is not None and plan.bed is None and not plan.notes:
        # no bed known (Cura files name none): the command would not turn the print at all; the
        # model's what-if at the angles it would try on a bed the print fits, said so in the figure
        bed_checked = False
        base = replace(base, check_bed=False)
        auto = build(program, replace(base, rotate="auto"))
    angles = [float(a) for a in auto.angles_deg]
    if len(angles) < 2:
        why = "; ".join(auto.notes) or (plan.why_none if plan is not None else "") or "no other angle fits"
        raise GatesoptError(f"{program.source}: no rotation sweep: --rotate auto tries only "
                            f"{angles[0] if angles else 0:g} deg on this file ({why})")
    chosen = solve(auto, formulation).rotation_deg
    energy = [float(solve(build(program, replace(base, rotate=a)), formulation).energy_j) for a in angles]
    order = np.argsort(angles, kind="stable")
    return Sweep(tuple(angles[i] for i in order), tuple(energy[i] for i in order), float(chosen), formulation,
                 bed_checked)


def build_figures(rows, sweeps=None):
    figs = [fig_saving_per_file(rows), fig_saving_by_pattern(rows), fig_rotation(rows, sweeps),
            fig_size_increase(rows), fig_travel(rows), fig_ordering_runtime(rows), fig_formulations(rows)]
    return [f for f in figs if f is not None]


#: the results table's columns: (heading, row key, format, scale)
TABLE_COLUMNS = (("saving %", "saving_pct", "{:.2f}", 1.0),
                 ("print time +% (planner)", "print_time_change_pct", "{:.2f}", 1.0),
                 ("size +%", "size_change_pct", "{:.1f}", 1.0), ("travel −%", "travel_reduction_pct", "{:.1f}", 1.0),
                 ("rotation °", "rotation_deg", "{:.6g}", 1.0), ("gap %", "gap", "{:.3f}", 100.0))


def render_table(rows) -> str:
    """The rows as one table, by file then formulation: what each run saved and cost, whether its
    output verified (or why not)."""
    ok = _ok(rows)
    head = "".join(f"<th>{html.escape(h)}</th>" for h, _, _, _ in TABLE_COLUMNS)
    out = ["<table id='results'><tr><th>file</th><th>formulation</th><th>firmware</th>" + head
           + "<th>status</th><th>verified</th></tr>"]
    for r in sorted(rows, key=lambda r: (_file_label(r), str(r.get("formulation")))):
        cells = []
        for _, key, fmt, scale in TABLE_COLUMNS:
            v = _num(r.get(key))
            cells.append("" if math.isnan(v) else fmt.format(v * scale))
        verdict = "yes" if r in ok else html.escape(str(r.get("error") or r.get("findings") or "no"))
        out.append(f"<tr><td>{html.escape(_file_label(r))}</td><td>{html.escape(str(r.get('formulation')))}</td>"
                   f"<td>{html.escape(str(r.get('firmware') or ''))}</td>"
                   + "".join(f"<td>{c}</td>" for c in cells)
                   + f"<td>{html.escape(str(r.get('status') or ''))}</td><td>{verdict}</td></tr>")
    out.append("</table>")
    return "\n".join(out)


def render_html(rows, figures, title="gatesopt results") -> str:
    """The page: a one-line summary, the results table first (it answers "what did each file
    get"), then the figures."""
    ok = _ok(rows)
    err = [r for r in rows if r.get("error")]
    sav = [_num(r.get("saving_pct")) for r in ok]
    sav = [v for v in sav if not math.isnan(v)]
    parts = [
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{html.escape(title)}</title>",
        "<style>body{font-family:sans-serif;max-width:960px;margin:2em auto;color:#222}"
        "figure{margin:1.5em 0}img{max-width:100%}table{border-collapse:collapse;font-size:12px}"
        "td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}td:first-child,th:first-child"
        "{text-align:left}tr:nth-child(even){background:#f6f6f6}"
        "figcaption{color:#555;font-size:13px}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
        f"<p>{len(rows)} rows, {len(ok)} verified, {len(err)} with errors. "
        + (f"Mean energy saving {np.mean(sav):.1f} %, max {np.max(sav):.1f} %." if sav else "")
        + (f" {len(_over_budget(rows))} verified rows broke their time budget (status infeasible)."
           if _over_budget(rows) else "") + "</p>",
        "<h2>Results</h2>",
        render_table(rows),
    ]
    for i, (name, caption, png) in enumerate(figures):
        b64 = base64.b64encode(png).decode()
        parts.append(f"<figure id='fig{i}'><h2>{html.escape(name)}</h2>"
                     f"<img class='figure' alt='{html.escape(name)}' src='data:image/png;base64,{b64}'>"
                     f"<figcaption>{html.escape(caption)}</figcaption></figure>")
    # lets a browser test (and a person) see that every figure decoded
    parts.append("<script>window.addEventListener('load',function(){var im=[].slice.call(document.images);"
                 "document.body.setAttribute('data-figures-rendered',im.filter(function(i){return i.complete&&"
                 "i.naturalWidth>0}).length+'/'+im.length);});</script>")
    parts.append("</body></html>")
    return "\n".join(parts)


def png_name(index: int, name: str) -> str:
    """The file name of figure ``index`` (0-based) titled ``name`` under ``--png DIR``."""
    return f"fig{index + 1:02d}_{name.lower().replace(' ', '_').replace('/', '')}.png"


def write_report(rows, out_html, png_dir=None, sweeps=None, title="gatesopt results",
                 overwrite: bool = False) -> list[str]:
    """The HTML page at ``out_html`` and, with ``png_dir``, each figure as a PNG there; returns the
    PNGs' paths. An existing PNG is replaced only with ``overwrite``, checked before anything is
    written; the page is written to a temporary file beside it and renamed."""
    if not rows:
        raise GatesoptError("no result rows to report")
    folder = Path(out_html).resolve().parent
    if not folder.is_dir():
        raise GatesoptError(f"{out_html}: folder {folder} does not exist")
    figures = build_figures(rows, sweeps)
    text = render_html(rows, figures, title)
    pngs = [Path(png_dir) / png_name(i, name) for i, (name, _, _) in enumerate(figures)] if png_dir else []
    if not overwrite:
        for p in pngs:
            if p.exists():
                raise GatesoptError(f"{p}: exists; pass --force to overwrite it")
    tmp = Path(out_html).with_name(f".{Path(out_html).name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(out_html)
    if png_dir:
        Path(png_dir).mkdir(parents=True, exist_ok=True)
        for p, (_, _, png) in zip(pngs, figures):
            p.write_bytes(png)
    return [str(p) for p in pngs]
