"""The curve-ordering emit of this checkout against another version's, byte for byte, on the same
solutions (the solve is wall-clock budgeted: two runs would order differently).

    python bench/emit_identity.py record DIR --code /tmp/main_export   # git archive main | tar -x -C /tmp/main_export
    python bench/emit_identity.py check DIR

``record`` runs, with the ``gatesopt`` of ``--code``, ``rewrite.order.reorder`` (the default
solve: greedy, the exact formulation, the time guard's stages and its repair pass; ``--budget``
seconds, one worker) on every file of ``--files`` (default: ../shared/instances) in each of
``--modes``, and records every emit the guard makes (the solution, which memo it shared, the
SHA-256 of the text), then three more: the final solution fresh, and through one memo the
slicer's order in every layer and in every other layer (``guard.keep_layers``). It pickles the
program, the problem and those solutions per file and mode into DIR. ``check`` emits each again
with this checkout's ``gatesopt`` (the guard's memos shared as they were) and counts the texts
that differ. Only the emit differs between the two runs: the problem and solutions are the
pickled ones.
"""
from __future__ import annotations

import argparse
import glob
import hashlib
import pickle
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "instances"


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8", "surrogateescape")).hexdigest()


def record(out: Path, files: list[Path], modes: list[str], budget_s: float) -> None:
    import numpy as np

    import gatesopt
    from gatesopt.ordering import OrderingOptions
    from gatesopt.ordering import emitter
    from gatesopt.rewrite import guard
    from gatesopt.rewrite.order import reorder
    print(f"emitting with {Path(gatesopt.__file__).parent}", flush=True)
    calls: list = []
    seen: dict = {}

    def recorded(program, problem, solution, memo=None):
        text = emitter.emit(program, problem, solution, memo)
        seen["problem"] = problem
        calls.append((solution, None if memo is None else id(memo), _sha(text)))
        return text
    guard.emit = recorded
    out.mkdir(parents=True, exist_ok=True)
    for path in files:
        for mode in modes:
            name = f"{path.name}.{mode}.pkl"
            if (out / name).exists():
                continue
            t = time.time()
            prog = gatesopt.parse(path)
            calls.clear()
            seen.clear()
            try:
                problem, _, guarded = reorder(prog, OrderingOptions(mode=mode), budget_s=budget_s,
                                              workers=1)
            except Exception as exc:     # (a file the ordering refuses: nothing to compare)
                print(f"{path.name} {mode}: not ordered ({type(exc).__name__}: {exc})", flush=True)
                continue
            guard_calls = list(calls)
            calls.clear()
            n_layers = int(problem.program_problem.curve_layer.max()) + 1 if len(
                problem.program_problem.curve_layer) else 0
            extra = [(guarded.solution, None)]
            memo_id = -1
            for layers in (np.arange(n_layers), np.arange(0, n_layers, 2)):
                extra.append((guard.keep_layers(problem, guarded.solution, layers), memo_id))
            memo: dict = {}
            for sol, m in extra:
                recorded(prog, problem, sol, memo if m is not None else None)
            extra_calls = [(s, None if m is None else -1, d) for (s, m), (_, _, d) in zip(extra, calls)]
            with open(out / name, "wb") as f:
                pickle.dump({"file": path.name, "mode": mode, "program": prog,
                             "problem": seen.get("problem", problem),
                             "calls": guard_calls + extra_calls}, f, protocol=pickle.HIGHEST_PROTOCOL)
            print(f"{path.name} {mode}: {len(guard_calls)} guard emits + {len(extra_calls)}, "
                  f"{time.time() - t:.1f} s", flush=True)


def check(out: Path) -> int:
    import gatesopt
    from gatesopt.ordering.emitter import emit
    print(f"emitting with {Path(gatesopt.__file__).parent}", flush=True)
    n_texts = n_diff = n_runs = 0
    for pkl in sorted(out.glob("*.pkl")):
        with open(pkl, "rb") as f:
            rec = pickle.load(f)
        memos: dict = {}
        diff = 0
        for sol, memo_id, digest in rec["calls"]:
            memo = None if memo_id is None else memos.setdefault(memo_id, {})
            text = emit(rec["program"], rec["problem"], sol, memo)
            diff += _sha(text) != digest
        n_runs += 1
        n_texts += len(rec["calls"])
        n_diff += diff
        print(f"{rec['file']} {rec['mode']}: {len(rec['calls'])} texts, "
              f"{'same' if not diff else f'{diff} DIFFER'}", flush=True)
    print(f"{n_runs} file x mode runs, {n_texts} texts, {n_diff} differ")
    return 1 if n_diff else 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("action", choices=("record", "check"))
    ap.add_argument("dir")
    ap.add_argument("--code", help="record: the checkout whose gatesopt emits (default: this one)")
    ap.add_argument("--files", default=str(SHARED / "*.gcode*"), help="a glob")
    ap.add_argument("--modes", default="safe,free")
    ap.add_argument("--budget", type=float, default=10.0, help="reorder's budget_s")
    args = ap.parse_args()
    sys.path.insert(0, str(Path(args.code).resolve() if args.code and args.action == "record"
                           else ROOT))
    if args.action == "record":
        files = [Path(p) for p in sorted(glob.glob(args.files))]
        record(Path(args.dir), files, args.modes.split(","), args.budget)
    else:
        sys.exit(check(Path(args.dir)))


if __name__ == "__main__":
    main()
