"""Best-known values for the bundled instances: `python instances/best_known.py` rewrites best_known.tsv.

Gating: the exact optimum (dp, proven by its own bound and cross-checked by milp) under the defaults
of `gatesopt solve` (paper energy profile, 3DGates firmware S0/S1, motors X and Y, start-ahead
1.8 ms, end-late 1.0 ms, rotation auto), curve ordering off. Ordering: travel after the `auto`
formulation in safe mode (as every report measures it, ``rewrite.figures.travel``: non-extruding
XY moves from the first layer on) and how many groups were proven optimal.
"""
from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def rows():
    import gatesopt
    from gatesopt import gating, ordering
    from gatesopt.rewrite.figures import travel
    for path in sorted(HERE.glob("*.gcode")):
        program = gatesopt.parse(path)
        problem = gating.build(program, gating.GatingOptions())
        dp = gating.solve(problem, "dp")
        milp = gating.solve(problem, "milp", time_limit_s=60)
        assert dp.status == "optimal" and abs(milp.energy_j - dp.energy_j) <= 1e-6 * dp.energy_j, path.name
        oprob = ordering.build(program)
        osol = ordering.solve(oprob, "auto", time_limit_s=10)
        out = gatesopt.parse(ordering.emit(program, oprob, osol))
        statuses = [g.status for g in osol.groups] if hasattr(osol, "groups") else []
        proven = sum(s == "optimal" for s in statuses)
        yield (path.name, f"{dp.energy_before_j:.6f}", f"{dp.energy_j:.6f}", f"{dp.saving_pct:.4f}",
               f"{dp.rotation_deg:.6g}", f"{travel(program)['travel_mm']:.3f}", f"{travel(out)['travel_mm']:.3f}",
               f"{proven}/{len(statuses)}")


def main() -> int:
    head = ("file", "energy_before_j", "gated_energy_j", "saving_pct", "rotation_deg", "travel_before_mm",
            "travel_after_mm", "ordering_groups_optimal")
    lines = ["\t".join(head)] + ["\t".join(r) for r in rows()]
    (HERE / "best_known.tsv").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
