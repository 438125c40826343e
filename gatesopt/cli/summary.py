"""Lines of the reports more than one command prints."""
from __future__ import annotations


def ordering_result_lines(s: dict) -> list[str]:
    """The lines of a re-ordering's report (``rewrite.order.order_summary``) that say what it
    did: travel, times, travels, curves, groups and layers (``order`` and ``solve`` print them)."""
    def pct(a, b):
        return f"{100.0 * (a / b - 1.0):+.1f} %" if b else "n/a"
    lead = []
    if s.get("print_time_planner_before_s") is not None:
        lead.append(f"print time    {s['print_time_planner_before_s']:,.1f} s -> "
                    f"{s['print_time_planner_after_s']:,.1f} s   "
                    f"({pct(s['print_time_planner_after_s'], s['print_time_planner_before_s'])}; "
                    f"planner model; objective: {s.get('objective', 'time')})")
    return lead + [
        f"travel        {s['travel_before_mm']:,.1f} mm -> {s['travel_after_mm']:,.1f} mm"
        f"   ({pct(s['travel_after_mm'], s['travel_before_mm'])})",
        f"travel time   {s['travel_time_before_s']:,.1f} s -> {s['travel_time_after_s']:,.1f} s"
        f"   ({pct(s['travel_time_after_s'], s['travel_time_before_s'])})",
        f"paper time    {s['print_time_before_s']:,.1f} s -> {s['print_time_after_s']:,.1f} s"
        f"   ({pct(s['print_time_after_s'], s['print_time_before_s'])}; T = L/F, no acceleration)",
        f"travels       {s['travels_before']:,} -> {s['travels_after']:,}"
        f"   retractions {s['retractions_before']:,} -> {s['retractions_after']:,}",
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
    """Safe mode's islands re-ordered as blocks (``ordering/blocks.py``), when a layer had some."""
    if not s.get("block_segments"):
        return []
    return [f"islands       {s['block_islands']:,} islands in {s['block_segments']:,} runs of >= 3; "
            f"re-ordered as blocks in {s['block_segments_moved']:,} runs ({s['block_layers_moved']:,} "
            f"layers); block order proven optimal in {s['block_orders_optimal']:,}"]


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
