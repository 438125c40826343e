"""`gatesopt profile --stream` against the whole-file profile: the planner's print time read chunk
by chunk (1 MB chunks here, 64 MB in use) against `gatesopt profile FILE --json` of the same file.

    python bench/stream_profile.py FILE [FILE ...]      (names in ../shared/instances)

Prints per file: whole-file time s, streamed time s, their difference %, energies J.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
INSTANCES = ROOT.parent / "shared" / "instances"
if not INSTANCES.exists():
    INSTANCES = Path("/work/shared/instances")


def main(names) -> None:
    from gatesopt.stream import profile_stream
    print("| file | whole s | streamed s | diff % | energy whole J | streamed J |")
    print("|---|---:|---:|---:|---:|---:|")
    for name in names:
        p = str(INSTANCES / name)
        whole = json.loads(subprocess.run([sys.executable, "-m", "gatesopt", "profile", p, "--json"],
                                          capture_output=True, text=True, check=True).stdout)
        r = profile_stream(p, chunk_bytes=1 << 20, time_model="planner", energy_time_model="paper")
        print(f"| {name} | {whole['time_s']:,.1f} | {r.time_s:,.1f} | "
              f"{100 * (r.time_s / whole['time_s'] - 1):+.2f} | {whole['energy_j']:,.0f} | "
              f"{r.energy_j:,.0f} |")


if __name__ == "__main__":
    main(sys.argv[1:])
