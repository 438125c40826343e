"""Parse + profile throughput and peak memory on the largest files in ../shared/instances.

Side by side, in one run, on the same uncompressed files (the .gz ones are decompressed into a
temp dir first so every method reads the same bytes from the same page cache):

- ``gatesopt``: ``gatesopt.parse(path)`` then ``gatesopt.energy.profile(program)``;
- ``plain loop``: a per-line Python loop that only tracks X Y Z E (split at ';', split words,
  update four floats on G0-G3/G92 lines) -- the floor any Python parser should beat;
- ``gcodeparser``: the PyPI parser (``GcodeParser(text)``; optional extra ``bench``);
- ``wc -l``: the I/O limit (wall time of the ``wc`` process, process start included).

Each (method, file) runs in its own subprocess: imports and a warm-up first (numba's cached
kernels load there), then the resident-set high-water mark is reset (Linux ``clear_refs`` 5) and
the method runs ``--repeat`` times; time = best run, memory = peak RSS above the warmed-up
baseline. Issue #2 targets: >= 10x the plain loop, within 20x of ``wc -l``, peak < 10x file size.

    python bench/parse_profile.py                 # 4 largest files, prints a Markdown table
    python bench/parse_profile.py --files 2 --repeat 1
    python bench/parse_profile.py --write docs/BENCHMARKS.md   # replace "## Parse and profile"
"""
from __future__ import annotations

import argparse
import csv
import gc
import gzip
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from _markdown import replace_section  # bench/_markdown.py

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "instances"
WARMUP_FILE = ROOT / "instances" / "square_lines.gcode"
METHODS = ("gatesopt", "plain", "gcodeparser", "wc")
SECTION = "## Parse and profile"
MOTION = frozenset(("G0", "G1", "G2", "G3", "G00", "G01", "G02", "G03", "G92"))


# ------------------------------------------------------------------------------------------------
# the methods (each reads the file itself)
def plain_loop(path: str) -> tuple[float, float, float, float]:
    """The floor: track X Y Z E as written, nothing else (no modes, no G92 offsets, no arcs)."""
    x = y = z = e = 0.0
    with open(path, encoding="utf-8", errors="surrogateescape") as f:
        for line in f:
            words = line.split(";", 1)[0].split()
            if not words or words[0] not in MOTION:
                continue
            for w in words[1:]:
                a = w[0]
                try:
                    if a == "X":
                        x = float(w[1:])
                    elif a == "Y":
                        y = float(w[1:])
                    elif a == "Z":
                        z = float(w[1:])
                    elif a == "E":
                        e = float(w[1:])
                except ValueError:
                    pass
    return x, y, z, e


def run_gatesopt(path: str):
    import gatesopt
    from gatesopt import energy
    t0 = time.perf_counter()
    prog = gatesopt.parse(path)
    t1 = time.perf_counter()
    report = energy.profile(prog)
    t2 = time.perf_counter()
    return (prog, report), {"parse_s": t1 - t0, "profile_s": t2 - t1}


def run_gcodeparser(path: str):
    import warnings
    from gcodeparser import GcodeParser
    with open(path, encoding="utf-8", errors="surrogateescape") as f:
        text = f.read()
    with warnings.catch_warnings():   # 0.3 deprecates the class in favour of parse_gcode_lines
        warnings.simplefilter("ignore", DeprecationWarning)
        return GcodeParser(text), {}


# ------------------------------------------------------------------------------------------------
# worker: one method on one file, in a fresh process
def _status_kb(field: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    raise KeyError(field)


def worker(method: str, path: str, repeat: int) -> dict:
    fn = {"gatesopt": run_gatesopt, "plain": lambda p: (plain_loop(p), {}),
          "gcodeparser": run_gcodeparser}[method]
    fn(str(WARMUP_FILE))                      # imports, numba cache load, first-call costs
    gc.collect()
    base_kb = _status_kb("VmRSS")
    try:                                      # reset the high-water mark to the current RSS
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        peak_field = "VmHWM"
    except OSError:
        peak_field = None
    best, extra = float("inf"), {}
    for _ in range(repeat):
        result = None
        gc.collect()
        t0 = time.perf_counter()
        result, info = fn(path)
        dt = time.perf_counter() - t0
        if dt < best:
            best, extra = dt, info
        del result
    if peak_field:
        peak_kb = _status_kb(peak_field)
    else:                                     # no clear_refs: whole-process peak (overestimates)
        import resource
        peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {"seconds": best, "peak_added_bytes": max(peak_kb - base_kb, 0) * 1024,
            "peak_exact": peak_field is not None, **extra}


def breakdown(path: str, top: int = 8) -> dict:
    """Where gatesopt's time and memory go on one file (cProfile, and the Program's arrays).

    Time is cProfile's own time per function, so the regular-expression scans that a function
    drives (``finditer``) count as that function's time. Generic over the parser's internals.
    """
    import cProfile
    import dataclasses
    import pstats

    import numpy as np
    run_gatesopt(str(WARMUP_FILE))
    best = None
    for _ in range(3):                 # keep the least disturbed of three profiled runs
        prof = cProfile.Profile()
        prof.enable()
        (prog, report), _ = run_gatesopt(path)
        prof.disable()
        st = pstats.Stats(prof)
        total = sum(v[2] for v in st.stats.values())
        if best is None or total < best[0]:
            best = (total, st)
    total, st = best
    rows = sorted(((v[2], f"{Path(k[0]).name}:{k[2]}") for k, v in st.stats.items()), reverse=True)
    buffers: dict[int, tuple[list[str], int]] = {}   # fields sharing one buffer count it once
    for obj in (prog, report):
        for f in dataclasses.fields(obj):
            v = getattr(obj, f.name)
            if isinstance(v, np.ndarray):
                base = v
                while isinstance(base.base, np.ndarray):
                    base = base.base
                names, _ = buffers.setdefault(id(base), ([], base.nbytes))
                names.append(f"{type(obj).__name__}.{f.name}")
    arrays = [("+".join(names), nbytes) for names, nbytes in buffers.values()]
    return {"total_s": total, "top": [(name, t) for t, name in rows[:top]],
            "arrays": sorted(arrays, key=lambda kv: -kv[1]), "data_bytes": len(prog.data)}


def measure(method: str, path: Path, repeat: int) -> dict:
    if method == "wc":
        best = float("inf")
        for _ in range(max(repeat, 3)):
            t0 = time.perf_counter()
            subprocess.run(["wc", "-l", str(path)], check=True, stdout=subprocess.DEVNULL)
            best = min(best, time.perf_counter() - t0)
        return {"seconds": best}
    cmd = [sys.executable, __file__, "--worker", method, str(path), "--repeat", str(repeat)]
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1] if out.stderr.strip() else "failed"}
    return json.loads(out.stdout)


# ------------------------------------------------------------------------------------------------
def largest_files(shared: Path, n: int) -> list[tuple[str, int]]:
    """(file name, uncompressed bytes) of the n largest files, from MANIFEST.tsv."""
    with open(shared / "MANIFEST.tsv", newline="") as f:
        rows = [(r["file"], int(r["bytes"])) for r in csv.DictReader(f, delimiter="\t")]
    return sorted(rows, key=lambda r: -r[1])[:n]


def materialize(shared: Path, name: str, tmp: Path) -> Path:
    """The uncompressed file in ``tmp`` (decompressed or copied, so all reads are alike)."""
    dst = tmp / (name[:-3] if name.endswith(".gz") else name)
    if name.endswith(".gz"):
        with gzip.open(shared / name, "rb") as src, open(dst, "wb") as out:
            shutil.copyfileobj(src, out)
    else:
        shutil.copyfile(shared / name, dst)
    return dst


def fmt_rate(lines: int, seconds: float | None) -> str:
    if seconds is None:
        return "n/a"
    r = lines / seconds
    return f"{r / 1e6:.2f} M" if r >= 1e6 else f"{r / 1e3:.0f} k"


def run(args) -> str:
    files = largest_files(args.shared, args.files)
    load = os.getloadavg()[0]
    rows = []
    with tempfile.TemporaryDirectory(prefix="gatesopt-bench-") as td:
        for name, _ in files:
            path = materialize(args.shared, name, Path(td))
            data = path.read_bytes()                 # also warms the page cache for everyone
            n_lines = data.count(b"\n") + (0 if data.endswith(b"\n") else 1)
            res = {m: measure(m, path, args.repeat if m != "gcodeparser" else min(args.repeat, 2))
                   for m in METHODS}
            rows.append((path.name, len(data), n_lines, res))
            if not rows[1:]:
                res["breakdown"] = measure("breakdown", path, 1)
            print(f"# {path.name}: " + json.dumps(res), file=sys.stderr)

    def sec(r, m):
        return r[m].get("seconds")

    out = ["| file | MB | lines | gatesopt lines/s (parse + profile s) | plain loop lines/s | "
           "gcodeparser lines/s | wc -l lines/s | gatesopt / plain | wc / gatesopt | "
           "gatesopt / gcodeparser | gatesopt peak / file size |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, size, n, r in rows:
        g, p, gp, w = (sec(r, m) for m in METHODS)
        ours = r["gatesopt"]
        detail = f" ({ours['parse_s']:.2f} + {ours['profile_s']:.2f})" if "parse_s" in ours else ""
        ratio = lambda a, b: f"{a / b:.1f}x" if a and b else "n/a"
        peak = ours.get("peak_added_bytes")
        out.append(f"| {name} | {size / 1e6:.1f} | {n:,} | {fmt_rate(n, g)}{detail} | {fmt_rate(n, p)} | "
                   f"{fmt_rate(n, gp)} | {fmt_rate(n, w)} | {ratio(p, g)} | {ratio(g, w)} | "
                   f"{ratio(gp, g)} | {f'{peak / size:.1f}x' if peak is not None else 'n/a'} |")
    peaks = [f"{name}: plain {r['plain'].get('peak_added_bytes', 0) / 1e6:.0f} MB, gcodeparser "
             f"{r['gcodeparser'].get('peak_added_bytes', 0) / 1e6:.0f} MB, gatesopt "
             f"{r['gatesopt'].get('peak_added_bytes', 0) / 1e6:.0f} MB" for name, _, _, r in rows]
    errors = [f"{name} {m}: {r[m]['error']}" for name, _, _, r in rows for m in METHODS if "error" in r[m]]
    bd_name, bd_size, _, bd = rows[0][0], rows[0][1], None, rows[0][3].get("breakdown", {})
    where = []
    if "top" in bd:
        where = [f"Where the time goes on {bd_name} (cProfile own time, least disturbed of 3 runs, "
                 f"{bd['total_s']:.3f} s in all; a regex scan counts as the function that drives it): "
                 + ", ".join(f"`{n}` {100 * t / bd['total_s']:.0f}%" for n, t in bd["top"]) + ".", "",
                 f"Where the memory goes on {bd_name} (array bytes held by the Program and the "
                 f"EnergyReport, as multiples of the {bd_size / 1e6:.1f} MB file; the Program also "
                 f"keeps the file's bytes, 1.0x): "
                 + ", ".join(f"`{n}` {b / bd_size:.2f}x" for n, b in bd["arrays"][:10])
                 + f"; all arrays {sum(b for _, b in bd['arrays']) / bd_size:.1f}x.", ""]
    cpu = platform.processor() or platform.machine()
    verdict = []
    for label, vals, ok, target in (
            ("gatesopt / plain", [sec(r, "plain") / sec(r, "gatesopt") for *_, r in rows
                                  if sec(r, "plain") and sec(r, "gatesopt")], lambda v: v >= 10, ">= 10x"),
            ("wc / gatesopt", [sec(r, "gatesopt") / sec(r, "wc") for *_, r in rows
                               if sec(r, "wc") and sec(r, "gatesopt")], lambda v: v <= 20, "<= 20x"),
            ("peak / file size", [r["gatesopt"]["peak_added_bytes"] / size for _, size, _, r in rows
                                  if "peak_added_bytes" in r["gatesopt"]], lambda v: v < 10, "< 10x")):
        if vals:
            met = sum(ok(v) for v in vals)
            verdict.append(f"{label} {min(vals):.1f}x to {max(vals):.1f}x (target {target}: "
                           f"met on {met} of {len(vals)} files)")
    text = "\n".join([
        SECTION, "",
        "Command (from the repository root, with ../shared/instances beside it):", "",
        "```", f"python bench/parse_profile.py --files {args.files} --repeat {args.repeat}", "```", "",
        f"Machine: {os.cpu_count()} cores ({cpu}), Python {platform.python_version()}, "
        f"{time.strftime('%Y-%m-%d', time.gmtime())}, load average {load:.1f} when the run started "
        f"(other jobs share the cores: absolute rates are noisy, the ratios within a row less so). Best of {args.repeat} runs per method "
        "(gcodeparser: best of " f"{min(args.repeat, 2)}), each method in its own process after a "
        "warm-up; files decompressed to a temp dir first. `wc -l` is the wall time of the `wc` "
        "process including its start. Peak = resident-set high-water mark above the warmed-up "
        "process (Linux `clear_refs`), for gatesopt the Program (which keeps the file's bytes) and "
        "the EnergyReport together.", "",
        *out, "",
        "Peak memory added: " + "; ".join(peaks) + ".", "",
        *where,
        *(["Errors: " + "; ".join(errors), ""] if errors else []),
        "Against the targets of issue #2: " + "; ".join(verdict) + ".",
        "",
    ])
    return text


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", type=int, default=4, help="how many of the largest files (default 4)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per method, best kept (default 3)")
    ap.add_argument("--shared", type=Path, default=SHARED, help="the shared instances folder")
    ap.add_argument("--write", type=Path, metavar="MD", help="replace the section in this Markdown file")
    ap.add_argument("--worker", nargs=2, metavar=("METHOD", "PATH"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        method, path = args.worker
        print(json.dumps(breakdown(path) if method == "breakdown" else worker(method, path, args.repeat)))
        return 0
    if not (args.shared / "MANIFEST.tsv").exists():
        print(f"parse_profile: {args.shared} has no MANIFEST.tsv: the shared instances are needed",
              file=sys.stderr)
        return 2
    text = run(args)
    print(text)
    if args.write:
        replace_section(args.write, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
