"""Check 3, ``commands``: the original's non-motion lines kept (gating), or its control commands
in order and the part fan's duty per layer's filament (re-ordering); see ``gatesopt.verify``."""
from __future__ import annotations

import numpy as np

from .. import _text
from .. import firmware as fwmod
from ..headers import ROTATE_PREFIX
from ..program import MOTION_KINDS, Program
from .finding import Finding

CONTROL_COMMANDS = (("M", 104), ("M", 109), ("M", 140), ("M", 190), ("M", 141), ("M", 191),
                    ("M", 106), ("M", 107),
                    # progress and display messages: a re-ordering moves them with curves, but
                    # their sequence must stay the slicer's (a printer showing 40 % after 42 %)
                    ("M", 73), ("M", 117))


def _non_motion_lines(program: Program) -> np.ndarray:
    motion_lines = program.line[np.isin(program.kind, MOTION_KINDS)]
    mask = np.ones(program.n_lines, bool)
    mask[motion_lines] = False
    return np.flatnonzero(mask)


def fan_duty_s(program: Program, rows: np.ndarray) -> np.ndarray:
    """The part-cooling fan duty at steps ``rows`` in M106 S units (0-255, rounded): the
    parser's modal ``fan``, as the fan checks compare it."""
    return np.round(program.fan[rows].astype(np.float64) * 255.0).astype(np.int64)


def _check_fan_duty(original: Program, output: Program, max_findings: int) -> list[Finding]:
    """Per layer, the filament extruded under each part-cooling fan duty is the same in both
    files (the parser's modal ``fan``; order-free, so it holds for re-ordered and gated output,
    whose moves may be split; ``gatesopt.verify.ordering.check_fan`` checks move by move)."""
    def table(p):
        rows = np.flatnonzero(p.extruding)
        de = p.end_mm[rows, 3] - p.start_mm[rows, 3]
        return p.layer[rows].astype(np.int64), fan_duty_s(p, rows), de, rows
    la, da, ea, _ = table(original)
    lb, db, eb, rb = table(output)
    key = np.concatenate([la * 1024 + da, lb * 1024 + db])
    key, inv = np.unique(key, return_inverse=True)
    sum_a = np.bincount(inv[:len(la)], ea, len(key))
    sum_b = np.bincount(inv[len(la):], eb, len(key))
    bad = np.flatnonzero(np.abs(sum_a - sum_b) > 1e-4 * np.maximum(np.abs(sum_a), np.abs(sum_b)) + 1e-4)
    out = []
    for k in bad[:max_findings].tolist():
        L, duty = divmod(int(key[k]), 1024)
        at = rb[(lb == L) & (db == duty)]
        line = int(output.line[at[0]]) + 1 if len(at) else None
        out.append(Finding("commands", line, f"layer {L}: {sum_b[k]:.5f} mm of filament extruded with the "
                                             f"part fan at S{duty}, {sum_a[k]:.5f} mm in the original"))
    return out


def check_commands(original: Program, output: Program, *, reordered: bool = False,
                   fan_duty: bool = True, max_findings: int = 5, exempt=((), ())) -> list[Finding]:
    """Control commands (heaters, tools, fans, ...) in the same order. ``reordered``: the part
    fan's lines may move and repeat; what counts is the filament each layer extrudes under each
    fan duty (``_check_fan_duty``), unless ``fan_duty`` is False (a caller that checks the fan
    move by move, ``gatesopt.verify.ordering.check``, would otherwise report one fault twice).
    ``exempt``: (original lines, output lines) a rotation rewrote and another check compares (the
    slicer's bounds lines, ``verify.bounds``)."""
    out: list[Finding] = []
    if reordered:
        def seq(p):
            m = np.zeros(p.n_lines, bool)
            for letter, num in CONTROL_COMMANDS:
                m |= p.is_command(letter, num)
            m |= p.line_letter == ord("T")
            # the part-cooling fan is state a re-ordering re-issues where a curve would see
            # another value: its lines may be more, and are checked by what each layer extrudes
            # under each fan duty (``_check_fan_duty``), not by their order
            m[p.part_fan_lines] = False
            idx = np.flatnonzero(m)
            return idx, [p.line_text(i).strip() for i in idx]
        if fan_duty:
            out += _check_fan_duty(original, output, max_findings)
        ia, ta = seq(original)
        ib, tb = seq(output)
        for k in range(max(len(ta), len(tb))):
            if k >= len(ta):
                out.append(Finding("commands", int(ib[k]) + 1, f"control command not in the original: {tb[k][:60]}"))
            elif k >= len(tb):
                out.append(Finding("commands", int(ia[k]) + 1, f"control command missing: {ta[k][:60]}", True))
            elif ta[k] != tb[k]:
                out.append(Finding("commands", int(ib[k]) + 1, f"control command {tb[k][:40]!r} where the "
                                                            f"original has {ta[k][:40]!r}"))
            if len(out) >= max_findings:
                break
        return out
    a = _non_motion_lines(original)
    b = _non_motion_lines(output)
    a = a[~np.isin(a, np.asarray(exempt[0], np.int64))]
    inverse, texts = _text.distinct_lines(output, b)
    inserted = np.array([fwmod.parse_motor_line(t) is not None or t.startswith(ROTATE_PREFIX)
                         for t in texts], bool)[inverse]
    inserted |= np.isin(b, np.asarray(exempt[1], np.int64))
    buf_a, buf_b = np.frombuffer(original.data, np.uint8), np.frombuffer(output.data, np.uint8)
    i = j = 0
    while i < len(a) and len(out) < max_findings:
        # equal lines and inserted motor instructions / rotation header, in bulk
        i, j = _text.walk_kept(buf_a, original.line_start, a, buf_b, output.line_start, b, inserted, i, j)
        if i >= len(a):
            break
        if j >= len(b):
            out.append(Finding("commands", int(a[i]) + 1,
                               f"line missing from the output: {original.line_text(int(a[i])).strip()[:60]}", True))
            i += 1
            continue
        # line b[j] is neither a[i] nor an insertion: deleted or changed: say which;
        # resynchronise on the next equal line
        ta = original.line_text(int(a[i]))
        tb = output.line_text(int(b[j]))
        nxt = next((jj for jj in range(j, min(j + 50, len(b))) if output.line_text(int(b[jj])) == ta), None)
        if nxt is not None:
            out.append(Finding("commands", int(b[j]) + 1, f"line added: {tb.strip()[:60]}"))
            j = nxt
        else:
            out.append(Finding("commands", int(a[i]) + 1,
                               f"line missing or changed in the output: {ta.strip()[:60]}", True))
            i += 1
    if not out:
        extra = j + np.flatnonzero(~inserted[j:])
        if len(extra):
            out.append(Finding("commands", int(b[extra[0]]) + 1,
                               f"line added: {output.line_text(int(b[extra[0]])).strip()[:60]}"))
    return out
