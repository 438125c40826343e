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
from pathlib import Path

import numpy as np

from .errors import GatesoptError


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


# ------------------------------------------------------------------------------------------------
# figures: each returns (title, caption, png bytes) or None when the rows hold no data for it
def fig_saving_histogram(rows):
    plt = _plt()
    ok = [r for r in _ok(rows) if not math.isnan(_num(r.get("saving_pct")))]
    if not ok:
        return None
    by_form = defaultdict(list)
    for r in ok:
        by_form[r.get("formulation", "")].append(_num(r["saving_pct"]))
    fig, ax = plt.subplots(figsize=(7, 3.6))
    bins = np.linspace(0, max(5.0, max(max(v) for v in by_form.values()) * 1.1), 21)
    for form, vals in sorted(by_form.items()):
        ax.hist(vals, bins=bins, alpha=0.6, label=f"{form} (mean {np.mean(vals):.1f} %)")
    ax.set_xlabel("energy saving (%)")
    ax.set_ylabel("files")
    ax.legend()
    ax.set_title("Energy saving per file (3DGates Fig. 11)")
    return ("Energy saving per file", f"{len(ok)} verified rows. The paper reports a 25 % mean over "
            "338 files on its own firmware and benchmark set.", _png(fig))


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
    ax.bar(names, [np.mean(groups[n]) for n in names], yerr=[np.std(groups[n]) for n in names], capsize=3,
           color="#4c72b0")
    for i, n in enumerate(names):
        ax.text(i, np.mean(groups[n]), f"n={len(groups[n])}", ha="center", va="bottom", fontsize=8)
    ax.set_ylabel("mean energy saving (%)")
    ax.set_xlabel("infill pattern (from the file's own settings)")
    ax.tick_params(axis="x", rotation=40)
    ax.set_title("Saving by infill pattern (3DGates Fig. 13)")
    return ("Saving by infill pattern", "Mean and standard deviation over the files of each pattern.", _png(fig))


def fig_rotation(rows, sweeps: dict | None):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 3.6))
    if sweeps:
        for name, pts in sweeps.items():
            ang = [p[0] for p in pts]
            e = np.array([p[1] for p in pts])
            ref = e[np.argmin(np.abs(np.array(ang) - 90.0))] if 90.0 in ang else e[0]
            ax.plot(ang, e / ref, marker="o", label=name)
        ax.set_xlabel("model rotation (degrees, counter-clockwise)")
        ax.set_ylabel("gated energy / energy at 90°")
        ax.legend(fontsize=8)
        cap = "Gated energy (dp) at each 30° rotation, normalised to 90° as in the paper."
    else:
        ok = [r for r in _ok(rows) if not math.isnan(_num(r.get("rotation_deg")))]
        if not ok:
            plt.close(fig)
            return None
        ax.scatter([_num(r["rotation_deg"]) for r in ok], [_num(r["saving_pct"]) for r in ok], s=14)
        ax.set_xlabel("rotation chosen (degrees)")
        ax.set_ylabel("energy saving (%)")
        cap = "Rotation the solver chose and the saving it reached (run with --sweep for the paper's curve)."
    ax.set_title("Energy vs rotation (3DGates Fig. 14)")
    return ("Energy vs model rotation", cap, _png(fig))


def fig_size_increase(rows):
    plt = _plt()
    ok = [r for r in _ok(rows) if not math.isnan(_num(r.get("size_change_pct")))]
    if not ok:
        return None
    vals = [_num(r["size_change_pct"]) for r in ok]
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.hist(vals, bins=20, color="#55a868")
    ax.set_xlabel("file size increase (%)")
    ax.set_ylabel("files")
    ax.set_title("File size increase (3DGates Fig. 15)")
    return ("File size increase", f"Mean {np.mean(vals):.2f} %, max {np.max(vals):.2f} % (the paper: about "
            "0.5 % mean, < 2 % max).", _png(fig))


def fig_travel(rows):
    plt = _plt()
    ok = [r for r in _ok(rows) if not math.isnan(_num(r.get("travel_reduction_pct")))
          and r.get("ordered") in (True, "True", 1.0)]
    if not ok:
        return None
    groups = defaultdict(list)
    for r in ok:
        groups[f"{_slicer(r)} / {_label(r)}"].append(_num(r["travel_reduction_pct"]))
    names = sorted(groups)
    fig, ax = plt.subplots(figsize=(8, 3.8))
    ax.bar(names, [np.mean(groups[n]) for n in names], color="#c44e52")
    ax.set_ylabel("travel reduction (%)")
    ax.tick_params(axis="x", rotation=60, labelsize=7)
    ax.set_title("Travel reduction by slicer and pattern (Fleming et al. Fig. 2)")
    return ("Travel reduction", "Non-extruding XY travel after curve ordering vs the slicer's own order.", _png(fig))


def fig_ordering_runtime(rows):
    plt = _plt()
    ok = [r for r in _ok(rows) if not math.isnan(_num(r.get("max_curves_per_layer")))]
    if not ok:
        return None
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.scatter([_num(r["max_curves_per_layer"]) for r in ok], [_num(r.get("wall_s")) for r in ok], s=14)
    ax.set_xlabel("curves in the largest layer")
    ax.set_ylabel("wall time per file (s)")
    ax.set_title("Runtime vs curves per layer (Fleming et al. Fig. 3)")
    return ("Runtime vs curves per layer", "Whole-file wall time (ordering + gating + verify).", _png(fig))


def fig_formulations(rows):
    plt = _plt()
    ok = _ok(rows)
    forms = sorted({r.get("formulation") for r in ok})
    if len(forms) < 2:
        return None
    by = defaultdict(dict)
    for r in ok:
        by[Path(str(r["file"])).name][r["formulation"]] = _num(r["saving_pct"])
    files = sorted(f for f in by if len(by[f]) == len(forms))
    if not files:
        return None
    fig, ax = plt.subplots(figsize=(max(7, 0.35 * len(files)), 3.8))
    w = 0.8 / len(forms)
    x = np.arange(len(files))
    for k, fm in enumerate(forms):
        ax.bar(x + k * w, [by[f][fm] for f in files], w, label=fm)
    ax.set_xticks(x + 0.4 - w / 2, [f[:22] for f in files], rotation=70, fontsize=6)
    ax.set_ylabel("energy saving (%)")
    ax.legend()
    ax.set_title("Formulations side by side (greedy = the paper's Algorithm 1)")
    return ("Greedy vs exact", "Same files, same energy model, each formulation's verified output.", _png(fig))


# ------------------------------------------------------------------------------------------------
def rotation_sweep(path, angles=tuple(range(0, 360, 30)), formulation: str = "dp") -> list[tuple[float, float]]:
    """Gated energy at each fixed rotation (the paper's Fig. 14 experiment) for one file."""
    from .gating.options import GatingOptions
    from .gating.problem import build
    from .gating.solve import solve
    from .parse import parse
    from .slicers import read_bed
    program = parse(path)
    out, refused = [], []
    for a in angles:
        try:
            # the model's what-if at each angle (nothing is printed): a file that names no bed is
            # swept unchecked; one that does has the angles that do not fit refused
            bed_known = read_bed(program.data) is not None
            sol = solve(build(program, GatingOptions(rotate=float(a), check_bed=bed_known)), formulation)
        except GatesoptError as e:
            refused.append(str(e))      # e.g. the rotated print does not fit the bed
            continue
        out.append((float(a), float(sol.energy_j)))
    if len(out) < 2 and refused:
        # one point is no sweep: say why instead of drawing it (a print of objects one at a
        # time is never rotated; a plate filled to the edge fits only as sliced)
        raise GatesoptError(f"{path}: no rotation sweep: {len(refused)} of {len(angles)} angles "
                            f"refused, the first: {refused[0]}")
    return out


def build_figures(rows, sweeps=None):
    figs = [fig_saving_histogram(rows), fig_saving_by_pattern(rows), fig_rotation(rows, sweeps),
            fig_size_increase(rows), fig_travel(rows), fig_ordering_runtime(rows), fig_formulations(rows)]
    return [f for f in figs if f is not None]


def render_html(rows, figures, title="gatesopt results") -> str:
    ok = _ok(rows)
    err = [r for r in rows if r.get("error")]
    sav = [_num(r.get("saving_pct")) for r in ok]
    sav = [v for v in sav if not math.isnan(v)]
    parts = [
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{html.escape(title)}</title>",
        "<style>body{font-family:sans-serif;max-width:960px;margin:2em auto;color:#222}"
        "figure{margin:1.5em 0}img{max-width:100%}table{border-collapse:collapse;font-size:12px}"
        "td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}td:first-child{text-align:left}"
        "figcaption{color:#555;font-size:13px}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
        f"<p>{len(rows)} rows, {len(ok)} verified, {len(err)} with errors. "
        + (f"Mean energy saving {np.mean(sav):.1f} %, max {np.max(sav):.1f} %.</p>" if sav else "</p>"),
    ]
    for i, (name, caption, png) in enumerate(figures):
        b64 = base64.b64encode(png).decode()
        parts.append(f"<figure id='fig{i}'><h2>{html.escape(name)}</h2>"
                     f"<img class='figure' alt='{html.escape(name)}' src='data:image/png;base64,{b64}'>"
                     f"<figcaption>{html.escape(caption)}</figcaption></figure>")
    parts.append("<h2>Rows</h2><table><tr><th>file</th><th>formulation</th><th>saving %</th><th>size +%</th>"
                 "<th>print time +% (planner)</th><th>status</th><th>gap</th><th>travel −%</th><th>verified / error</th></tr>")
    for r in rows:
        def f(k, d=1):
            v = _num(r.get(k))
            return "" if math.isnan(v) else f"{v:.{d}f}"
        parts.append(f"<tr><td>{html.escape(Path(str(r.get('file'))).name)}</td><td>{html.escape(str(r.get('formulation')))}</td>"
                     f"<td>{f('saving_pct')}</td><td>{f('size_change_pct', 2)}</td><td>{f('print_time_change_pct', 2)}</td>"
                     f"<td>{html.escape(str(r.get('status', '')))}</td><td>{f('gap', 4)}</td>"
                     f"<td>{f('travel_reduction_pct')}</td>"
                     f"<td>{'yes' if r in ok else html.escape(str(r.get('error') or r.get('findings') or 'no'))}</td></tr>")
    parts.append("</table>")
    # lets a browser test (and a person) see that every figure decoded
    parts.append("<script>window.addEventListener('load',function(){var im=[].slice.call(document.images);"
                 "document.body.setAttribute('data-figures-rendered',im.filter(function(i){return i.complete&&"
                 "i.naturalWidth>0}).length+'/'+im.length);});</script>")
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(rows, out_html, png_dir=None, sweeps=None, title="gatesopt results") -> list[str]:
    if not rows:
        raise GatesoptError("no result rows to report")
    folder = Path(out_html).resolve().parent
    if not folder.is_dir():
        raise GatesoptError(f"{out_html}: folder {folder} does not exist")
    figures = build_figures(rows, sweeps)
    text = render_html(rows, figures, title)
    Path(out_html).write_text(text, encoding="utf-8")
    names = []
    if png_dir:
        d = Path(png_dir)
        d.mkdir(parents=True, exist_ok=True)
        for i, (name, _, png) in enumerate(figures):
            p = d / f"fig{i + 1:02d}_{name.lower().replace(' ', '_').replace('/', '')}.png"
            p.write_bytes(png)
            names.append(str(p))
    return names
