"""Lines of the reports more than one command prints."""
from __future__ import annotations


def _pct(a, b) -> str:
    return f"{100.0 * (a / b - 1.0):+.1f} %" if b else "n/a"


def figure_lines(s: dict) -> list[str]:
    """The print time and travel of a run (``rewrite.figures``: one print time, the planner
    model's; travel measured on the files): ``solve``, ``order`` and ``compare`` print them."""
    return [
        f"print time    {s['print_time_before_s']:,.1f} s -> {s['print_time_after_s']:,.1f} s"
        f"   ({_pct(s['print_time_after_s'], s['print_time_before_s'])}; planner model: "
        "acceleration, junction speeds, firmware stops"
        + (f"; ordering objective: {s['objective']}" if s.get("objective") else "") + ")",
        f"travel        {s['travel_before_mm']:,.1f} mm -> {s['travel_after_mm']:,.1f} mm"
        f"   ({_pct(s['travel_after_mm'], s['travel_before_mm'])})"
        f"   travels {s['travels_before']:,} -> {s['travels_after']:,}"
        f"   retractions {s['retractions_before']:,} -> {s['retractions_after']:,}"
        + (f" (wipes {s['wipes_before']:,} -> {s['wipes_after']:,})"
           if s.get("wipes_before") or s.get("wipes_after") else ""),
    ]


def ordering_result_lines(s: dict) -> list[str]:
    """The lines of a re-ordering's report (``rewrite.order.order_summary``) that say how it was
    solved: curves, groups and layers (``order`` and ``solve`` print them)."""
    return [
        f"curves        {s['curves']:,} in {s['groups']:,} groups; {s['groups_reordered']:,} re-orderable "
        f"(largest {s['largest_group']} curves)",
    ] + _block_lines(s) + [
        f"groups        optimal {s['groups_optimal']:,}   feasible at limit {s['groups_feasible']:,}"
        f"   fallback {s['groups_fallback']:,}   worst gap {100 * s['worst_gap']:.2f} %",
        f"layers        optimal {s['layers_optimal']:,}   feasible at limit {s['layers_feasible']:,}"
        f"   fallback {s['layers_fallback']:,}   order kept {s['layers_kept']:,}"
        + (f" ({s['layers_kept_slower']:,} of them: slower re-ordered)" if s.get("layers_kept_slower") else ""),
    ] + _kept_lines(s)


def _block_lines(s: dict) -> list[str]:
    """Safe mode's islands and labelled objects re-ordered as blocks (``ordering/blocks.py``),
    when a layer had some, and the objects that kept their place."""
    out = []
    if s.get("block_segments"):
        out.append(f"islands       {s['block_islands']:,} islands in {s['block_segments']:,} runs of >= 3; "
                   f"re-ordered as blocks in {s['block_segments_moved']:,} runs ({s['block_layers_moved']:,} "
                   f"layers); block order proven optimal in {s['block_orders_optimal']:,}")
    if s.get("object_runs"):
        out.append(f"objects       {s['object_count']:,} labelled objects in {s['object_runs']:,} runs of >= 3; "
                   f"re-ordered as blocks in {s['object_runs_moved']:,} runs; "
                   f"order proven optimal in {s['object_orders_optimal']:,}")
    kept = s.get("objects_kept") or {}
    if kept:
        out.append("objects kept  " + "; ".join(f"{n:,} ({why})" for why, n in sorted(kept.items())))
    return out


def _kept_lines(s: dict) -> list[str]:
    """Why layers kept the slicer's order, one line per reason with the layers' count and the
    first few layer numbers (the per-layer rows of ``--json`` say it layer by layer)."""
    why: dict[str, list[int]] = {}
    for row in s.get("per_layer", []):
        if row.get("status") == "kept" and row.get("kept_why"):
            why.setdefault(row["kept_why"], []).append(row["layer"])
    out = []
    for reason, layers in sorted(why.items(), key=lambda kv: -len(kv[1])):
        head = ", ".join(str(x) for x in layers[:6]) + (", ..." if len(layers) > 6 else "")
        out.append(f"kept          {len(layers):,} layers ({head}): {reason}")
    return out


def time_spent_line(s: dict) -> str:
    """Where a ``solve`` run's time went (``RunResult.times``): the whole run, then each stage;
    every solve counted (the ordering's, the rotation search and the solve again after it)."""
    t = s.get("times", {})
    parts = [f"read {t.get('read_s', 0.0):.2f}"]
    if "ordering_s" in t:
        parts.append(f"ordering {t['ordering_s']:.2f} (solve {t.get('ordering_solve_s', 0.0):.2f})")
    if "gating_solve_s" in t:
        g = t.get("gating_build_s", 0.0) + t.get("gating_solve_s", 0.0) + t.get("rotate_s", 0.0) + t.get("emit_s", 0.0)
        solve = f"solve {t['gating_solve_s']:.2f}"
        if "resolve_s" in t:
            solve += (f": rotation search {t.get('rotation_search_s', 0.0):.2f}, rotating "
                      f"{t.get('rotate_s', 0.0):.2f}, solve again {t['resolve_s']:.2f}")
        parts.append(f"gating {g:.2f} ({solve})")
    parts.append(f"verify {t.get('verify_s', 0.0):.2f}")
    parts.append(f"report {t.get('report_s', 0.0):.2f}")
    return f"time spent    {s['wall_s']:.2f} s: " + ", ".join(parts) + " s"
