"""The rotated text of a whole file, no instruction in it (``gating.emit.render`` with a rotation
and nothing placed: the rotation is its own rewrite, ``rewrite.pipeline``): a compiled pass
(``_emit_kernel.render_rotated``) writes the lines slicers write in the plain form (``G1 X.. Y..
E.. F..``, absolute), and hands every other line it would have to rewrite (relative or arc moves,
inches, unusual spelling, a rounding tie) or whose texts it would have to read (an XY move kept as
written) to ``emit_line.LineRewriter``, the reference it must equal byte for byte, with the
rewriter's state (the last X/Y text written, its offset, the head's XY, the snap counts) passed
back and forth. Measured: the per-line rewriter took ~30 us of CPU per line (87 k rewritten lines
of a PrusaSlicer plate, 2.6 s); the pass takes a fraction of a microsecond.
"""
from __future__ import annotations

import math

import numpy as np

from ..program import Kind, Program
from .emit_line import SPLITTABLE, LineRewriter

#: longest X/Y text the compiled pass carries as the rewriter's state (longer: the reference)
TEXT_BYTES = 64


class _State:
    """The rewriter's state as the compiled pass holds it (arrays), and its exchange with a
    ``LineRewriter`` (``to_rewriter``, ``from_rewriter``)."""

    def __init__(self, em: LineRewriter):
        self.val = np.array(em.em_val, float)
        self.txt = np.zeros((2, TEXT_BYTES), np.uint8)
        self.len = np.full(2, -1, np.int64)
        self.off = np.array(em.em_off, float)
        self.stats = np.zeros(3)                # largest snap, snaps refused, snaps missed
        self.from_rewriter(em)

    def from_rewriter(self, em: LineRewriter) -> bool:
        self.val[:] = em.em_val
        self.off[:] = em.em_off
        for k, a in enumerate(("X", "Y")):
            t = em.em_text[a]
            if t is None:
                self.len[k] = -1
                continue
            raw = t.encode("utf-8", "surrogateescape")
            if len(raw) > TEXT_BYTES:
                return False
            self.txt[k, :len(raw)] = np.frombuffer(raw, np.uint8)
            self.len[k] = len(raw)
        self.stats[:] = (em.max_snap, em.snap_refused, em.snap_missed)
        return True

    def to_rewriter(self, em: LineRewriter) -> None:
        em.em_val = self.val.copy()
        em.em_off = [float(v) for v in self.off]
        for k, a in enumerate(("X", "Y")):
            em.em_text[a] = (None if self.len[k] < 0 else
                             self.txt[k, :self.len[k]].tobytes().decode("utf-8", "surrogateescape"))
        em.max_snap = float(self.stats[0])
        em.snap_refused = int(self.stats[1])
        em.snap_missed = int(self.stats[2])


def write_rotated(program: Program, em: LineRewriter, rewrite: set, header: list,
                  replace: dict | None = None):
    """``emit._write_lines`` for a rotation without instructions: (output text pieces, lines
    added, steps split = 0), the same bytes (module docstring); the lines of ``replace`` (line ->
    text: the slicer's bounds lines, ``emit.header_bounds``) as given there, the pass stopping
    before each."""
    replace = replace or {}
    stops = sorted(li for li in replace if li < program.n_lines)
    from . import _emit_kernel

    n = program.n_steps
    nl = program.line_ending
    rows = np.arange(n)
    row_of_line = np.full(program.n_lines, -1, np.int64)
    np.maximum.at(row_of_line, program.line[rows], rows)        # the last row of a line, as a dict
    flag = np.zeros(n, bool)
    if rewrite:
        flag[np.fromiter(rewrite, np.int64, len(rewrite))] = True
    splittable = np.isin(program.kind, SPLITTABLE)
    xy_moved = (program.end_mm[:, :2] != program.start_mm[:, :2]).any(axis=1)
    snap = em.snap if em.snap is not None else np.zeros((n, 2), bool)
    buf = np.frombuffer(program.data, np.uint8)
    ls = program.line_start
    # rewritten lines grow by at most the two rotated numbers (and a Y added beside an X)
    out = np.empty(len(program.data) + 64 * int(flag.sum()) + 1024, np.uint8)
    state = _State(em)
    pieces = [("".join(h + nl for h in header)).encode("utf-8", "surrogateescape")]
    p, li, k = 0, 0, 0
    args = (program.kind == Kind.ARC, np.asarray(program.relative_xyz, bool),
            np.asarray(program.relative_e, bool), np.asarray(program.inch, bool), xy_moved,
            em._start, em._end, np.asarray(program.end_mm, float), np.asarray(program.offset_mm, float),
            np.ascontiguousarray(snap, dtype=np.bool_), em.snap is not None)
    while True:
        while k < len(stops) and stops[k] < li:
            k += 1
        stop = stops[k] if k < len(stops) else program.n_lines
        # the pass ends at ``stop`` (a line of ``replace``) as at the file's end: its line table cut there
        p, li = _emit_kernel.render_rotated(buf, ls[:stop + 1], li, row_of_line, flag, splittable, *args,
                                            state.val, state.txt, state.len, state.off, state.stats, out, p)
        if li >= program.n_lines:
            break
        # a line the pass leaves to the reference, with the state it reached
        pieces.append(out[:p].tobytes())
        p = 0
        state.to_rewriter(em)
        r = int(row_of_line[li])
        text = program.line_text(li)
        if r < 0 and li in replace:
            pieces.append(replace[li].encode("utf-8", "surrogateescape"))
        elif r < 0 or not flag[r]:
            pieces.append(text.encode("utf-8", "surrogateescape"))
            if r >= 0:
                em.note_kept(r)
        else:
            new = em.rewrite(r, [])
            ending = text[len(text.rstrip("\r\n")):]
            pieces.append(("".join(x + nl for x in new[:-1]) + new[-1] + ending)
                          .encode("utf-8", "surrogateescape"))
        if not state.from_rewriter(em):
            return None         # a text too long for the pass: the reference writes the file
        li += 1
    pieces.append(out[:p].tobytes())
    state.to_rewriter(em)
    if math.isnan(em.max_snap):
        em.max_snap = 0.0
    return ["".join(x.decode("utf-8", "surrogateescape") for x in pieces)], len(header), 0
