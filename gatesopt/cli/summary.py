"""Lines of the reports more than one command prints."""
from __future__ import annotations


def ordering_result_lines(s: dict) -> list[str]:
    """The lines of a re-ordering's report (``rewrite.order.order_summary``) that say what it
    did: travel, times, travels, curves, groups and layers (``order`` and ``solve`` print them)."""
    def pct(a, b):
        return f"{100.0 * (a / b - 1.0):+.1f} %" if b else "n/a"
    return [
        f"travel        {s['travel_before_mm']:,.1f} mm -> {s['travel_after_mm']:,.1f} mm"
        f"   ({pct(s['travel_after_mm'], s['travel_before_mm'])})",
        f"travel time   {s['travel_time_before_s']:,.1f} s -> {s['travel_time_after_s']:,.1f} s"
        f"   ({pct(s['travel_time_after_s'], s['travel_time_before_s'])})",
        f"print time    {s['print_time_before_s']:,.1f} s -> {s['print_time_after_s']:,.1f} s"
        f"   ({pct(s['print_time_after_s'], s['print_time_before_s'])}; travels, retractions, z-hops)",
        f"travels       {s['travels_before']:,} -> {s['travels_after']:,}"
        f"   retractions {s['retractions_before']:,} -> {s['retractions_after']:,}",
        f"curves        {s['curves']:,} in {s['groups']:,} groups; {s['groups_reordered']:,} re-orderable "
        f"(largest {s['largest_group']} curves)",
        f"groups        optimal {s['groups_optimal']:,}   feasible at limit {s['groups_feasible']:,}"
        f"   fallback {s['groups_fallback']:,}   worst gap {100 * s['worst_gap']:.2f} %",
        f"layers        optimal {s['layers_optimal']:,}   feasible at limit {s['layers_feasible']:,}"
        f"   fallback {s['layers_fallback']:,}   order kept {s['layers_kept']:,}"
        + (f" ({s['layers_kept_slower']:,} of them: slower re-ordered)" if s.get("layers_kept_slower") else ""),
    ]
