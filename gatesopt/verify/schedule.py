"""Checks 4 and 5 for a firmware that times its own switches (``firmware.Schedule``; the
``klipper-gating`` dialect and integrations/klipper/gatesopt_gating.py): which motor is off when,
derived from the output's lines with the firmware's protocol (integrations/klipper/README.md "The
protocol"), written here again from that text and not taken from ``gatesopt.gating``.

For each line the rewrite added (``GATESOPT_GATE STEPPERS=...``) and each motor S it names, in file
order, with ``lb`` the lower-bound time of each step (``planner.min_move_time_s``: Klipper's
``min_move_t`` is at least that) and times on the verifier's stall-free timeline (3DGates Eq. 2):

- the interval runs from the line to S's next step (``t_next``; none: the end of the print);
- skipped (``motor_off``) where S has not stepped before the line, or where the firmware switches
  S itself between the line and its next step (homing, the file's own motor lines it carries out),
  and (``repeated``) where an earlier line's interval of S is still open;
- rule A (``short``): ``sum(lb) line..t_next >= off_delay + on_lead + min_off_s``;
- rule B (``spacing``), after S's previous gated interval (its line at row r', ended at step q';
  no switch of the firmware's own since), by the number K of changes of one pin the firmware keeps
  queued (``Schedule.pin_queue_slots``; each change comes at least ``min_spacing_s`` after the
  change K back): K = 1, ``on_lead + sum(lb) q'..line + off_delay >= min_spacing_s``; K = 2,
  ``sum(lb) r'..line >= min_spacing_s`` (off after off) and ``sum(lb) q'..t_next >= min_spacing_s``
  (on after on; t_next the end of the print when S never steps again);
- ``off_delay = end_late + Schedule.off_delay_s[S]`` (``margins``: at most ``MAX_OFF_DELAY_S``),
  ``on_lead = start_ahead + Schedule.on_lead_s[S]``;
- S is off over ``[t_line + off_delay, t_next - on_lead]``.

``check_schedule`` reports every added line the firmware would skip (the solver counted it as
gated) and every added line that is not the firmware's; ``scheduled_energy`` prices the output with
these intervals, the firmware's own stalls as ``energy.energy_of`` does."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import firmware as fwmod
from ..energy import load_profile, step_power_w
from ..limits import machine_limits
from ..planner import min_move_time_s, plan
from ..program import AXES, Kind, Program
from .finding import Finding
from .motor_lines import read_motor_rows

#: the module's limit on the off delay (integrations/klipper/gatesopt_gating.py MAX_OFF_DELAY_S)
MAX_OFF_DELAY_S = 0.050
#: rules A and B compared with this much slack (s): sums of the same numbers in another order
RULE_TOL_S = 1e-9


@dataclass(frozen=True)
class ScheduledLine:
    """One (added line, motor) as the firmware carries it out."""

    row: int            # the line's step row in the output
    motor: int          # index into AXES
    gated: bool
    reason: str         # "" when gated, else the firmware's skip reason
    off_s: float        # stall-free times of the pin's off and on (nan when skipped;
    on_s: float         # on = the end of the print when the motor never steps again)
    next_row: int = -1  # the motor's next step row (n_steps: none); the pin is off in between


def _barriers(output: Program, rows, parsed, mask, own, fw) -> np.ndarray:
    """(n + 1, 4) cumulative count of steps where the firmware switches a motor itself: homing,
    and the file's own motor lines it carries out (``Firmware.reads``)."""
    hit = np.zeros((output.n_steps, 4), bool)
    hit[output.kind == Kind.HOME] = True
    for r, ok, mk, o in zip(rows.tolist(), parsed.tolist(), mask.tolist(), own.tolist()):
        if ok and o and fw.reads(output.line_text(int(output.line[r]))) is not None:
            for m in range(4):
                if mk >> m & 1:
                    hit[r, m] = True
    cum = np.zeros((output.n_steps + 1, 4), np.int64)
    cum[1:] = np.cumsum(hit, axis=0)
    return cum


def timeline_s(program: Program, firmware, printer=None) -> np.ndarray:
    """(n_steps,) step durations under the dialect's time model (``Firmware.time_model``): the
    paper's T = L/F, or ``planner.plan`` with the dialect's planner rules and the printer's limits
    (``limits.machine_limits``), as ``gating.problem.build`` prices it; written here again so that
    the verifier does not take the solver's timeline."""
    fw = fwmod.get(firmware)
    if fw.time_model != "planner":
        return np.asarray(program.duration_s, float)
    family = fw.planner.family if fw.planner is not None else None
    return np.asarray(plan(program, machine_limits(program, family=family, printer=printer)).duration_s, float)


def scheduled_lines(output: Program, *, firmware, start_ahead_s: float, end_late_s: float,
                    printer=None, original: Program | None = None, duration_s=None) -> list[ScheduledLine]:
    """Every (added line, motor) of ``output`` as the firmware's protocol carries it out (module
    docstring), in file order; empty for a firmware without a schedule. ``duration_s``: the step
    durations (default ``timeline_s``)."""
    fw = fwmod.get(firmware)
    sched = fw.schedule(printer, start_ahead_s=start_ahead_s, end_late_s=end_late_s)
    if sched is None:
        return []
    n = output.n_steps
    dur = timeline_s(output, fw, printer) if duration_s is None else np.asarray(duration_s, float)
    start = np.concatenate(([0.0], np.cumsum(dur)))
    lb = np.concatenate(([0.0], np.cumsum(min_move_time_s(output, sched.arc_segment_mm))))
    steps = np.asarray(output.steps_motor(), bool)
    rows = np.flatnonzero(output.kind == Kind.MOTOR)
    parsed, on, mask, own = read_motor_rows(output, rows, original)
    barrier = _barriers(output, rows, parsed, mask, own, fw)
    added = parsed & ~own & ~on
    out: list[ScheduledLine] = []
    for m in range(len(AXES)):
        sel = rows[added & (mask >> m & 1).astype(bool)]
        if not len(sel):
            continue
        step_rows = np.flatnonzero(steps[:, m])
        off_delay = end_late_s + sched.off_delay_s[m]
        on_lead = start_ahead_s + sched.on_lead_s[m]
        need_a = off_delay + on_lead + sched.min_off_s - RULE_TOL_S
        open_until = -1           # the next step of the last line's interval (-1: none open)
        anchor = None             # step that ended the last gated interval (rule B)
        anchor_line = None        # that interval's line (rule B with two queued changes)
        queued = sched.pin_queue_slots
        for r in sel.tolist():
            j = int(np.searchsorted(step_rows, r))
            q = int(step_rows[j]) if j < len(step_rows) else n
            if r < open_until:
                out.append(ScheduledLine(r, m, False, "repeated", np.nan, np.nan))
                continue
            open_until = q
            if j == 0 or barrier[q, m] != barrier[r, m]:
                out.append(ScheduledLine(r, m, False, "motor_off", np.nan, np.nan))
                continue
            if anchor is not None and barrier[r, m] != barrier[anchor, m]:
                anchor = None     # the firmware switched S itself since: no rule B
            reason = ""
            if off_delay > MAX_OFF_DELAY_S:
                reason = "margins"
            elif lb[q] - lb[r] < need_a:
                reason = "short"
            elif anchor is not None and _too_close(queued, sched.min_spacing_s - RULE_TOL_S, on_lead, off_delay,
                                                   lb[anchor_line], lb[anchor], lb[r], lb[q]):
                reason = "spacing"
            if reason:
                out.append(ScheduledLine(r, m, False, reason, np.nan, np.nan))
                continue
            anchor, anchor_line = q, r
            t_on = start[q] - on_lead if q < n else start[n]
            out.append(ScheduledLine(r, m, True, "", float(start[r] + off_delay), float(t_on), q))
    out.sort(key=lambda s: (s.row, s.motor))
    return out


def _too_close(queued: int, spacing_s: float, on_lead: float, off_delay: float, lb_line_prev: float,
               lb_next_prev: float, lb_line: float, lb_next: float) -> bool:
    """Rule B between the previous gated interval (line, next step) and this one: one change of the
    pin waits for the change ``queued`` back (the pin's queue) and then needs ``spacing_s`` of lead."""
    if queued == 1:       # the on before, then this off
        return on_lead + (lb_line - lb_next_prev) + off_delay < spacing_s
    # two queued: the off before this off, the on before this on (the same margins at both ends)
    return lb_line - lb_line_prev < spacing_s or lb_next - lb_next_prev < spacing_s


def check_schedule(output: Program, lines: list[ScheduledLine], *, max_findings: int = 10) -> list[Finding]:
    """Every added line carried out as written: each motor it names switched off by the firmware
    (``lines``: ``scheduled_lines``), none skipped."""
    out = []
    for s in lines:
        if not s.gated and len(out) < max_findings:
            out.append(Finding("timing", int(output.line[s.row]) + 1,
                               f"the firmware skips this line for motor {AXES[s.motor]} ({s.reason}): "
                               f"the motor stays on"))
    return out


def scheduled_energy(output: Program, lines: list[ScheduledLine], file_enable: np.ndarray, stall_s: np.ndarray,
                     *, profile="paper", duration_s=None) -> tuple[float, float]:
    """(energy J, time s) of ``output`` with the motors as the file has them (``file_enable``), each
    firmware stall (``stall_s``) priced so, and each gated interval of ``lines`` off: the timeline
    cut at every step boundary and every pin change, each piece priced at its step's power with the
    motors off that are off then (so the XY coupling of the energy model is counted as it is)."""
    coeffs = load_profile(profile).coefficients(output)
    dur = np.asarray(output.duration_s if duration_s is None else duration_s, float)
    base = step_power_w(coeffs, file_enable) * (dur + stall_s)
    gated = [s for s in lines if s.gated and s.on_s > s.off_s]
    if not gated:
        return float(base.sum()), float((dur + stall_s).sum())
    start = np.concatenate(([0.0], np.cumsum(dur)))
    cuts = np.unique(np.concatenate((start, [s.off_s for s in gated], [s.on_s for s in gated])))
    lo, hi = cuts[:-1], cuts[1:]
    keep = hi > lo
    lo, hi = lo[keep], hi[keep]
    mid = 0.5 * (lo + hi)
    step = np.clip(np.searchsorted(start, mid, "right") - 1, 0, output.n_steps - 1)
    en = file_enable[step].copy()
    for m in range(4):
        iv = sorted((s.off_s, s.on_s) for s in gated if s.motor == m)
        if not iv:
            continue
        a = np.array([x[0] for x in iv])
        b = np.array([x[1] for x in iv])
        k = np.searchsorted(a, mid, "right") - 1
        inside = (k >= 0) & (mid < b[np.maximum(k, 0)])
        en[inside, m] = False
    c = coeffs.take(step)
    saved = (step_power_w(c, file_enable[step]) - step_power_w(c, en)) * (hi - lo)
    return float(base.sum() - saved.sum()), float((dur + stall_s).sum())
