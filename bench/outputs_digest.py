"""Digests of gatesopt's outputs on the corpus, for refactors that must not change behaviour.

    python bench/outputs_digest.py record OUT.tsv [--shared ../shared/instances] [--files GLOB]
                                               [--commands GLOB]
    python bench/outputs_digest.py compare OLD.tsv NEW.tsv

``record`` runs a fixed set of deterministic command lines (no wall-clock limit decides anything:
``dp`` and single-threaded ``milp`` gating without limits, ``greedy`` curve ordering) on every
corpus file through the installed ``gatesopt`` command and writes one row per (file, command):
the exit code and the SHA-256 of the written G-code and of the JSON report with its timing keys
dropped. ``compare`` lists the rows that differ. A refactor is behaviour-preserving on the corpus
when ``compare`` lists none (issue 35: "byte-identical outputs on the corpus before and after").
"""
from __future__ import annotations

import argparse
import fnmatch
import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
GATESOPT = [sys.executable, "-m", "gatesopt"]

#: (name, arguments after the input file). Every one is deterministic: no time limit decides
#: what is written (dp; milp with one thread and no limit, on small files only; greedy ordering)
COMMANDS = (
    ("solve-dp-3dgates", ["solve", "--no-order", "--formulation", "dp", "--firmware", "3dgates"]),
    ("solve-dp-marlin-1pct", ["solve", "--no-order", "--formulation", "dp", "--firmware", "marlin",
                              "--max-added-time-pct", "1"]),
    ("solve-dp-klipper", ["solve", "--no-order", "--formulation", "dp", "--firmware", "klipper",
                          "--rotate", "none"]),
    ("solve-greedy-gating", ["solve", "--no-order", "--formulation", "greedy"]),
    ("order-greedy-safe", ["order", "--formulation", "greedy", "--workers", "1"]),
    ("order-greedy-free", ["order", "--formulation", "greedy", "--order-mode", "free",
                           "--workers", "1"]),
    ("profile-planner", ["profile", "--json", "--time-model", "planner"]),
)
#: milp only where HiGHS proves the optimum quickly without a limit; solve's ordering only where
#: it does not start its second process (it has no --workers option; with two processes where the
#: two halves of the chain meet depends on timing: the Cura bunny's rows changed between runs of
#: the same code)
SMALL_BYTES = 400_000
#: a budget no run reaches: with the default 10 s a loaded machine skips the ordering (the note
#: "curve ordering skipped: the 10 s budget ... leaves it no time", seen at a load of ~15: the row
#: then holds the slicer's order)
ORDERED = ("solve-ordered-greedy", ["solve", "--formulation", "dp", "--order-formulation", "greedy",
                                    "--rotate", "none", "--budget", "3600"])
MILP = ("solve-milp-3dgates", ["solve", "--no-order", "--formulation", "milp", "--threads", "1",
                               "--rotate", "none", "--time-limit", "600"])
#: report keys that measure time on this machine, not what was decided
TIMING_KEYS = {"wall_s", "solve_s", "build_s", "emit_s", "verify_s", "parse_s", "solve_budget_s",
               "exact_s", "elapsed_s", "seconds", "time_s_wall", "gating_solve_s", "ordering_solve_s",
               "budget_s",  # what is left of --budget when the ordering starts
               "times",     # the run's stages in wall seconds (read_s, gating_build_s, report_s, ...)
               "output"}   # the output's path: a temporary directory


def _strip(obj):
    if isinstance(obj, dict):
        return {k: _strip(v) for k, v in obj.items()
                if k not in TIMING_KEYS and not k.endswith("_wall_s") and not k.startswith("time_spent")}
    if isinstance(obj, list):
        return [_strip(v) for v in obj]
    return obj


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def _run(path: Path, name: str, args: list[str], tmp: Path) -> tuple[str, str, str]:
    out, rep = tmp / f"{name}.gcode", tmp / f"{name}.json"
    for f in (out, rep):
        f.unlink(missing_ok=True)
    if args[0] == "profile":
        cmd = GATESOPT + [args[0], str(path)] + args[1:]
    else:
        cmd = GATESOPT + [args[0], str(path), "-o", str(out), "--json", str(rep)] + args[1:]
    proc = subprocess.run(cmd, capture_output=True, cwd=REPO)
    if args[0] == "profile":
        text = proc.stdout
        try:
            text = json.dumps(_strip(json.loads(text)), sort_keys=True).encode()
        except ValueError:
            pass
        return str(proc.returncode), _digest(text), "-"
    g = _digest(out.read_bytes()) if out.exists() else "-"
    j = "-"
    if rep.exists():
        j = _digest(json.dumps(_strip(json.loads(rep.read_text())), sort_keys=True).encode())
    return str(proc.returncode), g, j


def record(out_tsv: Path, shared: Path, pattern: str, only: str = "*") -> int:
    files = sorted(p for p in shared.iterdir() if p.name.endswith((".gcode", ".gcode.gz"))
                   and fnmatch.fnmatch(p.name, pattern))
    rows = ["file\tcommand\trc\tgcode_sha\tjson_sha"]
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for path in files:
            commands = list(COMMANDS)
            if path.stat().st_size < SMALL_BYTES:
                commands += [ORDERED, MILP]
            for name, args in commands:
                if not fnmatch.fnmatch(name, only):
                    continue
                rc, g, j = _run(path, name, args, tmp)
                rows.append(f"{path.name}\t{name}\t{rc}\t{g}\t{j}")
                print(rows[-1], flush=True)
    out_tsv.write_text("\n".join(rows) + "\n")
    return 0


def compare(old: Path, new: Path) -> int:
    def load(p):
        lines = p.read_text().splitlines()[1:]
        return {tuple(l.split("\t")[:2]): l.split("\t")[2:] for l in lines}
    a, b = load(old), load(new)
    diff = [k for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
    for k in diff:
        print(f"{k[0]}\t{k[1]}\t{a.get(k)}\t->\t{b.get(k)}")
    print(f"{len(diff)} of {len(set(a) | set(b))} rows differ")
    return 1 if diff else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("out", type=Path)
    r.add_argument("--shared", type=Path, default=REPO.parent / "shared" / "instances")
    r.add_argument("--files", default="*")
    r.add_argument("--commands", default="*", help="only the command lines whose name matches")
    c = sub.add_parser("compare")
    c.add_argument("old", type=Path)
    c.add_argument("new", type=Path)
    a = ap.parse_args()
    if a.cmd == "record":
        return record(a.out, a.shared, a.files, a.commands)
    return compare(a.old, a.new)


if __name__ == "__main__":
    sys.exit(main())
