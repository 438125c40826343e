"""CPU time of the parser and of its numba kernel alone on the largest corpus files, for changes to
``gatesopt/_scan.py`` (best of N, ``time.thread_time``: on a shared machine CPU time varies less
than wall time). Compare two trees by running it under each::

    python bench/scan_timing.py --repeat 15                      # this checkout
    PYTHONPATH=/tmp/old python bench/scan_timing.py --repeat 15  # another (git archive REV gatesopt)

Each file is decompressed into memory and parsed once before timing (kernels load or compile).
"""
from __future__ import annotations

import argparse
import gzip
import importlib
import time
from pathlib import Path

import numpy as np

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "instances"
FILES = ("prusa25_xend_honey25_acp.gcode.gz", "prusa25_bunny_triangles15_lh01.gcode.gz",
         "cura413_bunny_cubic10_mk3.gcode.gz", "cura413_xend_zigzag100.gcode.gz")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--shared", type=Path, default=SHARED)
    a = ap.parse_args()
    parse_mod = importlib.import_module("gatesopt.parse")   # the module (gatesopt.parse is the function)
    scan_mod = importlib.import_module("gatesopt._scan")
    # the kernel's tables, where the tree has them (before they were globals of _scan)
    tables = (parse_mod.SCAN_TABLES,) if hasattr(parse_mod, "SCAN_TABLES") else ()
    print(f"{parse_mod.__file__}")
    for name in FILES:
        data = gzip.decompress((a.shared / name).read_bytes())
        parse_mod.parse(data)
        buf = np.frombuffer(data, np.uint8)
        starts = scan_mod.line_starts(buf)
        best_parse_s = best_scan_s = float("inf")
        for _ in range(a.repeat):
            t = time.thread_time()
            parse_mod.parse(data)
            best_parse_s = min(best_parse_s, time.thread_time() - t)
            state = scan_mod.initial_state(25.0, 25.0)
            t = time.thread_time()
            scan_mod.scan(buf, starts, False, 1.0, 1.0, 25.0, 1.0, 25.0, state, *tables)
            best_scan_s = min(best_scan_s, time.thread_time() - t)
        print(f"{name:42s} {len(data) / 1e6:6.2f} MB  parse {best_parse_s * 1e3:7.1f} ms  "
              f"scan {best_scan_s * 1e3:7.1f} ms")


if __name__ == "__main__":
    main()
