"""Is `gatesopt order --budget` reproducible? (issue 36: the same numbers from every command)

    python bench/order_repro.py FILE [FILE...] [--modes safe,free] [--formulations auto,greedy]
        [--runs 3] [--budget 10] [--workers 2] [--gatesopt "python -m gatesopt"]

Runs the CLI (`gatesopt order FILE --budget B --json`) RUNS times per file, mode and formulation,
one run at a time, and prints per run the print time after (planner model), the groups proven
optimal (plus block orders), the groups left out of time (slicer's order / greedy's path), the
wall seconds, whether the wall-clock safety net fired, and the output's sha256 (first 10 hex
digits): two runs with the same digest wrote the same bytes. ``--gatesopt``: the command to run
(another checkout: ``"env PYTHONPATH=/path python -m gatesopt"``).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("files", nargs="+")
    ap.add_argument("--modes", default="safe,free")
    ap.add_argument("--formulations", default="auto,greedy")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--budget", type=float, default=10.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--gatesopt", default=f"{sys.executable} -m gatesopt")
    args = ap.parse_args()
    cmd = shlex.split(args.gatesopt)
    print("| file | mode | formulation | run | print after s | proven | out of time (kept / greedy) "
          "| wall s | net fired | sha256 |")
    print("|---|---|---|---|---:|---:|---:|---:|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for path in args.files:
            for mode in args.modes.split(","):
                for form in args.formulations.split(","):
                    for run in range(args.runs):
                        out, rep = Path(tmp, "o.gcode"), Path(tmp, "r.json")
                        subprocess.run(cmd + ["order", path, "-o", str(out), "--force",
                                              "--budget", f"{args.budget:g}",
                                              "--order-mode", mode, "--formulation", form,
                                              "--workers", str(args.workers), "--json", str(rep)],
                                       check=True, stdout=subprocess.DEVNULL)
                        r = json.loads(rep.read_text())
                        digest = hashlib.sha256(out.read_bytes()).hexdigest()[:10]
                        proven = r["groups_optimal"] + r.get("block_orders_optimal", 0)
                        net = r.get("work_net_fired", "-")
                        print(f"| {os.path.basename(path)} | {mode} | {form} | {run + 1} | "
                              f"{r['print_time_after_s']:,.2f} | {proven} | "
                              f"{r['groups_out_of_time']} / {r['groups_out_of_time_greedy']} | "
                              f"{r['wall_s']:.2f} | {net} | {digest} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
