"""Curve-ordering emit and verify: speed against the parser, and the time guard's re-emit with
the memo.

On the ``--files`` largest instances of ../shared/instances (by line count): the greedy order
in free mode (deterministic, so every run emits the same text), then the best of ``--repeat``
runs of

- ``gatesopt.parse`` of the file (the peer: the same number of lines, read instead of written),
- ``ordering.emit`` of the whole re-ordered file,
- after putting back ``--put-back`` % of its re-ordered layers (``rewrite.order.keep_layers``, what the
  time guard does with layers that got slower): the emit again without the memo and with the
  memo the first emit filled (``emit(..., memo)``, as ``rewrite.order.emit_guarded`` does),
- ``verify.ordering.check`` of the re-ordered output against the original (what every ``order``
  and ``solve`` run ends with).

Both emits of the last step are checked to give the same text.

    python bench/ordering_emit.py
    python bench/ordering_emit.py --write      # replace "## Curve-ordering emit and verify" in docs/BENCHMARKS.md
"""
from __future__ import annotations

import argparse
import csv
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SHARED = ROOT.parent / "shared" / "instances"
SECTION = "## Curve-ordering emit and verify"

import gatesopt  # noqa: E402
from gatesopt.ordering import OrderingOptions, build, emit, solve  # noqa: E402
from gatesopt.rewrite.order import keep_layers  # noqa: E402
from gatesopt.verify.ordering import check  # noqa: E402


def best_of(fn, repeat: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def largest(n: int) -> list[Path]:
    with open(SHARED / "MANIFEST.tsv", newline="") as f:
        rows = list(csv.DictReader(f, delimiter="\t"))
    rows.sort(key=lambda r: -int(r["lines"]))
    return [SHARED / r["file"] for r in rows[:n]]


def measure(path: Path, repeat: int, put_back_pct: float) -> dict:
    t_parse, prog = best_of(lambda: gatesopt.parse(path), repeat)
    prob = build(prog, OrderingOptions(mode="free"))
    sol = solve(prob, "greedy")
    t_emit, text = best_of(lambda: emit(prog, prob, sol), repeat)
    out = gatesopt.parse(text)
    t_verify, findings = best_of(lambda: check(prog, out), repeat)
    assert not findings, findings
    lay_of = prob.curve_layer[sol.curve_order]
    moved = [L for L in np.unique(prob.curve_layer)
             if not np.array_equal(sol.curve_order[lay_of == L], np.flatnonzero(prob.curve_layer == L))]
    k = max(1, int(round(len(moved) * put_back_pct / 100.0)))
    back = keep_layers(prob, sol, np.asarray(moved, np.int64)[np.linspace(0, len(moved) - 1, k).astype(int)])
    t_fresh, fresh = best_of(lambda: emit(prog, prob, back), repeat)

    def with_memo():
        memo: dict = {}
        emit(prog, prob, sol, memo)                 # the guard's first emit fills it (not timed)
        t = time.perf_counter()
        out = emit(prog, prob, back, memo)
        return time.perf_counter() - t, out

    runs = [with_memo() for _ in range(repeat)]
    t_memo = min(r[0] for r in runs)
    return {"file": path.name, "lines": prog.n_lines, "parse_s": t_parse, "emit_s": t_emit,
            "layers_moved": len(moved), "put_back": k, "fresh_s": t_fresh, "memo_s": t_memo,
            "same": runs[0][1] == fresh, "verify_s": t_verify}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", type=int, default=4, help="how many of the largest instances")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--put-back", type=float, default=2.0, help="%% of re-ordered layers put back")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    if not SHARED.is_dir():
        sys.exit(f"bench/ordering_emit.py: {SHARED} not found")
    emit(*_warm())                                   # numba caches, imports
    rows = []
    for path in largest(args.files):
        r = measure(path, args.repeat, args.put_back)
        rows.append(r)
        print(f"{r['file']}: {r['lines']:,} lines, parse {r['parse_s']:.2f} s, emit {r['emit_s']:.2f} s "
              f"({r['emit_s'] / r['parse_s']:.1f}x parse); {r['put_back']} of {r['layers_moved']} layers "
              f"put back: emit {r['fresh_s']:.2f} s, with the memo {r['memo_s']:.2f} s, same text "
              f"{r['same']}; verify {r['verify_s']:.2f} s", flush=True)
    cmd = "python bench/ordering_emit.py" + (" " + " ".join(a for a in sys.argv[1:] if a != "--write")
                                             if len(sys.argv) > 1 else "")
    lines = [SECTION, "",
             f"Command: `{cmd.strip()}` ({platform.processor() or platform.machine()}, "
             f"{time.strftime('%Y-%m-%d')}, best of {args.repeat}; greedy order, free mode). The "
             "parse of the same file is the peer; the last two columns are the time guard's second "
             f"emit after putting back {args.put_back:g} % of the re-ordered layers, without and "
             "with the memo of the first emit (`ordering.emit(..., memo)`); both give the same text. "
             "Verify: `verify.ordering.check` of the re-ordered output against the original.",
             "", "| file | lines | parse s | emit s | emit / parse | emit k lines/s | layers put back "
             "| re-emit s | with memo s | memo speed-up | same text | verify s | verify / parse |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['file']} | {r['lines']:,} | {r['parse_s']:.2f} | {r['emit_s']:.2f} | "
                     f"{r['emit_s'] / r['parse_s']:.1f} | {r['lines'] / r['emit_s'] / 1e3:.0f} | "
                     f"{r['put_back']} of {r['layers_moved']} | {r['fresh_s']:.2f} | {r['memo_s']:.2f} | "
                     f"{r['fresh_s'] / r['memo_s']:.1f}x | {r['same']} | {r['verify_s']:.2f} | "
                     f"{r['verify_s'] / r['parse_s']:.1f} |")
    text = "\n".join(lines) + "\n"
    print()
    print(text)
    if args.write:
        from _markdown import replace_section
        replace_section(ROOT / "docs" / "BENCHMARKS.md", text)
    if not all(r["same"] for r in rows):
        sys.exit("bench/ordering_emit.py: the memo changed the text")


def _warm():
    """A two-curve file: loads the compiled kernels before anything is timed."""
    prog = gatesopt.parse("G90\nM83\n;LAYER:0\nG1 Z0.2 F600\nG1 X0 Y0 F3000\nG1 X1 Y0 E1\n"
                          "G0 X2 Y0\nG1 X3 Y0 E1\n")
    prob = build(prog, OrderingOptions(mode="free"))
    return prog, prob, solve(prob, "greedy")


if __name__ == "__main__":
    main()
