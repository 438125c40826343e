"""Which motor enable/disable lines of an output are the original's own and which the rewrite
added: what ``timing``, ``firmware`` and ``energy`` need to tell them apart."""
from __future__ import annotations

import numpy as np

from .. import _text
from .. import firmware as fwmod
from ..headers import HEADER_LINES, PREFIX
from ..parse import parse
from ..program import MOTION_KINDS, Kind, Program


def only_motor_between(program: Program, rows: np.ndarray) -> np.ndarray:
    """(len(rows) - 1,) bool: steps rows[k] and rows[k+1] are separated by motor instruction lines
    only (what gating inserts), so they may be pieces of one split move."""
    if len(rows) < 2:
        return np.zeros(0, bool)
    motor_cum = np.cumsum(program.kind == Kind.MOTOR)
    between_motor = motor_cum[rows[1:] - 1] - motor_cum[rows[:-1]]
    line_gap = program.line[rows[1:]] - program.line[rows[:-1]] - 1
    return (rows[1:] - rows[:-1] - 1 == between_motor) & (line_gap == between_motor)


def _anchors(program: Program) -> np.ndarray:
    """Lines a gating rewrite keeps one for one and in order: every line that is neither a motion
    (a split move gives several) nor a motor instruction (gating adds those), nor gatesopt's own
    header in the first ``HEADER_LINES`` lines (``; gatesopt: rotate_deg=``)."""
    mask = np.ones(program.n_lines, bool)
    mask[program.line[np.isin(program.kind, MOTION_KINDS) | (program.kind == Kind.MOTOR)]] = False
    for i in range(min(program.n_lines, HEADER_LINES)):
        if mask[i] and program.line_text(i).startswith(PREFIX):
            mask[i] = False
    return np.flatnonzero(mask)


def _step_starts(program: Program) -> np.ndarray:
    """(n + 1,) stall-free start time of each step, and the end of the print."""
    return np.concatenate(([0.0], np.cumsum(np.asarray(program.duration_s, float))))


def _places_by_anchor(program: Program, rows: np.ndarray, anchors: np.ndarray):
    """Where steps ``rows`` are: (stretch: the number of ``anchors`` lines before them, stall-free
    time since the end of the last of those, and inf: the time is always counted from there)."""
    line = np.asarray(program.line)
    start = _step_starts(program)
    seg = np.searchsorted(anchors, line[rows])
    t_anchor = np.concatenate(([0.0], start[np.searchsorted(line, anchors, "right")]))
    return seg, start[rows] - t_anchor[seg], np.full(len(rows), np.inf)


def _places_by_layer(program: Program, rows: np.ndarray):
    """Where steps ``rows`` are: (layer, stall-free time since the layer's first step, time to the
    end of its last step)."""
    start = _step_starts(program)
    layer = np.asarray(program.layer, np.int64)
    key = layer - layer.min() if len(layer) else layer
    first = np.full(int(key.max()) + 1 if len(key) else 0, len(layer), np.int64)
    last = np.full(len(first), -1, np.int64)
    np.minimum.at(first, key, np.arange(len(layer)))
    np.maximum.at(last, key, np.arange(len(layer)))
    k = key[rows]
    return layer[rows], start[rows] - start[first[k]], start[last[k] + 1] - start[rows]


def own_motor_rows(original: Program | None, output: Program, rows: np.ndarray) -> np.ndarray:
    """Per output step of ``rows`` (motor lines): True if it is one of the original's own motor
    lines (a start G-code ``M17``, a closing ``M84``), kept by the rewrite, False if the rewrite
    added it.

    By text alone the two cannot be told apart: Marlin gating writes ``M18 X``, and a file may have
    an ``M18 X`` of its own. So each own line is paired with an output line of the same text in the
    same place, nearest in stall-free time to where the original has it. Gating keeps every other
    non-motion line one for one and in order (``check_commands``; ``_anchors``), so the place is
    the stretch between two such lines and the time is counted from its start (a split keeps a
    stretch's time; a rotation only changes the travels into and out of the print). A re-ordered
    file keeps its layers: the place is the layer, the time counted from the nearer end of it."""
    own = np.zeros(len(rows), bool)
    if original is None or not len(rows):
        return own
    if output is original:
        return np.ones(len(rows), bool)
    orows = np.flatnonzero(original.kind == Kind.MOTOR)
    if not len(orows):
        return own
    oinv, otexts = _text.distinct_lines(original, original.line[orows])
    ids: dict[str, int] = {}
    ocode = np.array([ids.setdefault(t.strip(), len(ids)) for t in otexts], np.int64)[oinv]
    inv, texts = _text.distinct_lines(output, output.line[rows])
    code = np.array([ids.get(t.strip(), -1) for t in texts], np.int64)[inv]
    oanch, anch = _anchors(original), _anchors(output)
    if len(oanch) == len(anch):
        oplace, o_from, o_to = _places_by_anchor(original, orows, oanch)
        place, c_from, c_to = _places_by_anchor(output, rows, anch)
    else:
        oplace, o_from, o_to = _places_by_layer(original, orows)
        place, c_from, c_to = _places_by_layer(output, rows)
    lo_place = min(int(oplace.min()), int(place.min()))
    width = max(int(oplace.max()), int(place.max())) - lo_place + 1
    okey = ocode * width + (oplace - lo_place)
    cand = np.flatnonzero(code >= 0)
    key = code[cand] * width + (place[cand] - lo_place)
    order = np.argsort(key, kind="stable")               # by key, then in file order
    cand, key = cand[order], key[order]
    # a place with as many lines of a text as the original's: all of them are its own
    ukeys, ocount = np.unique(okey, return_counts=True)
    lo, hi = np.searchsorted(key, ukeys, "left"), np.searchsorted(key, ukeys, "right")
    same = (hi - lo) == ocount
    for a, b in zip(lo[same].tolist(), hi[same].tolist()):
        own[cand[a:b]] = True
    used = np.zeros(len(cand), bool)
    for i in np.flatnonzero(~np.isin(okey, ukeys[same])).tolist():
        a, b = int(np.searchsorted(key, okey[i], "left")), int(np.searchsorted(key, okey[i], "right"))
        if a >= b:
            continue                    # gone from the output: check_commands reports it
        c = cand[a:b]
        if o_from[i] <= o_to[i]:
            d = np.abs(c_from[c] - o_from[i])
        else:
            d = np.abs(c_to[c] - o_to[i])
        d[used[a:b]] = np.inf
        j = int(np.argmin(d))
        if not np.isfinite(d[j]):
            continue
        used[a + j] = True
        own[c[j]] = True
    return own


def read_motor_rows(program: Program, rows: np.ndarray, original: Program | None = None):
    """Per step of ``rows``: (a motor line, on, motor mask with bit m = AXES[m], the file's own
    line (``own_motor_rows``)); each distinct text is read once."""
    inverse, texts = _text.distinct_lines(program, program.line[rows])
    ok, on, mask = fwmod.parse_motor_lines(texts)
    return ok[inverse], on[inverse], mask[inverse], own_motor_rows(original, program, rows)


def added_motor_lines(original: Program | None, output: Program):
    """The motor enable/disable lines (``firmware.parse_motor_line``) of ``output`` that the rewrite
    added: (rows, per row the index of its stripped text in ``texts``, ``texts``). A line of the
    original's own (a slicer's closing ``M84``, end G-code's ``M18``) is not one, a copy the rewrite
    added of an original line is (``own_motor_rows``)."""
    rows = np.flatnonzero(output.kind == Kind.MOTOR)
    inverse, texts = _text.distinct_lines(output, output.line[rows])
    texts = [t.strip() for t in texts]
    motor = np.array([fwmod.parse_motor_line(t) is not None for t in texts], bool)
    if not len(rows) or not motor.any():
        return rows[:0], inverse[:0], texts
    keep = motor[inverse]
    rows, inverse = rows[keep], inverse[keep]
    own = own_motor_rows(original, output, rows)
    return rows[~own], inverse[~own], texts


def without_added_motor_lines(program: Program, original: Program) -> Program:
    """The program without the motor lines the rewrite added (``added_motor_lines``; the file's
    own, such as a start G-code's ``M17``, stay: they are barriers for a re-ordering), re-parsed:
    what the ordering checks see."""
    rows = added_motor_lines(original, program)[0]
    if not len(rows):
        return program
    drop = set(program.line[rows].tolist())
    text = "".join(program.line_text(i) for i in range(program.n_lines) if i not in drop)
    return parse(text, source=program.source)
