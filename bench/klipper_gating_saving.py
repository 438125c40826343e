"""Issue 34's "saving equals the 3dgates optimum within 0.5 points", file by file, with the gap taken
apart: what the paper's patched firmware would save, what gatesopt's Klipper module saves, and why
they differ.

For every corpus file, same rotation (none) and no ordering, each the optimum of its own problem
(``dp``, exact where the problem separates: no budget, one pin per motor):

- *3dgates*: ``--firmware 3dgates`` (the paper's S0/S1 lines, T = L / F, no stall: the optimum the
  issue compares with);
- *3dgates on Klipper's planner*: the same problem timed by gatesopt's planner with Klipper's rules
  and the replay's printer.cfg (bench/klipper/printer.cfg), the time model klipper-gating is priced
  on: the difference to the first is the time model alone;
- *klipper-gating*: ``--firmware klipper-gating --printer-config`` that printer.cfg (rules A and B
  with the module's ``min_pin_spacing``, 0.1 s by default);
- *spacing 0*: the same with rules A and B at 0 s (``Schedule.min_off_s`` and ``min_spacing_s``):
  what the module would save if Klipper let one pin change twice in less than 0.1 s -- it does
  not (integrations/klipper/README.md, "Pin spacing"); *rule A only* / *rule B only*: one of them
  at 0;
- the same with an input shaper (``--input-shaper``, its step window widens every margin).

    python bench/klipper_gating_saving.py [--files a.gcode,b.gcode.gz] [--input-shaper none,mzv:30]
        [--json rows.json]

The energy of each is gatesopt's report of the verified output (``gatesopt solve`` gives the same
numbers: it runs this build and solve, then emits and verifies).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import klipper_replay as kr  # noqa: E402  (bench/klipper_replay.py: the corpus and the printer.cfg)

from gatesopt.gating import GatingOptions, build, solve  # noqa: E402
from gatesopt.parse import parse  # noqa: E402
from gatesopt.printer_config import read_printer_config  # noqa: E402

#: (key, pin_queue_slots, rule A's floor, rule B's spacing); None: the dialect's own. ``kg`` is the
#: module's default (two queued changes per pin), ``kg1`` one change in flight (pin_queue_slots: 1)
VARIANTS = (("kg", 2, None, None), ("kg1", 1, None, None), ("rule_b_only", 1, 0.0, None),
            ("rule_a_only", 1, None, 0.0), ("spacing0", 1, 0.0, 0.0))


def saving_pct(program, options) -> float:
    return solve(build(program, options), "dp").saving_pct


def file_row(path: Path, printers: dict) -> dict:
    t0 = time.perf_counter()
    prog = parse(path)
    paper = GatingOptions.for_firmware("3dgates", rotate="none")
    row = {"file": path.name, "3dgates": saving_pct(prog, paper)}
    base = printers["none"]
    row["3dgates_planner"] = saving_pct(prog, paper.replace(time_model="planner", planner_family="klipper",
                                                            printer=base))
    for shaper, printer in printers.items():
        kg = GatingOptions.for_firmware("klipper-gating", printer=printer, rotate="none")
        for key, slots, min_off, spacing in VARIANTS:
            sch = kg.schedule
            floor = sch.min_off_s if slots == 2 else max(sch.min_off_s, sch.min_spacing_s)
            sch = dataclasses.replace(sch, pin_queue_slots=slots, min_off_s=floor if min_off is None else min_off,
                                      min_spacing_s=sch.min_spacing_s if spacing is None else spacing)
            row[f"{key}_{shaper}"] = saving_pct(prog, kg.replace(schedule=sch))
    row["s"] = time.perf_counter() - t0
    return row


def table(rows: list[dict], shapers: list[str]) -> str:
    """Per file: the saving of each, and the points klipper-gating (two queued changes per pin, the
    module's default) is below 3dgates taken apart: below = time model (3dgates - 3dgates on
    Klipper's planner) + pin spacing (spacing 0 - klipper-gating) + the rest (3dgates on Klipper's
    planner - spacing 0: the margins, the shaper's window with one, the lower-bound clock); and
    klipper-gating with one change in flight (``pin_queue_slots: 1``)."""
    head = ["file", "3dgates %", "3dgates, Klipper's planner %"]
    for sh in shapers:
        tag = "" if sh == "none" else f", {sh}"
        head += [f"K=1{tag} %", f"klipper-gating{tag} %", f"below{tag}", "= time model", "+ pin spacing",
                 "+ rest"]
    out = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * (len(head) - 1)]
    for r in rows:
        tm = r["3dgates"] - r["3dgates_planner"]
        cells = [r["file"], f"{r['3dgates']:.2f}", f"{r['3dgates_planner']:.2f}"]
        for sh in shapers:
            kg, s0 = r["kg_" + sh], r["spacing0_" + sh]
            cells += [f"{r['kg1_' + sh]:.2f}", f"{kg:.2f}", f"{r['3dgates'] - kg:+.2f}", f"{tm:+.2f}",
                      f"{s0 - kg:+.2f}", f"{r['3dgates_planner'] - s0:+.2f}"]
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


def summary(rows: list[dict], shapers: list[str]) -> str:
    med = statistics.median
    lines = ["| measure | " + " | ".join(shapers) + " |", "|---|" + "---:|" * len(shapers)]

    def add(name, fn):
        lines.append(f"| {name} | " + " | ".join(fn(sh) for sh in shapers) + " |")

    def spread(fn, sh, signed=False):
        v = [fn(r, sh) for r in rows]
        f = "{:+.2f}" if signed else "{:.2f}"
        return f"{f.format(med(v))} [{f.format(min(v))}, {f.format(max(v))}]"

    for key, name in (("kg1", "K=1 (one change in flight)"), ("kg", "K=2 (the default)"),
                      ("spacing0", "spacing 0 (any K: the most a pin queue can give)")):
        add(f"files at most 0.5 points below 3dgates, {name}",
            lambda sh, key=key: f"{sum(r['3dgates'] - r[key + '_' + sh] <= 0.5 for r in rows)} of {len(rows)}")
        add(f"files within 0.5 points either side, {name}",
            lambda sh, key=key: f"{sum(abs(r['3dgates'] - r[key + '_' + sh]) <= 0.5 for r in rows)} of {len(rows)}")
    for key, name in (("kg1", "K=1"), ("kg", "K=2")):
        add(f"points below 3dgates, {name}: median [min, max]",
            lambda sh, key=key: spread(lambda r, s: r["3dgates"] - r[key + "_" + s], sh))
    add("mean saving: 3dgates / K=1 / K=2",
        lambda sh: f"{statistics.mean(r['3dgates'] for r in rows):.2f} / "
                   f"{statistics.mean(r['kg1_' + sh] for r in rows):.2f} / "
                   f"{statistics.mean(r['kg_' + sh] for r in rows):.2f}")
    add("time model (3dgates on Klipper's planner - 3dgates): median [min, max]",
        lambda sh: spread(lambda r, s: r["3dgates_planner"] - r["3dgates"], sh, signed=True))
    add("pin spacing, K=1 (spacing 0 - K=1): median [min, max]",
        lambda sh: spread(lambda r, s: r["spacing0_" + s] - r["kg1_" + s], sh))
    add("of it rule A (off time >= spacing) alone: median [min, max]",
        lambda sh: spread(lambda r, s: r["rule_b_only_" + s] - r["kg1_" + s], sh))
    add("of it rule B (on -> next off >= spacing) alone: median [min, max]",
        lambda sh: spread(lambda r, s: r["rule_a_only_" + s] - r["kg1_" + s], sh))
    add("pin spacing, K=2 (spacing 0 - K=2): median [min, max]",
        lambda sh: spread(lambda r, s: r["spacing0_" + s] - r["kg_" + s], sh))
    add("the rest (3dgates on Klipper's planner - spacing 0): median [min, max]",
        lambda sh: spread(lambda r, s: r["3dgates_planner"] - r["spacing0_" + s], sh, signed=True))
    add("spacing 0 within 0.5 points of 3dgates on Klipper's planner",
        lambda sh: f"{sum(abs(r['3dgates_planner'] - r['spacing0_' + sh]) <= 0.5 for r in rows)} of {len(rows)}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", default=None, help="comma separated corpus files (default: all of MANIFEST.tsv)")
    ap.add_argument("--input-shaper", default="none,mzv:30", help="comma separated: none, TYPE:HZ")
    ap.add_argument("--json", default=None, help="write the rows here")
    ap.add_argument("--from-json", default=None, help="print the tables of rows written before (no solving)")
    a = ap.parse_args(argv)
    shapers = [s.strip() for s in a.input_shaper.split(",")]
    if a.from_json:
        rows = json.loads(Path(a.from_json).read_text())
        print(summary(rows, shapers))
        print()
        print(table(rows, shapers))
        return 0
    if a.files:
        files = kr.corpus_files(a.files)
    else:
        manifest = (kr.SHARED / "MANIFEST.tsv").read_text().splitlines()[1:]
        files = [kr.SHARED / ln.split("\t")[0] for ln in manifest if ln.strip()]
    shapers = [s.strip() for s in a.input_shaper.split(",")]
    printers = {}
    with tempfile.TemporaryDirectory() as tmp:
        for sh in shapers:
            cfg = Path(tmp) / f"{sh.replace(':', '_')}.cfg"
            cfg.write_text(kr.printer_config(kr.parse_shaper(sh), {}))
            printers[sh] = read_printer_config(cfg)
    if "none" not in printers:
        ap.error("--input-shaper must include none (the 3dgates-on-Klipper's-planner column uses it)")
    rows = []
    for f in files:
        rows.append(file_row(f, printers))
        print(f"{f.name}: {rows[-1]['s']:.1f} s", file=sys.stderr, flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))
    print(summary(rows, shapers))
    print()
    print(table(rows, shapers))
    return 0


if __name__ == "__main__":
    sys.exit(main())
