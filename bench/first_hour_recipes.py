"""The README's "For your printer" recipes, measured as a user runs them, and issue 37's done-when
check (every real file solved with the defaults, the output verified on its own).

    python bench/first_hour_recipes.py [--write docs/RESULTS.md] [--out rows.tsv]
    python bench/first_hour_recipes.py --check [--write docs/RESULTS.md] [--out check.tsv]

Recipes (README "For your printer"), each a `gatesopt solve IN -o OUT` process exactly as written
there (plus `--json R` to read the figures), run with rotation on and off:

- ``stock``: `gatesopt solve IN -o OUT`: the firmware read from the file (Marlin's M18/M17 or
  Klipper's SET_STEPPER_ENABLE) and the stock-firmware 1 % time budget; rotation on: the default
  (`--rotate auto`, which turns the print only on a bed the file names), with `--bed WxD` of the
  printer the file was sliced for where the file names none (Cura); rotation off: `--rotate none`;
- ``3dgates``: the same with `--firmware 3dgates` (the paper's S0/S1, patched firmware).

The files (``RECIPE_FILES``) are named below: PrusaSlicer (Marlin), Cura (Marlin, no bed in the
file), Cura files for an Ender 3 on Klipper (`--printer-config` bench/klipper/printer.cfg, a
cartesian Klipper printer; stock recipe only) and files for corexy Klipper printers (OrcaSlicer,
SuperSlicer, Cura for a Creality K1 Max; PrusaSlicer's Voron profile: no X/Y gating) from ../shared/instances (MANIFEST.tsv) and from ../fresh (manifest.tsv: slices the
project never saw during development). One process at a time.

``--check``: every file of ../shared/instances and ../fresh, `gatesopt solve IN -o OUT` with no
option at all, then `gatesopt verify IN OUT` as a separate process (the output checked on its own).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _markdown import replace_section  # bench/_markdown.py

REPO = Path(__file__).resolve().parents[1]
KLIPPER = "Klipper corexy (Orca, SuperSlicer, Cura K1 Max, PrusaSlicer Voron)"
#: Cura files for an Ender 3 run by Klipper: `--printer-config` of a cartesian Klipper printer
#: (the replay bench's, bench/klipper/printer.cfg), the README's Klipper recipe
KLIPPER_CARTESIAN = "Klipper cartesian (Cura Ender 3 files, --printer-config)"
KLIPPER_CFG = REPO / "bench" / "klipper" / "printer.cfg"
#: (file stem, kind, ``--bed`` for rotation on when the file names no bed: the printer definition
#: it was sliced with, from MANIFEST.tsv / manifest.tsv)
RECIPE_FILES = (
    ("real_prusa261_benchy", "PrusaSlicer / Marlin", None),
    ("prusa25_star_rect15_m82", "PrusaSlicer / Marlin", None),
    ("prusa25_cyl_gyroid20", "PrusaSlicer / Marlin", None),
    ("holes__prusa_mk3s", "PrusaSlicer / Marlin", None),
    ("pins__prusa_mk3s", "PrusaSlicer / Marlin", None),
    ("plate__prusa_mk3s", "PrusaSlicer / Marlin", None),
    ("cura413_star_triangles20", "Cura / Marlin", "235x235"),     # creality_ender3.def.json
    ("cura413_cyl_grid20", "Cura / Marlin", "235x235"),
    ("cube__cura_ender3", "Cura / Marlin", "235x235"),
    ("pins__cura_ender3", "Cura / Marlin", "235x235"),
    ("plate__cura_mk3", "Cura / Marlin", "250x210"),               # prusa_i3_mk3.def.json
    ("real_orca230_arcs", KLIPPER, None),
    ("real_superslicer2356_arcwelder", KLIPPER, None),
    ("real_cura591", KLIPPER, "300x300"),                          # ;TARGET_MACHINE.NAME:Creality K1 Max
    ("cura413_star_triangles20", KLIPPER_CARTESIAN, "235x235"),
    ("cura413_cyl_grid20", KLIPPER_CARTESIAN, "235x235"),
    ("cube__cura_ender3", KLIPPER_CARTESIAN, "235x235"),
    ("pins__cura_ender3", KLIPPER_CARTESIAN, "235x235"),
    ("phonecase__prusa_klipper", KLIPPER, None),                   # PrusaSlicer's Voron profile
    ("pins__prusa_klipper", KLIPPER, None),
    ("plate__prusa_klipper", KLIPPER, None),
)
RECIPES = {"stock": [], "3dgates": ["--firmware", "3dgates"]}


def gatesopt_cmd() -> list[str]:
    exe = Path(sys.executable).parent / "gatesopt"
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "gatesopt"]


def find(stem: str, dirs: list[Path]) -> Path | None:
    for d in dirs:
        for suffix in (".gcode", ".gcode.gz"):
            if (d / f"{stem}{suffix}").exists():
                return d / f"{stem}{suffix}"
    return None


def _last_line(text: str) -> str:
    lines = [ln for ln in text.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else ""


def solve(path: Path, extra: list[str], tmp: Path, verify: bool = False) -> dict:
    """One `gatesopt solve IN -o OUT [extra]` process; its --json figures; optionally `gatesopt
    verify IN OUT` as another process."""
    out, rj = tmp / "out.gcode", tmp / "r.json"
    for p in (out, rj):
        if p.exists():
            p.unlink()
    cmd = [*gatesopt_cmd(), "solve", str(path), "-o", str(out), *extra, "--json", str(rj)]
    t = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True)
    row = {"rc": r.returncode, "wall_s": time.perf_counter() - t,
           "error": _last_line(r.stderr) if r.returncode else ""}
    if r.returncode == 0:
        d = json.loads(rj.read_text())
        row.update(saving_pct=d["saving_pct"], added_time_pct=d["added_time_pct"], rotation_deg=d["rotation_deg"],
                   verified=d["verified"], firmware=d["firmware"], status=d["status"], solve_s=d["solve_s"],
                   run_s=d.get("wall_s", float("nan")), firmware_line=d.get("firmware_line", ""),
                   rotation_line=d.get("rotation_line", ""),
                   read=((d.get("firmware_choice") or {}).get("read") or {}).get("kind") or "nothing")
        if verify:
            v = subprocess.run([*gatesopt_cmd(), "verify", str(path), str(out)], capture_output=True, text=True)
            row.update(verify_rc=v.returncode, verify_line=_last_line(v.stdout if v.returncode != 2 else v.stderr))
    return row


def _fmt(v, spec: str = ".2f") -> str:
    return "-" if v is None or v != v else format(v, spec)


def _stats(vals) -> str:
    return "-" if not vals else f"{statistics.mean(vals):.1f} / {statistics.median(vals):.1f} / {max(vals):.1f}"


def _env(cmd: str) -> str:
    return (f"Command: `{cmd}` ({platform.machine()}, {os.cpu_count()} cores shared with other work, Python "
            f"{platform.python_version()}, {time.strftime('%Y-%m-%d')}); one `gatesopt` process at a time.")


def recipe_tables(rows: list[dict], cmd: str) -> str:
    md = ["## For your printer: the README recipes measured (issue 37)", "", _env(cmd),
          "Every run is `gatesopt solve IN -o OUT` as the README writes it (defaults: curve ordering "
          "with its 10 s budget, `dp`, `--firmware auto`), plus `--json R`; rotation on = the default "
          "`--rotate auto` (with `--bed WxD` of the printer the file was sliced for where the file names "
          "no bed), off = `--rotate none`. Saving = energy saving of the 3DGates model, added time = "
          "`added_time_pct`: the print time against the file as given (planner model, the `print time` "
          "every command reports; re-ordering, rotation and the firmware's stalls together), what the "
          "stock 1 % budget bounds since issue 37's follow-up; solve time = the run's `solve_s` (wall time "
          "of the whole `gatesopt` process in the per-file table).", "",
          "| printer (files) | recipe | rotation | saving % mean / median / max | added time % mean / max "
          "| rotated | verified |", "|---|---|---|---:|---:|---:|---:|"]
    kinds = list(dict.fromkeys(r["kind"] for r in rows))
    for kind in kinds:
        for recipe in RECIPES:
            for rotate in ("on", "off"):
                sel = [r for r in rows if r["kind"] == kind and r["recipe"] == recipe and r["rotate"] == rotate]
                if not sel:
                    continue
                ok = [r for r in sel if r["rc"] == 0]
                add = [r["added_time_pct"] for r in ok]
                md.append(f"| {kind} ({len(sel)}) | {recipe} | {rotate} | {_stats([r['saving_pct'] for r in ok])} | "
                          f"{_fmt(statistics.mean(add) if add else None)} / {_fmt(max(add) if add else None)} | "
                          f"{sum(1 for r in ok if r['rotation_deg'])} | {sum(1 for r in ok if r['verified'])}/{len(sel)} |")
    md += ["", "Per file (firmware = the dialect `--firmware auto` chose and what it read it from; deg = the "
           "angle rotation on chose):", "",
           "| file | set | firmware (read from) | --bed | stock on % | stock off % | deg | added time % on / off "
           "| 3dgates on % | 3dgates off % | deg | solve s (stock on) | run s |",
           "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for f in dict.fromkeys(r["file"] for r in rows):
        g = {(r["recipe"], r["rotate"]): r for r in rows if r["file"] == f}
        so, sf, go, gf = (g.get(k, {}) for k in (("stock", "on"), ("stock", "off"), ("3dgates", "on"),
                                                 ("3dgates", "off")))
        md.append(f"| {f} | {so.get('set', '')} | {so.get('firmware', '-')} ({so.get('read', so.get('error', ''))}) | "
                  f"{so.get('bed') or ''} | {_fmt(so.get('saving_pct'))} | {_fmt(sf.get('saving_pct'))} | "
                  f"{_fmt(so.get('rotation_deg'), 'g')} | {_fmt(so.get('added_time_pct'))} / "
                  f"{_fmt(sf.get('added_time_pct'))} | {_fmt(go.get('saving_pct'))} | {_fmt(gf.get('saving_pct'))} | "
                  f"{_fmt(go.get('rotation_deg'), 'g')} | {_fmt(so.get('solve_s'))} | {_fmt(so.get('wall_s'), '.1f')} |")
    failed = [r for r in rows if r["rc"] != 0 or not r.get("verified")]
    md += ["", f"Failed or unverified runs: {len(failed)}" + "".join(
        f"\n- {r['file']} {r['recipe']} rotation {r['rotate']}: {r['error']}" for r in failed)]
    return "\n".join(md) + "\n"


def short_rotation(line: str) -> str:
    """The rotation line of `gatesopt solve` in a table cell: the angle and why."""
    import re
    if m := re.match(r"none: (\S+) deg, the best of (\d+) candidate angles.*?, saves ([\d.]+ % \w+) than 0 deg", line):
        return f"0 deg: {m[1]} deg saves {m[3]} once rotated"
    if m := re.match(r"none: 0 deg is the best of (\d+) candidate angles", line):
        return f"0 deg: best of {m[1]} candidates"
    if m := re.match(r"(\S+) deg about .*?the best of (\d+) candidate angles", line):
        return f"{m[1]} deg: best of {m[2]} candidates"
    if "one at a time" in line:
        return "none (objects printed one at a time)"
    return line[:60]


def check_tables(rows: list[dict], cmd: str) -> str:
    ok = [r for r in rows if r["rc"] == 0 and r.get("verify_rc") == 0]
    md = ["## Done-when check of issue 37: `gatesopt solve IN -o OUT` with defaults on every real file", "",
          _env(cmd),
          f"Every file of ../shared/instances and ../fresh, `gatesopt solve IN -o OUT` with no option, then "
          f"`gatesopt verify IN OUT` as its own process: {len(ok)} of {len(rows)} solved and verified.", "",
          "| file | set | firmware (read from) | saving % | added time % | rotation | solve s | run s | "
          "verify |", "|---|---|---|---:|---:|---|---:|---:|---|"]
    for r in rows:
        if r["rc"] != 0:
            md.append(f"| {r['file']} | {r['set']} | FAILED (exit {r['rc']}) | | | {r['error']} | | "
                      f"{r['wall_s']:.1f} | |")
            continue
        md.append(f"| {r['file']} | {r['set']} | {r['firmware']} ({r['read']}) | {r['saving_pct']:.2f} | "
                  f"{r['added_time_pct']:.2f} | {short_rotation(r['rotation_line'])} | {r['solve_s']:.2f} | "
                  f"{r['wall_s']:.1f} | {'holds' if r.get('verify_rc') == 0 else r.get('verify_line', '')} |")
    runs = [r["wall_s"] for r in rows]
    md += ["", f"Wall time per `gatesopt solve` process (numba cache warm): median {statistics.median(runs):.1f} s, "
           f"max {max(runs):.1f} s, {sum(1 for t in runs if t > 10)} of {len(runs)} over 10 s (the machine's 2 "
           "cores shared with other work during the run)."]
    return "\n".join(md) + "\n"


NUMBERS = ("saving_pct", "added_time_pct", "rotation_deg", "solve_s", "run_s", "wall_s")


def read_rows(path: Path) -> list[dict]:
    """The rows of an earlier run's ``--out`` TSV, numbers as numbers (the kind from RECIPE_FILES)."""
    kinds = {stem: kind for stem, kind, _ in RECIPE_FILES}
    rows = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f, delimiter="\t"):
            row: dict = {}
            for k, v in r.items():
                if k in ("rc", "verify_rc"):
                    row[k] = int(v) if v != "" else None
                elif k == "verified":
                    row[k] = v == "True"
                elif k in ("bed",):
                    row[k] = v or None
                elif k in NUMBERS:
                    row[k] = float(v) if v != "" else None
                else:
                    row[k] = v
            row["kind"] = kinds.get(row["file"], row.get("kind"))
            rows.append(row)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", default=str(REPO.parent / "shared" / "instances"))
    ap.add_argument("--fresh", default=str(REPO.parent / "fresh"))
    ap.add_argument("--check", action="store_true", help="issue 37's done-when check instead of the recipes")
    ap.add_argument("--out", help="one row per run (TSV)")
    ap.add_argument("--write", metavar="MD", help="write the tables into this Markdown file")
    ap.add_argument("--tables-from", metavar="TSV", help="only write the tables of an earlier run's --out")
    ap.add_argument("--only", help="comma-separated file stems (a subset of the recipe files or of --check's)")
    a = ap.parse_args()
    shared, fresh = Path(a.shared), Path(a.fresh)
    only = set(a.only.split(",")) if a.only else None
    rows: list[dict] = [] if not a.tables_from else read_rows(Path(a.tables_from))
    with tempfile.TemporaryDirectory() as tmp:
        if a.tables_from:
            pass
        elif a.check:
            files = sorted(p for p in shared.iterdir() if p.name.endswith((".gcode", ".gcode.gz")))
            files += sorted(fresh.glob("*.gcode"))
            for path in files:
                stem = path.name.split(".gcode")[0]
                if only and stem not in only:
                    continue
                row = {"file": stem, "set": "fresh" if path.parent == fresh else "corpus",
                       **solve(path, [], Path(tmp), verify=True)}
                rows.append(row)
                print(stem, row["rc"], row.get("verify_rc"), _fmt(row.get("saving_pct")), f"{row['wall_s']:.1f}",
                      row.get("rotation_line", row["error"]), sep="\t", flush=True)
        else:
            for stem, kind, bed in RECIPE_FILES:
                if only and stem not in only:
                    continue
                path = find(stem, [shared, fresh])
                if path is None:
                    print(f"{stem}: not found, skipped", file=sys.stderr)
                    continue
                for recipe, extra in RECIPES.items():
                    if kind == KLIPPER_CARTESIAN and recipe != "stock":
                        continue        # the paper's firmware is not Klipper
                    for rotate in ("on", "off"):
                        opts = extra + (["--rotate", "none"] if rotate == "off" else
                                        (["--bed", bed] if bed else []))
                        if kind == KLIPPER_CARTESIAN:
                            opts += ["--printer-config", str(KLIPPER_CFG)]
                        row = {"file": stem, "kind": kind, "set": "fresh" if path.parent == fresh else "corpus",
                               "recipe": recipe, "rotate": rotate, "bed": bed if rotate == "on" else None,
                               **solve(path, opts, Path(tmp))}
                        rows.append(row)
                        print(stem, recipe, rotate, row["rc"], _fmt(row.get("saving_pct")),
                              _fmt(row.get("added_time_pct")), _fmt(row.get("rotation_deg"), "g"),
                              f"{row['wall_s']:.1f}", row["error"], sep="\t", flush=True)
    if a.out:
        keys = list(dict.fromkeys(k for r in rows for k in r))
        with open(a.out, "w", newline="") as f:
            w = csv.DictWriter(f, keys, delimiter="\t")
            w.writeheader()
            w.writerows(rows)
    cmd = "python bench/first_hour_recipes.py" + (" --check" if a.check else "") + (
        f" --write {os.path.relpath(Path(a.write).resolve(), REPO)}" if a.write else "")
    text = check_tables(rows, cmd) if a.check else recipe_tables(rows, cmd)
    print(text)
    if a.write:
        replace_section(Path(a.write), text)
    return 0 if all(r["rc"] == 0 and r.get("verified") and r.get("verify_rc", 0) == 0 for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
