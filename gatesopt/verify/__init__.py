"""Independent verifier: re-parse an emitted file and prove it prints what the original printed.

DESIGN.md "Verification": every output, every test. The checks trust nothing the solver says; they
read the two Programs (``gatesopt.parse`` of the original and of the output) and:

1. ``geometry``: per layer, the extruded moves are the same after undoing the declared rotation
   (``; gatesopt: rotate_deg=`` header): a multiset of segments up to direction (so a re-ordered
   curve, printed either way, matches), matched within ``geometry_tol_mm``; arcs as arcs (end
   points + centre). On the output side, runs of continuous collinear pieces separated only by
   motor instruction lines (a split move) are joined back, taking from each piece the longest
   stretch that is a move of the original -- so an instruction inserted *between* two original
   moves never merges them. Moves shorter than ``SHORT_MM`` are below any printer's resolution
   and not reported.
2. ``extrusion``: net E per layer equal (relative ``e_rel_tol``).
3. ``commands``: for gating output every original line that is not a motion is still there,
   unchanged and in order (only motor instructions and the rotation header may be added); for
   re-ordered output the heater and tool commands (and fans other than the part-cooling fan)
   keep their order, and each layer extrudes as much filament at each part-fan duty as before
   (the re-ordering re-issues M106 / M107 where a curve needs it). A rotated output's slicer
   bounds lines (``;MINX:``, ``EXCLUDE_OBJECT_DEFINE`` outlines) are checked by ``bounds``: they
   must state the rotated print's bounds.
4. ``timing``: no motor steps while a motor instruction holds it off (on firmware that needs an
   explicit enable), each explicit enable comes at least ``start_ahead_s`` before the motor's next
   step, and no disable comes within ``end_late_s`` of the motor's last step (3DGates Sec. 4.4,
   instruction inertia and delay). Times are the paper's T = L/F (Eq. 2) without stalls: a stall
   only adds time between an instruction and the moves around it, so this is the strict reading.
4b. ``firmware`` (run before ``timing``): every motor enable/disable line the rewrite added (the
   original's own lines, a slicer's closing ``M84``, are not checked) is one the firmware carries
   out as gating means it: in its dialect (``Firmware.off_word`` / ``on_word``: no ``M18 X`` for
   Klipper, which turns every stepper off, no ``S0`` for stock firmware, which does not know it),
   on a motor it may gate (``allowed_motors``: RepRapFirmware's ``M18 X`` unhomes X) and keeping
   the axis homed (``homing_kept``), all read from ``gatesopt.firmware``.
4c. ``schedule`` (instead of ``timing``, for a firmware that times its own switches,
   ``Firmware.schedule``: klipper-gating): which added line switches which motor off when, derived
   from the lines with the firmware's protocol on the dialect's time model (``schedule.timeline_s``);
   a line the firmware would skip is a finding, and ``energy`` prices exactly those intervals.
5. ``energy``: energy and time of the output, recomputed from its text with the one energy model
   (``gatesopt.energy.step_energy_j``, stall times from ``gatesopt.firmware.stall_durations``),
   agree with what the solver claimed within ``claim_rel_tol``.
6. ``positions`` (gating output, not re-ordered): every move of the original -- travels, wipes,
   z-hops, start and end G-code too, not only the extruded segments ``geometry`` sees -- ends in
   the output where the original's move ends, either as written or under the declared rotation
   (start and end G-code stay put, the print turns), positions as the parser resolves them in
   both files; and a relative (G91) move that starts in the rotated frame ends in it: its XY
   delta is the rotated delta. (A relative wipe written as a travel to where the *unrotated*
   print ended lands on a point of the original and passes every other check.)

Findings carry the 1-based line number in the output file (or the original, said so).

A gated file of millions of lines is checked in bulk, with the same answers as a line-by-line
reading: lines are compared as bytes in a compiled walk (``gatesopt._text``), each distinct text of
a motor instruction is parsed once, a split move is joined back in one lookup when its whole run is
a move of the original, and a layer whose segments are exactly the original's, none repeated, is
matched without a k-d tree (``gatesopt._rowset``); everything else takes the general path.

The package, one module per check: ``geometry`` (1; with ``rotation``, the declared rotation read
back), ``extrusion`` (2), ``commands`` (3), ``timing`` (4), ``firmware`` (4b), ``energy`` (5),
``positions`` (6), ``ordering`` (the re-ordering's own checks: ``gatesopt.verify.ordering.check``);
``motor_lines`` tells the original's own motor lines from the ones the rewrite added; ``verify``
below runs them all. The header lines it reads are ``gatesopt.headers``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .. import firmware as fwmod
from ..headers import HEADER_LINES, ORDER_PREFIX, ROTATE_PREFIX
from ..program import Program
from .bounds import bounds_line_numbers, check_bounds
from .commands import CONTROL_COMMANDS, check_commands, fan_duty_s
from .energy import CLAIM_REL_TOL, check_claim, claimed_energy_time, energy_of
from .extrusion import E_REL_TOL, check_extrusion
from .finding import Finding
from .firmware import check_firmware, detect_firmware, firmware_problem
from .geometry import (GEOMETRY_TOL_MM, PARTITION_MAX_PIECES, SHORT_MM, check_geometry, order_changed,
                       segment_pair)
from .handoff import check_handoffs, check_scheduled_handoffs
from .motor_lines import without_added_motor_lines
from .ordering import SHARED_CHECKS, check_barriers, check_moves, check_objects
from .ordering import check as check_ordering
from .positions import check_positions
from .rotation import read_rotation, undone_tol
from .schedule import check_schedule, scheduled_lines, timeline_s
from .timing import TIME_TOL_S, check_timing

__all__ = ["verify", "VerifyReport", "Finding", "read_rotation", "energy_of", "check_geometry",
           "check_extrusion", "check_positions", "check_commands", "check_timing", "check_firmware",
           "check_ordering", "check_moves", "check_barriers", "check_objects", "SHARED_CHECKS",
           "check_bounds", "firmware_problem", "detect_firmware", "fan_duty_s",
           "GEOMETRY_TOL_MM", "SHORT_MM", "PARTITION_MAX_PIECES", "E_REL_TOL", "TIME_TOL_S",
           "CLAIM_REL_TOL", "CONTROL_COMMANDS", "ROTATE_PREFIX", "ORDER_PREFIX"]


@dataclass(frozen=True)
class VerifyReport:
    """What ``verify`` found: ``ok`` only without findings; energy and time of both files
    recomputed with the one model; ``checks``: the checks that ran, in order."""

    ok: bool
    findings: tuple
    energy_j: float                 # output, recomputed from its text (stalls included)
    time_s: float
    energy_before_j: float          # original, same model
    time_before_s: float
    stall_s: float
    lines_before: int
    lines_after: int
    bytes_before: int
    bytes_after: int
    rotate_deg: float
    center_mm: tuple
    reordered: bool
    firmware: str
    checks: tuple = field(default=())

    @property
    def saving_pct(self) -> float:
        return 100.0 * (1.0 - self.energy_j / self.energy_before_j) if self.energy_before_j else 0.0

    def to_dict(self) -> dict:
        return {"ok": self.ok, "findings": [str(f) for f in self.findings],
                "energy_j": self.energy_j, "time_s": self.time_s,
                "energy_before_j": self.energy_before_j, "time_before_s": self.time_before_s,
                "stall_s": self.stall_s, "lines_before": self.lines_before,
                "lines_after": self.lines_after, "bytes_before": self.bytes_before,
                "bytes_after": self.bytes_after, "rotate_deg": self.rotate_deg,
                "reordered": self.reordered, "firmware": self.firmware, "checks": list(self.checks)}


def _has_line(program: Program, prefix: str, within: int = HEADER_LINES) -> bool:
    return any(program.line_text(i).startswith(prefix) for i in range(min(program.n_lines, within)))


def verify(original: Program, output: Program, *, firmware="3dgates", start_ahead_s: float = 1.8e-3,
           end_late_s: float = 1.0e-3, claimed=None, profile="paper", reordered: bool | None = None,
           claim_rel_tol: float = CLAIM_REL_TOL, geometry_tol_mm: float = GEOMETRY_TOL_MM,
           time_tol_s: float = TIME_TOL_S, printer=None) -> VerifyReport:
    """Run every check of ``output`` against ``original``; ``ok`` only if all hold.

    ``claimed``: what the solver reported (a GatingSolution, a dict with ``energy_after_j`` /
    ``time_after_s``, or an (energy J, time s) pair); None skips that comparison.
    ``reordered``: output whose curves were re-ordered (None: detect it: a ``; gatesopt: order``
    header, or original lines that are not all kept in order); then only heater/tool commands
    (and other fans) must keep their order, the part-fan duty per layer its filament, and the
    ordering checks (``gatesopt.verify.ordering``) run too.
    ``printer``: the printer's Klipper config (``gatesopt.printer_config``) for a firmware that
    times its own switches (``Firmware.schedule``: the input shaper's window, the module's options).
    """
    fw = fwmod.get(firmware)
    segments = segment_pair(original, output, geometry_tol_mm)
    if reordered is None:
        # detect: a header says so, or the lines are not the original's plus insertions (then the
        # output can only be a re-ordering, and is checked as one)
        reordered = _has_line(output, ORDER_PREFIX) or order_changed(
            original, output, segments if geometry_tol_mm == GEOMETRY_TOL_MM else None)
    findings: list[Finding] = []
    checks = []
    deg, cx, cy = read_rotation(output, original)
    bare = without_added_motor_lines(output, original) if reordered else output
    # a re-ordering not rotated, without gating lines: the ordering's checks compare it move by move
    move_by_move = bool(reordered) and deg % 360.0 == 0.0 and bare.n_lines == output.n_lines
    findings += check_geometry(original, output, tol_mm=geometry_tol_mm, segments=segments)
    checks.append("geometry")
    findings += check_extrusion(original, output)
    checks.append("extrusion")
    if reordered:
        # moves in another order: ``geometry`` and the ordering checks compare them
        # (``rewrite.pipeline.run`` checks the positions of the gated re-ordered print itself)
        checks.append("positions(skipped: re-ordered)")
    else:
        findings += check_positions(original, output, tol_mm=geometry_tol_mm)
        checks.append("positions")
    exempt = ((), ())
    if deg % 360.0 != 0.0:
        # the slicer's bounds lines describe the rotated print: rewritten, checked on their own
        exempt = (bounds_line_numbers(original), bounds_line_numbers(output))
    # compared move by move, the part fan is checked per move (``check_moves``' fan), which implies
    # the per-layer filament by fan duty: one finding per fault, the stricter one
    findings += check_commands(original, output, reordered=reordered, exempt=exempt, fan_duty=not move_by_move)
    checks.append("commands")
    if deg % 360.0 != 0.0:
        findings += check_bounds(original, output, deg, (cx, cy))
        checks.append("bounds")
    # the firmware's own dialect first: timing read with the wrong firmware's rules means little
    findings += check_firmware(output, firmware=fw, original=original, printer=printer)
    checks.append("firmware")
    scheduled = dur_out = dur_orig = None
    if fw.schedule(printer, start_ahead_s=start_ahead_s, end_late_s=end_late_s) is not None:
        # the firmware's own options in the printer's config are what it switches with
        own = fw.gating_defaults(printer)
        start_ahead_s = own.get("start_ahead_s", start_ahead_s)
        end_late_s = own.get("end_late_s", end_late_s)
        # the firmware switches by itself: its protocol says which motor is off when, on the
        # dialect's time model
        dur_out, dur_orig = timeline_s(output, fw, printer), timeline_s(original, fw, printer)
        scheduled = scheduled_lines(output, firmware=fw, start_ahead_s=start_ahead_s, end_late_s=end_late_s,
                                    printer=printer, original=original, duration_s=dur_out)
        findings += check_schedule(output, scheduled)
        checks.append("timing(schedule)")
        findings += check_scheduled_handoffs(original, output, scheduled)
        checks.append("handoff(schedule)")
    else:
        findings += check_timing(output, firmware=fw, start_ahead_s=start_ahead_s, end_late_s=end_late_s,
                                 original=original, tol_s=time_tol_s)
        checks.append("timing")
        # the output's own motor lines (a firmware with a schedule switches by itself, between
        # them: the gating problem keeps its intervals clear of these lines)
        findings += check_handoffs(original, output)
        checks.append("handoff")
    if reordered:
        if move_by_move:
            # extrusion and commands ran above (``SHARED_CHECKS``): the ordering's own checks only
            findings += list(check_moves(original, output))
            checks.append("ordering")
        else:
            # rotated or gated: the ordering checks' move-by-move comparison fails on rotated
            # and on split moves, and ``geometry`` above has compared those already (un-rotated,
            # splits joined). What a move-free comparison can still see holds for any output:
            # no extrusion crossed a barrier (per-bin sums of E and path length, with the
            # gating lines taken out and a rotation's snap allowed per move)
            snap = undone_tol(geometry_tol_mm, deg) if deg % 360.0 else 0.0
            findings += list(check_barriers(original, bare, snap_tol_mm=snap))
            findings += list(check_objects(original, bare, snap_tol_mm=snap))
            checks.append("ordering(barriers, objects; moves: geometry)")
    e_after, t_after, stall = energy_of(output, firmware=fw, profile=profile, original=original,
                                        scheduled=scheduled, duration_s=dur_out, printer=printer)
    # the original's motor lines are all its own (a stall priced with the state they leave, as the
    # solver's ``energy_before_j`` does), not gating lines whose effect is undone
    e_before, t_before, _ = energy_of(original, firmware=fw, profile=profile, original=original,
                                      duration_s=dur_orig, printer=printer)
    cl = claimed_energy_time(claimed)
    if cl is not None:
        checks.append("energy")
        findings += check_claim(cl, e_after, t_after, rel_tol=claim_rel_tol)
    return VerifyReport(
        ok=not findings, findings=tuple(findings), energy_j=e_after, time_s=t_after,
        energy_before_j=e_before, time_before_s=t_before, stall_s=stall,
        lines_before=original.n_lines, lines_after=output.n_lines, bytes_before=len(original.data),
        bytes_after=len(output.data), rotate_deg=deg, center_mm=(cx, cy), reordered=bool(reordered),
        firmware=fw.name, checks=tuple(checks))
