"""Power-gating evaluation over ../shared/instances (issue 3, "Evaluation").

For every file: saving %, added lines, file-size change, added time, status/gap and solve time of
the paper's greedy re-compiler vs dp vs milp (3DGates firmware, X and Y, rotate auto), and the
same under the Marlin and Klipper cost models with a 1 % added-time budget. Every output is
verified (``gatesopt.verify``) and counted only if it passes.

    python bench/gating.py                         # all files, table on stdout
    python bench/gating.py --json out.json --markdown out.md
    python bench/gating.py --files real_slic3r131_stars.gcode --milp-time-limit 20

Run from the repository root with ../shared/instances beside it.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import gatesopt  # noqa: E402
from gatesopt.gating import GatingOptions  # noqa: E402
from gatesopt.rewrite import run  # noqa: E402

SHARED = REPO.parent / "shared" / "instances"

# (label, firmware, formulation, rotate, added-time budget %)
CONFIGS = [
    ("greedy", "3dgates", "greedy", "auto", None),
    ("dp", "3dgates", "dp", "auto", None),
    ("milp", "3dgates", "milp", "auto", None),
    ("marlin 1%", "marlin", "milp", "none", 1.0),
    ("klipper 1%", "klipper", "milp", "none", 1.0),
]


def files(names=None):
    all_files = sorted(p for p in SHARED.iterdir() if p.name.endswith((".gcode", ".gcode.gz")))
    if names:
        all_files = [p for p in all_files if p.name in set(names)]
    return all_files


def bench_file(path: Path, configs, milp_time_limit_s: float) -> list[dict]:
    t0 = time.perf_counter()
    program = gatesopt.parse(path)
    parse_s = time.perf_counter() - t0
    rows = []
    for label, fw, form, rot, budget in configs:
        t = time.perf_counter()
        try:
            opts = GatingOptions.for_firmware(fw, rotate=rot, max_added_time_pct=budget)
            r = run(program, opts, formulation=form, order=False,
                    time_limit_s=milp_time_limit_s if form in ("milp", "cpsat") else None)
        except gatesopt.GatesoptError as exc:
            rows.append({"file": path.name, "config": label, "error": str(exc)})
            continue
        s = r.summary()
        rows.append({
            "file": path.name, "config": label, "firmware": fw, "formulation": form,
            "verified": r.report.ok, "findings": [str(f) for f in r.report.findings[:3]],
            "saving_pct": s["saving_pct"], "rotation_deg": s["rotation_deg"],
            "lines_added_pct": 100.0 * s["lines_added"] / max(s["lines_before"], 1),
            "instruction_lines": s["instruction_lines"], "size_change_pct": s["size_change_pct"],
            "added_time_pct": s["added_time_pct"], "status": s["status"], "gap": s["gap"],
            "solve_s": s["solve_s"], "wall_s": time.perf_counter() - t, "parse_s": parse_s,
            "steps": program.n_steps,
        })
    return rows


def firmware_peers(program) -> dict:
    """Energy saving % of what firmware already does, on the same energy model (no rewrite):

    - ``marlin_disable_xy``: Marlin's compile-time DISABLE_X/DISABLE_Y: an axis is off while no
      block in the planner queue steps it; simulated with a 16-block look-ahead (BLOCK_BUFFER_SIZE):
      X is on in step i iff one of steps i..i+15 steps X (the axis is then untrusted: homing lost).
    - ``hold_current``: TMC hold-current reduction (Marlin HOLD_MULTIPLIER 0.5): a motor idle for
      more than 2 s draws half its power until its next step (Marlin default timeout ~2 s).
    """
    import numpy as np
    from gatesopt.energy import load_profile, step_energy_j
    from gatesopt.program import X, Y
    coeffs = load_profile("paper").coefficients(program)
    en0 = np.asarray(program.enabled, bool)
    dur = np.asarray(program.duration_s, float)
    base = float(step_energy_j(dur, coeffs, en0).sum())
    steps = np.asarray(program.steps_motor(), bool)
    n = program.n_steps
    en = en0.copy()
    for m in (X, Y):
        c = np.concatenate(([0], np.cumsum(steps[:, m])))
        ahead = c[np.minimum(np.arange(n) + 16, n)] - c[np.arange(n)]
        en[:, m] &= ahead > 0
    marlin = float(step_energy_j(dur, coeffs, en).sum())
    t_end = np.cumsum(dur)
    t_start = t_end - dur
    saved = 0.0
    for m in (X, Y):
        rows = np.flatnonzero(steps[:, m])
        last = np.full(n, -np.inf)
        if len(rows):
            idx = np.searchsorted(rows, np.arange(n), "right") - 1      # last stepping row <= i
            ok = idx >= 0
            last[ok] = t_end[rows[idx[ok]]]
            last[steps[:, m]] = np.inf                                     # stepping now: full power
        lo = np.maximum(t_start, last + 2.0)
        idle = np.clip(t_end - lo, 0.0, dur)
        saved += float((0.5 * coeffs.motor_w[:, m] * en0[:, m] * idle).sum())
    return {"marlin_disable_xy": 100.0 * (1 - marlin / base), "hold_current": 100.0 * saved / base}


def sweep(path: Path, step_deg: float = 5.0) -> list[tuple[float, float, bool]]:
    """dp saving % against a fixed rotation angle (the paper's Fig. 14): (deg, saving %, verified)."""
    program = gatesopt.parse(path)
    out = []
    deg = 0.0
    while deg < 90.0 + 1e-9:
        r = run(program, GatingOptions.for_firmware("3dgates", rotate=deg), formulation="dp", order=False)
        out.append((deg, r.summary()["saving_pct"], r.report.ok))
        deg += step_deg
    return out


def markdown(rows: list[dict], command: str) -> str:
    labels = [c[0] for c in CONFIGS if any(r["config"] == c[0] for r in rows)]
    files_ = list(dict.fromkeys(r["file"] for r in rows))
    out = [f"Command: `{command}`", ""]
    out.append("| file | " + " | ".join(f"{l} saving %" for l in labels) + " | dp lines +% | dp size +% | "
               "dp rot deg | milp status (gap) | milp solve s | klipper 1% time +% |")
    out.append("|---|" + "---:|" * len(labels) + "---:|---:|---:|---|---:|---:|")
    for f in files_:
        by = {r["config"]: r for r in rows if r["file"] == f}
        cells = []
        for l in labels:
            r = by.get(l)
            if r is None or "error" in r:
                cells.append("error" if r else "")
            elif not r["verified"]:
                cells.append(f"FAIL ({r['saving_pct']:.2f})")
            else:
                cells.append(f"{r['saving_pct']:.2f}")
        dp = by.get("dp", {})
        ml = by.get("milp", {})
        kl = by.get("klipper 1%", {})
        gap = ml.get("gap")
        out.append(f"| {f} | " + " | ".join(cells) + " | "
                   f"{dp.get('lines_added_pct', float('nan')):.1f} | {dp.get('size_change_pct', float('nan')):.1f} | "
                   f"{dp.get('rotation_deg', float('nan')):.3g} | {ml.get('status', '')}"
                   f"{'' if gap is None else f' ({100 * gap:.3f} %)'} | {ml.get('solve_s', float('nan')):.1f} | "
                   f"{kl.get('added_time_pct', float('nan')):.2f} |")
    # summary lines
    out.append("")
    for l in labels:
        ok = [r for r in rows if r["config"] == l and r.get("verified")]
        bad = [r for r in rows if r["config"] == l and not r.get("verified")]
        if ok:
            sv = sorted(r["saving_pct"] for r in ok)
            out.append(f"- **{l}**: {len(ok)} files verified, {len(bad)} failed/errored; saving mean "
                       f"{sum(sv) / len(sv):.2f} %, median {sv[len(sv) // 2]:.2f} %, max {sv[-1]:.2f} %; "
                       f"size +{sum(r['size_change_pct'] for r in ok) / len(ok):.1f} % mean; "
                       f"time +{sum(r['added_time_pct'] for r in ok) / len(ok):.3f} % mean")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--files", nargs="*", help="file names in ../shared/instances (default: all)")
    ap.add_argument("--configs", default=",".join(c[0] for c in CONFIGS),
                    help="comma-separated labels of CONFIGS to run")
    ap.add_argument("--milp-time-limit", type=float, default=60.0)
    ap.add_argument("--json", help="write the rows as JSON")
    ap.add_argument("--markdown", help="write a markdown table")
    ap.add_argument("--sweep", nargs="*", metavar="FILE",
                    help="instead: dp saving vs fixed rotation angle (0..90 deg) for these files")
    ap.add_argument("--sweep-step", type=float, default=5.0)
    ap.add_argument("--peers", action="store_true",
                    help="instead: firmware's own gating (Marlin DISABLE_X/Y) and hold-current reduction")
    args = ap.parse_args(argv)
    if not SHARED.exists():
        print(f"{SHARED} absent", file=sys.stderr)
        return 2
    if args.peers:
        for path in files(args.files):
            d = firmware_peers(gatesopt.parse(path))
            print(f"| {path.name} | {d['marlin_disable_xy']:.3f} | {d['hold_current']:.3f} |", flush=True)
        return 0
    if args.sweep:
        for name in args.sweep:
            res = sweep(SHARED / name, args.sweep_step)
            print(f"{name}: " + "  ".join(f"{d:g}:{v:.2f}{'' if ok else '!'}" for d, v, ok in res), flush=True)
        return 0
    want = set(args.configs.split(","))
    configs = [c for c in CONFIGS if c[0] in want]
    rows = []
    for path in files(args.files):
        rs = bench_file(path, configs, args.milp_time_limit)
        for r in rs:
            if "error" in r:
                print(f"{r['file']:42s} {r['config']:11s} ERROR {r['error']}", flush=True)
            else:
                print(f"{r['file']:42s} {r['config']:11s} {'ok' if r['verified'] else 'FAIL':4s} "
                      f"saving {r['saving_pct']:6.2f} %  rot {r['rotation_deg']:7.3f}  lines "
                      f"+{r['lines_added_pct']:6.2f} %  size {r['size_change_pct']:+6.2f} %  time "
                      f"+{r['added_time_pct']:.3f} %  {r['status']}  solve {r['solve_s']:.2f} s "
                      f"wall {r['wall_s']:.1f} s", flush=True)
                for f in r["findings"]:
                    print(f"    {f}", flush=True)
        rows += rs
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=str) + "\n")
    if args.markdown:
        cmd = "python bench/gating.py " + " ".join(argv if argv is not None else sys.argv[1:])
        Path(args.markdown).write_text(markdown(rows, cmd) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
