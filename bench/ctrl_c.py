"""How soon `gatesopt solve` answers a Ctrl-C (issue 37: "within a second in every solver").

    python bench/ctrl_c.py --at S[,S...] FILE [SOLVE ARGS]

Starts `gatesopt solve FILE -o OUT --json J SOLVE ARGS` in a fresh process, sends it SIGINT ``S``
seconds after its start, and prints: the time from the signal to the process's exit, its exit
code, the status and `stopped` of its report, and the notes that say what stopped (a stop
request makes the running solver answer with its best, then the run emits and verifies: the
time after the signal includes that). A run that ended before the signal says so.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def one(path: str, at_s: float, extra: list[str]) -> dict:
    with tempfile.TemporaryDirectory(prefix="gatesopt-ctrlc-") as tmp:
        out, rj = Path(tmp) / "out.gcode", Path(tmp) / "r.json"
        t0 = time.perf_counter()
        p = subprocess.Popen([sys.executable, "-m", "gatesopt", "solve", path, "-o", str(out), "--json", str(rj)]
                             + extra, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            p.wait(timeout=at_s)
            return {"at_s": at_s, "ended_before_s": time.perf_counter() - t0, "rc": p.returncode}
        except subprocess.TimeoutExpired:
            pass
        sent = time.perf_counter()
        p.send_signal(signal.SIGINT)
        _, err = p.communicate()
        after = time.perf_counter() - sent
        row = {"at_s": at_s, "exit_after_signal_s": after, "rc": p.returncode, "load": os.getloadavg()[0]}
        if rj.exists():
            s = json.loads(rj.read_text())
            row.update(status=s.get("status"), stopped=s.get("stopped"), verified=s.get("verified"),
                       notes=[n for n in s.get("notes", []) if "stop" in n or "interrupt" in n],
                       times=s.get("times"))
        else:
            row["stderr"] = err.strip()[-300:]
        return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--at", required=True, metavar="S[,S...]", help="seconds after the start")
    ap.add_argument("file")
    a, extra = ap.parse_known_args()
    for at in (float(v) for v in a.at.split(",")):
        print(json.dumps(one(a.file, at, extra)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
