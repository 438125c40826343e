"""The work after the ordering's solve, made faster (issue 36: the solve gets the time), gives
what it gave before: the time guard's emitted text, states and planner durations byte for byte
(golden values made by the code before the change), the writer's cached line texts and E words,
the verifier's one-key sorts and the report's reused planner times."""
from __future__ import annotations

import hashlib
import re

import numpy as np
import pytest

import gatesopt
from gatesopt.ordering import OrderingOptions, build, solve
from gatesopt.ordering.writer import E_WORD, e_word_split, line_texts
from gatesopt.planner import plan, planned_durations_s
from gatesopt.rewrite.figures import figures
from gatesopt.rewrite.guard import emit_guarded, keep_layers, step_times_s
from gatesopt.verify.ordering import _layers_differing, _sorted_rows, unique_pairs
from conftest import SHARED_INSTANCES, needs_shared

#: (file, mode, stage) -> sha256 prefix of the guarded text, sha256 prefix of the per-layer
#: sources, the output's planned total (repr): made with main at abb2f1f (before this change) by
#: the same calls as ``_guarded``
GOLDEN = {
    ("prusa25_star_rect15_m82.gcode.gz", "safe", "one"): ("508a68b18421c4e4f15b", "88163244840e", "1405.6640489309104"),
    ("prusa25_star_rect15_m82.gcode.gz", "safe", "two"): ("508a68b18421c4e4f15b", "b9b382714f47", "1405.6640489309104"),
    # (free: made again when the file's last group got the file's end as its end, ``chain.end_of``:
    # greedy's last layer ends elsewhere, 1392.2626 s before, 14 ms longer now)
    # (texts made again on branch s9-orca, where a rebuilt travel gets the motion limits in force
    # at the slicer's travel, ``emitter``: PrusaSlicer's per-feature "M204 P1000" / "M204 P800",
    # "M204 S3000" / "M204 S4000" around a travel between features; sources and planned totals
    # unchanged: neither changes a travel's acceleration here (M204 P: T is the travel's; the
    # S values: above the config block's travel maximum, 1500, real_prusa240). Was
    # 852e3eda9de6b08e7259 free; d6a52ba8042313b87646 safe, 557ae6110a7bafe8e45f free below)
    # free re-made when loops PrusaSlicer clips short of their seam became one-way curves
    # (``ordering.candidates``: free mode had reversed them): was 00974aedd0c585531dce /
    # 1392.276829078052 here, 7ff76d3330b78d6f1d6e / 808.005272017447 on real_prusa240
    ("prusa25_star_rect15_m82.gcode.gz", "free", "one"): ("98dacbf9ea23ac6e32b5", "88163244840e", "1387.724217175126"),
    ("prusa25_star_rect15_m82.gcode.gz", "free", "two"): ("98dacbf9ea23ac6e32b5", "6856b736fdc3", "1387.724217175126"),
    # re-made on branch s8-det, where the greedy formulation solves groups of <= 12 curves by the
    # subset DP and runs the matching step on groups of <= 40 (``ordering.greedy_pass``): another
    # greedy answer on this file (was 4a9768fee491bfa0a50f / 816.6829637932368 safe,
    # b2c9397606c85e06b2bb / 812.1655626997027 free); the guard's code is unchanged
    # free re-made on branch s10-settle, where a path the chain DP took but that is not proven
    # where it prints is settled there by the subset DP (``ordering.settle``): greedy's answer
    # 16 ms shorter (was 491b3abdbbdadc5484bd / 812.1738508146342)
    # both re-made on branch family, where a file is planned by the rules of the firmware
    # ``solve`` reads from it (``limits.default_family``): this one's print_start macro makes it a
    # Klipper file, planned by Klipper's rules as ``solve`` always planned it (the sources are
    # the same; planned by Marlin's rules the texts and totals are still the ones before: was
    # ee91bcc783e5440a80a7 / 816.6122633040444 safe, 687da7e7cc17a7b7c57f / 812.1574899575054 free)
    ("real_prusa240_m486_arcwelder.gcode", "safe", "one"): ("1f54abb428d32ac3db2b", "9060d7baa74e", "811.133507337486"),
    ("real_prusa240_m486_arcwelder.gcode", "safe", "two"): ("1f54abb428d32ac3db2b", "bf00fe1f2910", "811.133507337486"),
    ("real_prusa240_m486_arcwelder.gcode", "free", "one"): ("4ff738138e767b52dbea", "9060d7baa74e", "808.2730251451784"),
    ("real_prusa240_m486_arcwelder.gcode", "free", "two"): ("4ff738138e767b52dbea", "ea0e63d9e25d", "808.2730251451784"),
}


def _guarded(name: str, mode: str):
    """The greedy order's guard (one stage), and a second stage: greedy against greedy with every
    third layer put back (deterministic: no time limit reaches them)."""
    prog = gatesopt.parse(SHARED_INSTANCES / name)
    prob = build(prog, OrderingOptions(mode=mode))
    g = solve(prob, "greedy")
    other = keep_layers(prob, g, np.arange(0, prog.n_layers, 3))
    return prog, {"one": emit_guarded(prog, prob, g, True),
                  "two": emit_guarded(prog, prob, other, True, greedy=g)}


@needs_shared
@pytest.mark.parametrize("name", sorted({k[0] for k in GOLDEN}))
@pytest.mark.parametrize("mode", ["safe", "free"])
def test_guarded_text_states_and_durations_as_before(name, mode):
    prog, runs = _guarded(name, mode)
    for stage, gd in runs.items():
        text_sha, source_sha, total = GOLDEN[(name, mode, stage)]
        assert hashlib.sha256(gd.text.encode("utf-8", "surrogateescape")).hexdigest()[:20] == text_sha
        assert hashlib.sha256(np.asarray(gd.source, np.int64).tobytes()).hexdigest()[:12] == source_sha
        assert len(gd.kept) == 0
        # the durations the guard hands the report are the planner's on both files, step by step
        before_s, after_s = gd.planned_s
        assert np.array_equal(before_s, step_times_s(prog))
        assert np.array_equal(after_s, step_times_s(gd.output))
        # the durations-only entry of the planner is the planner's own computation
        assert np.array_equal(plan(gd.output).duration_s, after_s)
        assert np.array_equal(planned_durations_s(prog), plan(prog).duration_s)
        assert repr(float(after_s.sum())) == total
        assert figures(prog, gd.output, planned_s=gd.planned_s) == figures(prog, gd.output)


@needs_shared
@pytest.mark.parametrize("name", ["real_prusa240_m486_arcwelder.gcode", "cura413_star_triangles20.gcode.gz"])
def test_line_texts_and_e_words_as_the_program_reads_them(name):
    prog = gatesopt.parse(SHARED_INSTANCES / name)
    texts = line_texts(prog)
    assert texts == [prog.line_text(i) for i in range(prog.n_lines)]
    for text in texts[::7]:
        code, sep, comment = text.partition(";")
        m = E_WORD.search(code)
        got = e_word_split(text)
        if m is None:
            assert got is None
        else:       # what copy_line wrote before: the code around the number, then the comment
            assert got[0] + "12.5" + got[1] == code[:m.start(2)] + "12.5" + code[m.end(2):] + sep + comment


def test_line_texts_of_a_file_that_is_not_ascii():
    prog = gatesopt.parse_text("; caf\u00e9 \u2014 M117 \u00e9t\u00e9\r\nG1 X1 E1 ; \u00b5\r\nG1 X2 E2\r\n".encode()
                               + b"; \xff raw\r\nG1 X3 E3")
    assert line_texts(prog) == [prog.line_text(i) for i in range(prog.n_lines)]


def _layers_differing_by_lexsort(layer_a, qa, layer_b, qb):
    """The check before: a lexicographic sort of all columns."""
    a = _sorted_rows(np.column_stack([layer_a, qa]))
    b = _sorted_rows(np.column_stack([layer_b, qb]))
    out = []
    for L in np.union1d(layer_a, layer_b).tolist():
        if not np.array_equal(a[a[:, 0] == L], b[b[:, 0] == L]):
            out.append(L)
    return out


@pytest.mark.parametrize("seed", range(30))
def test_layers_differing_matches_the_lexicographic_sort(seed):
    rng = np.random.default_rng(seed)
    n, cols = int(rng.integers(0, 300)), int(rng.integers(1, 13))
    qa = rng.integers(-3, 4, (n, cols))
    # layers from -1 (before the first marker) on, and now and then far apart
    la = rng.integers(-1, 6, n) * (1 if seed % 3 else 10_000_000)
    perm = rng.permutation(n)           # the same moves in another order...
    qb, lb = qa[perm].copy(), la[perm].copy()
    for _ in range(int(rng.integers(0, 4))):    # ...with a few moved, changed or dropped
        if not n:
            break
        j = int(rng.integers(0, n))
        what = rng.integers(0, 3)
        if what == 0:
            lb[j] = rng.integers(-1, 6) * (1 if seed % 3 else 10_000_000)
        elif what == 1:
            qb[j, rng.integers(0, cols)] += 1
        else:
            qb, lb = np.delete(qb, j, 0), np.delete(lb, j)
            n -= 1
    assert _layers_differing(la, qa, lb, qb).tolist() == _layers_differing_by_lexsort(la, qa, lb, qb)


@pytest.mark.parametrize("seed", range(20))
def test_unique_pairs_is_numpys_unique_of_rows(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 200))
    a = rng.integers(-2, 5, n).astype(np.int64)
    b = rng.integers(-10**15, 10**15, n).astype(np.int64) // rng.integers(1, 10**14)
    pair, inv = unique_pairs(a, b)
    want, want_inv = np.unique(np.column_stack([a, b]).reshape(n, 2), axis=0, return_inverse=True)
    assert np.array_equal(pair, want)
    assert np.array_equal(inv, np.ravel(want_inv))


def test_e_word_split_of_a_line_without_code():
    assert e_word_split("; E12 only a comment\n") is None
    assert e_word_split("G1 X1 E2.5 F300 ; E9\n") == ("G1 X1 E", " F300 ; E9\n")
    assert re.match(r"G1 X1 E7 F300", "".join(("G1 X1 E", "7", " F300 ; E9\n")))
