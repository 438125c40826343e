"""Check 6, ``positions`` (gating output): every move of the original ends where it did, as
written or under the declared rotation (see ``gatesopt.verify``)."""
from __future__ import annotations

import numpy as np
from numba import njit

from ..program import MOTION_KINDS, Kind, Program
from .finding import Finding
from .geometry import GEOMETRY_TOL_MM
from .motor_lines import only_motor_between
from .rotation import read_rotation, rotate_xy


@njit(cache=True)
def _match_positions(a_raw, a_rot, a_last, a_rel, a_home, b_end, b_run_end, tol, e_tol, out_k, out_flag,
                     out_allowed):
    """Walk the original's moves (ends ``a_raw``, rotated ``a_rot``: X Y Z E) against the output's
    (``b_end``) in order. Each original move is one block of output moves (a split move's pieces,
    joined by motor lines only) whose last move ends at the original's end, as written (flag 1)
    or rotated (flag 2); the last move of a run of the original (``a_last``: a non-motor line
    follows) ends the output's run too (``b_run_end[k]``: the last move of the output's run holding
    move k, found once for all, not per move: a file with no other line between its moves is one
    run). Within a run the block ends at the earliest
    output move that matches, which finds an alignment whenever there is one (matching a
    subsequence greedily). ``a_rel``: a relative XY move: from a start that is rotated only, its
    end must be rotated (allowed flags 2), unless homing (``a_home``) came between. Fills
    ``out_k`` (the output move taken, -1: none left), ``out_flag`` (0: no match) and
    ``out_allowed``."""
    n = a_raw.shape[0]
    m = b_end.shape[0]
    k = 0
    prev = 3
    for i in range(n):
        if a_home[i]:
            prev = 3        # homed since the last move: the head is at a machine position
        allowed = 2 if (a_rel[i] and prev == 2) else 3
        out_allowed[i] = allowed
        if k >= m:
            out_k[i] = -1
            out_flag[i] = 0
            prev = 3
            continue
        end = b_run_end[k]
        cand_hi = end if a_last[i] else end - 1     # a move inside a run ends before the run does
        first = end if a_last[i] else k
        found = -1
        flag = 0
        for kk in range(first, cand_hi + 1):
            f = 0
            d_raw = 0.0
            d_rot = 0.0
            for q in range(3):
                d_raw = max(d_raw, abs(b_end[kk, q] - a_raw[i, q]))
                d_rot = max(d_rot, abs(b_end[kk, q] - a_rot[i, q]))
            de = abs(b_end[kk, 3] - a_raw[i, 3])
            if de <= e_tol:
                if d_raw <= tol:
                    f |= 1
                if d_rot <= tol:
                    f |= 2
            f &= allowed
            if f:
                found = kk
                flag = f
                break
        if found < 0:
            # no match: report it, and go on as if the move were not split
            found = end if a_last[i] else k
        out_k[i] = found
        out_flag[i] = flag
        prev = flag if flag else 3
        k = found + 1
    return 0


def check_positions(original: Program, output: Program, *, tol_mm: float = GEOMETRY_TOL_MM,
                    e_tol_mm: float = 1e-5, max_findings: int = 10) -> list[Finding]:
    """Every move of the original ends in the output where the original's move ends, as written
    or rotated by the output's declared rotation (``; gatesopt: rotate_deg=``), and a relative XY
    move (G91) that starts in the rotated frame ends in it (its delta is the rotated delta, no
    translation). Positions are the parser's, in both files. For gating output (the original's
    moves in order, split moves' pieces joined by motor lines); a re-ordering is checked by
    ``geometry`` and ``gatesopt.verify.ordering``. ``tol_mm`` covers the single-axis snaps of a
    rotated output; E (the cumulative filament position) must agree within ``e_tol_mm``."""
    deg, cx, cy = read_rotation(output, original)
    ra = np.flatnonzero(np.isin(original.kind, MOTION_KINDS))
    rb = np.flatnonzero(np.isin(output.kind, MOTION_KINDS))
    if not len(ra):
        return []
    a_raw = np.ascontiguousarray(original.end_mm[ra], dtype=np.float64)
    a_rot = a_raw.copy()
    if deg % 360.0 != 0.0:
        a_rot[:, :2] = rotate_xy(a_raw[:, :2], deg, (cx, cy))
    a_last = np.ones(len(ra), bool)
    a_last[:-1] = ~only_motor_between(original, ra)
    b_last = np.ones(len(rb), bool)
    b_last[:-1] = ~only_motor_between(output, rb)
    ends = np.flatnonzero(b_last)
    b_run_end = ends[np.searchsorted(ends, np.arange(len(rb)))]     # b_last[-1] holds: never past it
    moves_xy = ((original.end_mm[ra, :2] != original.start_mm[ra, :2]).any(axis=1)
                | (original.kind[ra] == Kind.ARC))
    a_rel = np.asarray(original.relative_xyz[ra], bool) & moves_xy
    home_cum = np.cumsum(original.kind == Kind.HOME)
    a_home = np.diff(np.concatenate(([0], home_cum[ra]))) > 0    # a G28 since the move before
    b_end = np.ascontiguousarray(output.end_mm[rb], dtype=np.float64)
    out_k = np.empty(len(ra), np.int64)
    out_flag = np.zeros(len(ra), np.int64)
    out_allowed = np.zeros(len(ra), np.int64)
    _match_positions(a_raw, a_rot, a_last, a_rel, a_home, b_end, b_run_end, float(tol_mm), float(e_tol_mm),
                     out_k, out_flag, out_allowed)
    out: list[Finding] = []
    for i in np.flatnonzero(out_flag == 0)[:max_findings].tolist():
        oline = int(original.line[ra[i]]) + 1
        k = int(out_k[i])
        if k < 0:
            out.append(Finding("positions", oline, "move of the original has no counterpart in the output "
                                                   "(the output ends before it)", in_original=True))
            continue
        b, raw, rot = b_end[k], a_raw[i], a_rot[i]
        at = f"({b[0]:.4f}, {b[1]:.4f}, {b[2]:.4f})"
        if out_allowed[i] == 2:
            out.append(Finding("positions", int(output.line[rb[k]]) + 1,
                               f"relative move (G91, original line {oline}) from the rotated print ends at "
                               f"{at}, not at ({rot[0]:.4f}, {rot[1]:.4f}, {rot[2]:.4f}): its XY delta is "
                               f"not the original's delta rotated by {deg:g} deg"))
        else:
            where = (f"({raw[0]:.4f}, {raw[1]:.4f}, {raw[2]:.4f})" + (
                f", or rotated ({rot[0]:.4f}, {rot[1]:.4f}, {rot[2]:.4f})" if deg % 360.0 != 0.0 else ""))
            out.append(Finding("positions", int(output.line[rb[k]]) + 1,
                               f"move ends at {at} E{b[3]:.5f}; the original's move (line {oline}) ends at "
                               f"{where} E{raw[3]:.5f}"))
    return out
