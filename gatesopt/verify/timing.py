"""Check 4, ``timing``: motor instructions against the motor's steps around them (3DGates
Sec. 4.4: start-ahead and end-late); see ``gatesopt.verify``."""
from __future__ import annotations

import numpy as np

from .. import firmware as fwmod
from ..program import AXES, Kind, Program
from .finding import Finding
from .motor_lines import read_motor_rows

# The emitted text has finite resolution (split points 0.01 um, rotated points 0.1 um); 20 us is
# about 1 % of the 1.8 ms start-ahead and covers 0.1 um of rounding at 5 mm/s.
TIME_TOL_S = 2e-5


def check_timing(output: Program, *, firmware="3dgates", start_ahead_s: float = 1.8e-3,
                 end_late_s: float = 1.0e-3, original: Program | None = None,
                 tol_s: float = TIME_TOL_S, max_findings: int = 10) -> list[Finding]:
    fw = fwmod.get(firmware)
    dur = np.asarray(output.duration_s, float)
    t_end = np.cumsum(dur)
    t_start = t_end - dur
    steps = np.asarray(output.steps_motor(), bool)
    motor_rows = np.flatnonzero(output.kind == Kind.MOTOR)
    parsed, is_on, mask, own = read_motor_rows(output, motor_rows, original)
    explicit_on = fw.reenable == "exact"
    out: list[Finding] = []
    for m, letter in enumerate(AXES):
        sel = parsed & (mask >> m & 1).astype(bool)
        if not sel.any():
            continue
        ev_rows, on, orig = motor_rows[sel], is_on[sel], own[sel]
        step_rows = np.flatnonzero(steps[:, m])
        if explicit_on:
            # the first step whose last instruction before it is an inserted "off"
            k = np.searchsorted(ev_rows, step_rows, "right") - 1
            kk = np.maximum(k, 0)
            held = np.flatnonzero((k >= 0) & ~on[kk] & ~orig[kk])
            if len(held):
                sr, r = step_rows[held[0]], ev_rows[k[held[0]]]
                out.append(Finding("timing", int(output.line[sr]) + 1,
                                   f"motor {letter} steps while off (switched off at line {int(output.line[r]) + 1})"))
        if not len(step_rows):
            continue
        # each inserted instruction against the motor's steps around it; the state before an
        # instruction is the previous instruction's (on before the first)
        t = t_start[ev_rows]
        was_on = np.concatenate(([True], on[:-1]))
        j = np.searchsorted(step_rows, ev_rows)                 # first step at or after it
        nxt = step_rows[np.minimum(j, len(step_rows) - 1)]
        prv = step_rows[np.maximum(j - 1, 0)]
        lead = t_start[nxt] - t
        lag = t - t_end[prv]
        late_on = ~orig & on & ~was_on & (j < len(step_rows)) & (lead < start_ahead_s - tol_s)
        early_off = ~orig & ~on & (j >= 1) & (lag < end_late_s - tol_s)
        hits = np.flatnonzero(late_on | early_off)
        # at most max_findings in all; once reached, a motor still reports its first inserted
        # instruction if that one fails
        if len(out) >= max_findings:
            first = np.flatnonzero(~orig)[:1]
            hits = hits[:1] if len(first) and len(hits) and hits[0] == first[0] else hits[:0]
        else:
            hits = hits[:max_findings - len(out)]
        for h in hits:
            r = ev_rows[h]
            if on[h]:
                out.append(Finding("timing", int(output.line[r]) + 1,
                                   f"motor {letter} switched on only {lead[h] * 1e3:.3f} ms before its step "
                                   f"at line {int(output.line[nxt[h]]) + 1} (start-ahead {start_ahead_s * 1e3:g} ms)"))
            else:
                out.append(Finding("timing", int(output.line[r]) + 1,
                                   f"motor {letter} switched off {lag[h] * 1e3:.3f} ms after its step at "
                                   f"line {int(output.line[prv[h]]) + 1} (end-late {end_late_s * 1e3:g} ms)"))
    return out
