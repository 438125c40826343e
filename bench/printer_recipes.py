"""The README's "for your printer" recipes, measured: `gatesopt solve IN -o OUT` as a user runs it,
per firmware, with rotation on and off, on the files made for that firmware (issue 37).

    python bench/printer_recipes.py [--shared ../shared/instances] [--fresh ../fresh]
                                    [--out rows.tsv] [--write docs/RESULTS.md] [--recipes marlin,klipper,3dgates]

Recipes (each run once with `--rotate auto` and once with `--rotate none`):

- marlin: `gatesopt solve IN -o OUT` on the files whose printer runs Marlin (``--firmware auto``
  reads it: Marlin-compatible flavors, no Klipper command, no Klipper printer model); the default
  1 % time budget;
- klipper: `gatesopt solve IN -o OUT` on the files made for Klipper (read the same way);
- 3dgates: `gatesopt solve IN -o OUT --firmware 3dgates` on every file (the paper's patched
  firmware can be flashed on any printer).

Cura files name no bed: they get `--bed WxD` of the printer definition they were sliced with
(`BEDS`, from the slicing commands in MANIFEST.tsv / fresh manifest.tsv), or none (no rotation).
Every run is a separate `gatesopt solve` process with `--json`; one process at a time.
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
#: the bed of the printer definition a Cura file was sliced with (Cura writes none into the file)
BEDS = {"cura413_bunny_cubic10_mk3": "250x210",            # prusa_i3_mk3.def.json
        "cura413_": "235x235",                             # creality_ender3.def.json (machine_width 235)
        "__cura_ender3": "235x235", "__cura_mk3": "250x210",
        "real_cura591": "300x300"}                         # ;TARGET_MACHINE.NAME:Creality K1 Max
#: the fresh slices measured (a few per printer: bench/fresh_slices.py, ../fresh)
FRESH = ("cube__cura_ender3", "pins__cura_ender3", "plate__cura_mk3", "holes__prusa_mk3s", "pins__prusa_mk3s",
         "plate__slic3r", "phonecase__prusa_klipper", "pins__prusa_klipper", "plate__prusa_klipper_complete")


def bed_of(name: str) -> str | None:
    for key, bed in BEDS.items():
        if key in name:
            return bed
    return None


def dialect_of(path: Path) -> str:
    from gatesopt.rewrite.printer import choose
    import gzip
    data = gzip.open(path).read() if path.name.endswith(".gz") else path.read_bytes()
    return choose(data).firmware or "none"


def solve(path: Path, extra: list[str], tmp: Path) -> dict:
    out, rj = tmp / "out.gcode", tmp / "r.json"
    cmd = [sys.executable, "-m", "gatesopt", "solve", str(path), "-o", str(out), "--json", str(rj), "--force",
           *extra]
    t = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t
    row = {"rc": r.returncode, "wall_s": wall, "error": r.stderr.strip().splitlines()[-1] if r.returncode else ""}
    if r.returncode == 0:
        d = json.loads(rj.read_text())
        row.update(saving_pct=d["saving_pct"], added_time_pct=d["added_time_pct"], rotation_deg=d["rotation_deg"],
                   verified=d["verified"], firmware=d["firmware"], status=d["status"])
    for p in (out, rj):
        if p.exists():
            p.unlink()
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", default=str(REPO.parent / "shared" / "instances"))
    ap.add_argument("--fresh", default=str(REPO.parent / "fresh"))
    ap.add_argument("--out", default="printer_recipes.tsv", help="one row per run (TSV)")
    ap.add_argument("--write", metavar="MD", help="write the tables into this Markdown file")
    ap.add_argument("--recipes", default="marlin,klipper,3dgates")
    a = ap.parse_args()
    files = sorted(p for p in Path(a.shared).iterdir() if p.name.endswith((".gcode", ".gcode.gz")))
    files += [Path(a.fresh) / f"{n}.gcode" for n in FRESH if (Path(a.fresh) / f"{n}.gcode").exists()]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for path in files:
            name = path.name.split(".gcode")[0]
            dialect = dialect_of(path)
            bed = bed_of(name)
            for recipe in a.recipes.split(","):
                if recipe in ("marlin", "klipper") and dialect != recipe:
                    continue
                for rotate in ("auto", "none"):
                    extra = ["--rotate", rotate] + (["--firmware", "3dgates"] if recipe == "3dgates" else [])
                    if bed and rotate == "auto":
                        extra += ["--bed", bed]
                    row = {"file": path.name, "set": "fresh" if path.parent == Path(a.fresh) else "corpus",
                           "recipe": recipe, "rotate": rotate, "bed": bed or "", **solve(path, extra, Path(tmp))}
                    rows.append(row)
                    print("\t".join(str(row.get(k, "")) for k in ("file", "recipe", "rotate", "rc", "saving_pct",
                                                                   "added_time_pct", "rotation_deg", "wall_s")),
                          flush=True)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(a.out, "w", newline="") as f:
        w = csv.DictWriter(f, keys, delimiter="\t")
        w.writeheader()
        w.writerows(rows)
    text = tables(rows, a)
    print(text)
    if a.write:
        replace_section(Path(a.write), text)
    return 0 if all(r["rc"] == 0 and r.get("verified") for r in rows) else 1


def _stats(vals) -> str:
    if not vals:
        return "-"
    return f"{statistics.mean(vals):.1f} / {statistics.median(vals):.1f} / {max(vals):.1f}"


def tables(rows, a) -> str:
    md = ["## For your printer: what each recipe saves (issue 37)", "",
          f"Command: `python bench/printer_recipes.py --write docs/RESULTS.md` ({platform.machine()}, "
          f"{os.cpu_count()} cores shared with other work, Python {platform.python_version()}, "
          f"{time.strftime('%Y-%m-%d')}): every run a `gatesopt solve IN -o OUT --json R` process with the "
          "defaults (curve ordering with its 10 s budget, `dp`), one at a time; Cura files get `--bed` of "
          "the printer definition they were sliced with where the manifest names it.", "",
          "| recipe | files | rotation | saving % mean / median / max | added time % mean / max | rotated files | verified |",
          "|---|---:|---|---:|---:|---:|---:|"]
    for recipe in a.recipes.split(","):
        for rotate in ("auto", "none"):
            sel = [r for r in rows if r["recipe"] == recipe and r["rotate"] == rotate]
            if not sel:
                continue
            ok = [r for r in sel if r["rc"] == 0]
            sav = [r["saving_pct"] for r in ok]
            add = [r["added_time_pct"] for r in ok]
            rot = sum(1 for r in ok if r["rotation_deg"])
            md.append(f"| {recipe} | {len(sel)} | {'on (auto)' if rotate == 'auto' else 'off'} | {_stats(sav)} | "
                      f"{statistics.mean(add) if add else 0:.2f} / {max(add) if add else 0:.2f} | {rot} | "
                      f"{sum(1 for r in ok if r['verified'])}/{len(sel)} |")
    md += ["", "Per file (saving %, rotation on / off; the angle chosen):", "",
           "| file | recipe | saving on | saving off | deg | added time % on |", "|---|---|---:|---:|---:|---:|"]
    for recipe in a.recipes.split(","):
        for f in dict.fromkeys(r["file"] for r in rows if r["recipe"] == recipe):
            on = next((r for r in rows if r["file"] == f and r["recipe"] == recipe and r["rotate"] == "auto"), {})
            off = next((r for r in rows if r["file"] == f and r["recipe"] == recipe and r["rotate"] == "none"), {})
            md.append(f"| {f} | {recipe} | {on.get('saving_pct', float('nan')):.2f} | "
                      f"{off.get('saving_pct', float('nan')):.2f} | {on.get('rotation_deg', 0):g} | "
                      f"{on.get('added_time_pct', float('nan')):.2f} |")
    return "\n".join(md) + "\n"


if __name__ == "__main__":
    sys.exit(main())
