"""No motor off where the machine is handed over: a pause, a filament or tool change
(``firmware.handoff_lines``). During a pause the user may move the head by hand and a motor
without holding torque loses its position; on an IDEX or tool-changer printer a tool change moves
X. The gating problem never switches a motor off across such a line (``gating.problem``); these
checks read the output's own lines, independently of the solver: its motor lines
(``check_handoffs``), or, for a firmware that switches by itself (``klipper-gating``), the
intervals its protocol makes of the added lines (``check_scheduled_handoffs``)."""
from __future__ import annotations

import numpy as np

from ..firmware import handoff_lines
from ..program import AXES, Program
from .finding import Finding


def state_at_lines(program: Program, lines: np.ndarray) -> np.ndarray:
    """(len(lines), 4) bool: the motors on at each of ``lines``: as the last step before the line
    left them (the first step's state where none is before it; all on in a file without steps)."""
    if program.n_steps == 0:
        return np.ones((len(lines), 4), bool)
    before = np.searchsorted(program.line, lines) - 1
    return np.asarray(program.enabled, bool)[np.maximum(before, 0)]


def check_handoffs(original: Program, output: Program) -> list[Finding]:
    """A finding per hand-over line of ``output`` where a motor is off that the original had on
    at the same line (the k-th such line of each file: they keep their order, ``commands``)."""
    a, b = handoff_lines(original), handoff_lines(output)
    if len(a) != len(b) or not len(b):
        return []               # the commands check says what was lost or added
    off = state_at_lines(original, a) & ~state_at_lines(output, b)
    return _findings(output, b, off, "off at")


def _findings(output: Program, lines: np.ndarray, off: np.ndarray, how: str) -> list[Finding]:
    """A finding per hand-over line ``lines[k]`` with a motor off (``off[k]``)."""
    out = []
    for k in np.flatnonzero(off.any(axis=1)).tolist():
        motors = " ".join(AXES[m] for m in np.flatnonzero(off[k]).tolist())
        text = output.line_text(int(lines[k])).strip()[:40]
        out.append(Finding("handoff", int(lines[k]) + 1,
                           f"motor {motors} {how} {text!r}: a pause or a filament or tool change "
                           "with a motor off (the head may be moved by hand, a tool change moves "
                           "it)"))
    return out


def check_scheduled_handoffs(original: Program, output: Program, scheduled) -> list[Finding]:
    """As ``check_handoffs`` for a firmware that switches by itself: a finding per hand-over line
    of ``output`` inside a gated interval (``verify.schedule.ScheduledLine``: off from its line to
    the motor's next step, ``next_row``) of a motor the original had on at that line."""
    a, b = handoff_lines(original), handoff_lines(output)
    gated = [s for s in scheduled if s.gated]
    if len(a) != len(b) or not len(b) or not gated:
        return []
    on_before = state_at_lines(original, a)
    # the first step row after each hand-over line: the line lies inside an interval (r, q] of
    # step rows when r < row <= q
    row = np.searchsorted(np.asarray(output.line), b)
    off = np.zeros((len(b), 4), bool)
    for s in gated:
        off[:, s.motor] |= (row > s.row) & (row <= s.next_row)
    off &= on_before
    return _findings(output, b, off, "switched off by the firmware across")
