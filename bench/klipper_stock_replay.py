"""The stock ``--firmware klipper`` dialect in Klipper's own host (issue 34): steps while off, the
cost of each ``SET_STEPPER_ENABLE`` line against gatesopt's price, start-ahead and end-late.

Each file is solved with ``gatesopt solve --firmware klipper`` (``--solve-args``, default
``--no-order``) and replayed with bench/klipper_replay.py's machinery (klippy in batch mode, the
MCU stream decoded) on each printer of ``--input-shaper``, four times: the original, the output,
the output without its gating lines and the output without its ``ENABLE=1`` lines (Klipper's own
re-enable at the next move instead). So:

- *ms/enable* = (output - output without ENABLE=1 lines) / enable lines;
- *ms/disable* = (output without ENABLE=1 lines - output without gating lines) / disable lines;
- *instr s* = output - output without gating lines, against gatesopt's price of those lines
  (the report's added paper time: disable lines x ``stall_off_s`` + each enable line priced per
  move, ``planner.stop_restart_s`` + its restart);
- *rest s* = output without gating lines - original: what the rest of the rewrite costs (split
  moves; 0 extrude-only moves are split by this dialect).

    python bench/klipper_stock_replay.py --files 'real_*' --input-shaper none,mzv:30 \\
        --json /tmp/stock.json [--write docs/RESULTS.md]
    python bench/klipper_stock_replay.py --from-json /tmp/stock.json --write docs/RESULTS.md

Rows go to ``--json`` as each file finishes (a long run can be cut and still be written).
"""
from __future__ import annotations

import argparse
import json
import math
import re
import shlex
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import klipper_replay as kr  # noqa: E402  (bench/klipper_replay.py)

from gatesopt import firmware as fwmod  # noqa: E402

TITLE = "## Klipper replay: the stock klipper dialect with explicit enables (issue 34)"
ENABLE_ON = re.compile(r"^SET_STEPPER_ENABLE\s+STEPPER=\w+\s+ENABLE=1\s*$", re.M)
ENABLE_OFF = re.compile(r"^SET_STEPPER_ENABLE\s+STEPPER=\w+\s+ENABLE=0\s*$", re.M)


def without(text: str, pattern: re.Pattern) -> str:
    return "\n".join(ln for ln in text.splitlines() if not pattern.match(ln)) + "\n"


def row_of(file: str, shaper: str, orig, out, stripped, no_on, report: dict, out_text: str, orig_text: str) -> dict:
    fw = fwmod.get("klipper")
    n_on, n_off = len(ENABLE_ON.findall(out_text)), len(ENABLE_OFF.findall(out_text))
    instr_s = out.end_s - stripped.end_s
    # gatesopt's price of the lines: what its report adds to the paper time (the dialect changes
    # no move's time; disables x stall_off_s, each enable priced per move, planner.stop_restart_s)
    before, after = report.get("paper_time_before_s"), report.get("paper_time_after_s")
    model_s = (after - before) if before is not None and after is not None else \
        n_off * fw.stall_off_s + n_on * fw.stall_on_s
    gated = [v for v in out.steppers.values() if v.gated]
    return {
        "file": file, "shaper": shaper, "print_s": orig.print_s, "added_s": out.end_s - orig.end_s,
        "added_pct": 100 * (out.end_s - orig.end_s) / orig.print_s,
        "model_added_pct": report.get("added_time_pct"), "enables": n_on, "disables": n_off,
        "instr_s": instr_s, "model_instr_s": model_s,
        "instr_vs_model_pct": 100 * (instr_s - model_s) / model_s if model_s else float("nan"),
        "ms_enable": 1000 * (out.end_s - no_on.end_s) / n_on if n_on else float("nan"),
        "ms_disable": 1000 * (no_on.end_s - stripped.end_s) / n_off if n_off else float("nan"),
        "rest_s": stripped.end_s - orig.end_s,
        "e_only_extra": kr.count_extrude_only_moves(out_text) - kr.count_extrude_only_moves(orig_text),
        "steps_while_off": {kr.MOTOR_OF[k]: v.gated_steps_while_off for k, v in out.steppers.items()},
        "no_enable_steps_while_off": {kr.MOTOR_OF[k]: v.gated_steps_while_off for k, v in no_on.steppers.items()},
        "start_ahead_min_s": min((v.start_ahead_min_s for v in gated), default=float("nan")),
        "start_ahead_median_s": min((v.start_ahead_median_s for v in gated), default=float("nan")),
        "end_late_min_s": min((v.end_late_min_s for v in gated), default=float("nan")),
        "off_s": {kr.MOTOR_OF[k]: v.off_time_s for k, v in out.steppers.items() if v.gated},
        "report_off_s": report.get("off_time_s", {}), "saving_pct": report.get("saving_pct"),
        "verified": report.get("verified"),
    }


def run(a) -> list[dict]:
    host = kr.find_host()
    if isinstance(host, str):
        raise SystemExit("klipper_stock_replay: " + host)
    rows: list[dict] = []
    work = Path(tempfile.mkdtemp(prefix="gatesopt-stock-"))
    shapers = [kr.parse_shaper(s) for s in a.input_shaper.split(",")]
    with kr.KlippyRunner(host) as k:
        for path in kr.corpus_files(a.files):
            orig_raw = kr.read_gcode(path)
            try:
                out_path, report = kr.solve(path, "klipper", shlex.split(a.solve_args), work)
            except kr.ReplayError as exc:
                rows.append({"file": path.name, "shaper": "-", "error": str(exc)})
                continue
            out_raw = kr.read_gcode(out_path)
            for shaper in shapers:
                cfg = kr.printer_config(shaper)
                pins = kr.stepper_pins(cfg)
                label = shaper.label if shaper else "none"
                t0 = time.perf_counter()
                try:
                    reps = [k.run(cfg, kr.replay_text(t)[0], pins) for t in
                            (orig_raw, out_raw, kr.strip_gating_lines(out_raw, "klipper"), without(out_raw, ENABLE_ON))]
                except kr.ReplayError as exc:
                    rows.append({"file": path.name, "shaper": label, "error": str(exc)})
                    continue
                r = row_of(path.name, label, *reps, report, out_raw, orig_raw)
                r["replay_s"] = time.perf_counter() - t0
                rows.append(r)
                print(f"{path.name} [{label}]: added {r['added_s']:+.2f} s, instr {r['instr_s']:.2f} / model "
                      f"{r['model_instr_s']:.2f} s, steps while off {r['steps_while_off']} (without enables "
                      f"{r['no_enable_steps_while_off']}), {r['replay_s']:.0f} s", file=sys.stderr, flush=True)
            if a.json:
                Path(a.json).write_text(json.dumps({"command": a.command, "rows": rows}, indent=1, default=float))
    return rows


def _f(x, fmt="{:.1f}") -> str:
    return "—" if x is None or (isinstance(x, float) and math.isnan(x)) else fmt.format(x)


def _range(vals, fmt="{:.1f}") -> str:
    v = [x for x in vals if x is not None and not (isinstance(x, float) and math.isnan(x))]
    if not v:
        return "—"
    return f"{fmt.format(float(np.median(v)))} [{fmt.format(min(v))}, {fmt.format(max(v))}]"


def _swo(d: dict) -> str:
    return "0" if not any(d.values()) else "**" + " ".join(f"{k} {v}" for k, v in d.items() if v) + "**"


def tables(rows: list[dict]) -> str:
    out = ["| shaper | files | errors | files with steps while off (steps) | same without ENABLE=1 lines | "
           "added % median [min, max] | model % median | ms/enable | ms/disable | instr replay vs model % | "
           "start-ahead min ms | end-late min ms |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for label in dict.fromkeys(r["shaper"] for r in rows):
        rs = [r for r in rows if r["shaper"] == label]
        ok = [r for r in rs if "error" not in r]
        bad = [r for r in ok if any(r["steps_while_off"].values())]
        bad0 = [r for r in ok if any(r["no_enable_steps_while_off"].values())]
        sa = [r["start_ahead_min_s"] for r in ok if not math.isnan(r["start_ahead_min_s"])]
        el = [r["end_late_min_s"] for r in ok if not math.isnan(r["end_late_min_s"])]
        out.append(
            f"| {label} | {len(ok)} | {len(rs) - len(ok)} | {len(bad)} ({sum(sum(r['steps_while_off'].values()) for r in bad)}) | "
            f"{len(bad0)} ({sum(sum(r['no_enable_steps_while_off'].values()) for r in bad0)}) | "
            f"{_range([r['added_pct'] for r in ok], '{:+.2f}')} | {_range([r['model_added_pct'] for r in ok], '{:+.2f}')} | "
            f"{_range([r['ms_enable'] for r in ok])} | {_range([r['ms_disable'] for r in ok])} | "
            f"{_range([r['instr_vs_model_pct'] for r in ok], '{:+.1f}')} | "
            f"{_f(1000 * min(sa), '{:.2f}') if sa else '—'} | {_f(1000 * min(el), '{:.2f}') if el else '—'} |")
    out += ["", "| file | shaper | print s | added s (%) | model % | on / off lines | ms/enable | ms/disable | "
            "instr s replay / model | rest s | E-only +n | steps while off (without ENABLE=1) | "
            "start-ahead min / med ms | end-late min ms | off s replay / report |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        if "error" in r:
            out.append(f"| {r['file']} | {r['shaper']} | {r['error'][:120]} |" + " |" * 12)
            continue
        off = " ".join(f"{m} {r['off_s'].get(m, 0.0):.1f}/{float(r['report_off_s'].get(m, 0.0)):.1f}"
                       for m in sorted(set(r["off_s"]) | {m for m, v in r["report_off_s"].items() if v}))
        out.append(
            f"| {r['file']} | {r['shaper']} | {r['print_s']:.1f} | {r['added_s']:+.2f} ({r['added_pct']:+.2f} %) | "
            f"{_f(r['model_added_pct'], '{:+.2f}')} | {r['enables']} / {r['disables']} | {_f(r['ms_enable'])} | "
            f"{_f(r['ms_disable'])} | {r['instr_s']:.2f} / {r['model_instr_s']:.2f} | {r['rest_s']:+.2f} | "
            f"{r['e_only_extra']:+d} | {_swo(r['steps_while_off'])} ({_swo(r['no_enable_steps_while_off'])}) | "
            f"{_f(1000 * r['start_ahead_min_s'], '{:.2f}')} / {_f(1000 * r['start_ahead_median_s'], '{:.2f}')} | "
            f"{_f(1000 * r['end_late_min_s'], '{:.2f}')} | {off or '—'} |")
    return "\n".join(out)


def section(rows: list[dict], command: str) -> str:
    return "\n".join([
        TITLE, "", "Command (from the repository root, Klipper from $GATESOPT_KLIPPER, "
        "$GATESOPT_KLIPPY_PYTHON, $GATESOPT_KLIPPER_DICT):", "", "```", command, "```", "",
        "Each file solved with `gatesopt solve --firmware klipper` and replayed in Klipper's own host "
        "(bench/klipper_replay.py's printer and decoder; *shaper*: an `[input_shaper]` section, both "
        "axes) four times: original, output, output without its gating lines, output without its "
        "`ENABLE=1` lines (Klipper's own re-enable at the next move, the dialect before this change). "
        "*model %*: gatesopt's added time; *ms/enable*, *ms/disable*: what each line adds in Klipper; "
        "*instr s replay / model*: time the gating lines add in Klipper vs gatesopt's price of them "
        "(the report's added time: disables x `stall_off_s` + each enable priced per move by the speed "
        "its flush stops, `planner.stop_restart_s`); *rest s*: output without gating lines "
        "vs original (split moves); *steps while off*: steps sent while a gated pin was off; "
        "*start-ahead*: pin on -> next step of that motor; *end-late*: last step -> pin off.", "",
        tables(rows), ""])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", help="comma-separated names or globs in ../shared/instances")
    ap.add_argument("--input-shaper", default="none,mzv:30")
    ap.add_argument("--solve-args", default="--no-order", help="`gatesopt solve` options")
    ap.add_argument("--json", metavar="FILE")
    ap.add_argument("--from-json", metavar="FILE", help="no replay: the rows of an earlier --json")
    ap.add_argument("--write", nargs="?", const=str(kr.RESULTS), metavar="MD")
    a = ap.parse_args(argv)
    a.command = "python bench/klipper_stock_replay.py " + " ".join(shlex.quote(x) for x in sys.argv[1:])
    if a.from_json:
        saved = json.loads(Path(a.from_json).read_text())
        rows, command = saved["rows"], saved["command"]
    else:
        rows, command = run(a), a.command
    print(tables(rows))
    if a.write:
        from _markdown import replace_section  # bench/_markdown.py
        replace_section(Path(a.write), section(rows, command))
    return 0


if __name__ == "__main__":
    sys.exit(main())
