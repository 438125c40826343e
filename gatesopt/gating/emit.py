"""Emit gated G-code: the original Program plus motor switches (and a rotation) -> G-code text.

3DGates (Chen et al., ASPLOS'17) Section 4.4, Algorithm 1 lines 12-21: the re-compiler only
*inserts* S-series instructions and, to honour Start-Ahead and End-Late, splits an instruction
"X -> X1 + S Y on + X2" at the exact moment. This module does that for any firmware dialect
(``gatesopt.firmware``) and for an optional rotation of the model about a centre in the XY plane.

What the text looks like:

- every original line that is not rewritten is copied byte for byte, in order; with no switch and
  no rotation the output *is* the input;
- a switch at time t (paper time model, T = L/F, 3DGates Eq. 2, measured from the start of the
  program) that falls inside a G0/G1/G2/G3 step splits that step into pieces that meet at the
  exact point: collinear for lines, on the same circle for arcs, E proportional to the fraction
  of the step. The first piece keeps the line's other words (F ...) and its comment; later pieces
  inherit the modal feedrate. Pieces are written in the line's own modal state (G90/G91, M82/M83,
  G20, G92 offset). With relative values (G91, M83) the pieces' numbers add up *exactly*, in
  decimal text, to the original number; with absolute values the last piece keeps the original
  text;
- a switch inside a step that cannot be split (dwell, heat-up wait, homing) moves to the safe side
  (an "on" to the step's start, an "off" to its end) and is counted in ``EmitResult.moved``;
- a rotation rewrites every XY coordinate (and the arc centre offsets I/J, as vectors) of every
  motion line, counter-clockwise by ``rotation_deg`` about ``center`` in machine coordinates, and
  adds the line ``; gatesopt: rotate_deg=<deg> center_x=<x> center_y=<y>`` at the top. A move that
  is single-axis after rotation (other-axis change <= ``snap_mm``) gets exactly the previous text
  on the other axis, so the firmware does not step that motor; ``EmitResult.max_snap_mm`` is the
  largest such correction. A relative move (G91) that starts in the rotated print says where to go
  *from there*: its XY delta is rotated (no translation) and it stays in the rotated frame
  (``rotated_run_end``), and its delta is written from the position the text before it reached,
  so rounding does not add up over a run of relative moves. The slicer's statements of where
  the print lies (Cura's ``;MINX:`` ... ``;MAXY:``, ideaMaker's ``;Bounding Box:``, Klipper's
  ``EXCLUDE_OBJECT_DEFINE`` outlines, ``slicers.BOUNDS_FORMATS``) are rewritten for the rotated
  print (``header_bounds``).

Without rotation the text is written by a compiled pass over the lines (``emit_plain``,
``_emit_kernel``); the per-line ``emit_line.LineRewriter`` is the reference it must equal byte for
byte, and still writes the rotated output and any split move the kernel leaves to it (arcs, unusual
spelling). Where the lines go: ``placement``.

Files with line numbers and checksums (``N12 G1 ... *34``) are refused when anything must change:
inserting lines would mean renumbering every following line, and hosts resend by number.
"""
from __future__ import annotations

import re

import numpy as np

from .. import firmware as fwmod
from .. import slicers
from ..program import AXES, Kind, Program
from .emit_line import (DECIMALS_INCH, DECIMALS_MM, DECIMALS_SPLIT_INCH, DECIMALS_SPLIT_MM, SNAP_MM,
                        SPLITTABLE, EmitError, EmitResult, LineRewriter, fmt_number, rotate_xy)
from .emit_plain import render_plain
from .emit_rotated import write_rotated
from .placement import (SWITCH_EPS_S, Placed, PlacedArrays, Switch, place_switches, solution_arrays,
                        solution_placed, solution_snap)
from .timeline import whole_steps

from ..headers import ROTATE_HEADER  # noqa: F401  (re-exported: gating.emit.ROTATE_HEADER)
_XY_WORD = re.compile(r"[XYxy]\s*[-+.0-9]")
_LINE_NUMBER = re.compile(rb"(?m)^[ \t]*N\d+")

__all__ = ["render", "render_switches", "emit_result", "emit", "ROTATE_HEADER", "EmitError",
           "EmitResult", "Switch", "Placed", "PlacedArrays", "place_switches", "solution_placed",
           "solution_snap", "solution_arrays", "SWITCH_EPS_S", "SNAP_MM", "SPLITTABLE", "DECIMALS_MM",
           "DECIMALS_SPLIT_MM", "DECIMALS_INCH", "DECIMALS_SPLIT_INCH", "rotate_xy"]


def render(program: Program, placed, *, firmware="3dgates", rotation_deg: float = 0.0,
           center_mm=(0.0, 0.0), rotate_rows=None, snap=None) -> EmitResult:
    """Write ``program`` with instruction lines ``placed`` (``Placed``) and an optional rotation.

    ``rotate_rows``: (lo, hi): rows whose end point the rotation moves (default all);
    ``snap``: (n, 2) bool, X/Y of a row that must not step (written equal to the previous text);
    default under rotation: rows whose rotated X or Y change is at most ``SNAP_MM``.
    """
    program.check_rewritable()      # a split line keeps its other words on the first piece
    fw = fwmod.get(firmware)
    if isinstance(placed, PlacedArrays):
        fw.check_motors(placed.motors())
        n_placed = len(placed.time_s)
    else:
        placed = list(placed)
        fw.check_motors(sorted({m for pl in placed for m in pl.motors}, key=AXES.index))
        n_placed = len(placed)
    rotated = float(rotation_deg) % 360.0 != 0.0
    if not n_placed and not rotated:
        return EmitResult(program.to_gcode(), 0, 0, 0, 0, 0.0)
    if _LINE_NUMBER.search(program.data):
        raise EmitError(f"{program.source}: the file uses line numbers/checksums (N.. *..); inserting "
                        "lines would renumber every following line and break host resends: strip them first")
    n = program.n_steps
    if not rotated and (n < 2 or bool((program.line[1:] > program.line[:-1]).all())):
        arrays = placed if isinstance(placed, PlacedArrays) else PlacedArrays.from_placed(placed)
        return render_plain(program, fw, arrays, float(rotation_deg), center_mm)
    if isinstance(placed, PlacedArrays):
        placed = placed.to_placed()
    em = LineRewriter(program, rotation_deg, center_mm, rotate_rows, snap)
    if rotated:
        lo, hi = em.lo, em.hi
        o = program.offset_mm[lo:min(hi + 1, n), :2]
        if len(o) and (o != o[0]).any():
            raise EmitError(f"{program.source}: a G92 sets X/Y inside the part to rotate: cannot rotate")
        if snap is None:
            em.snap = _default_snap(em, program)
    before, cuts, moved, instr = _place_lines(program, fw, placed)
    rewrite = _rows_to_rewrite(program, em, cuts) if rotated else set(cuts)
    header = []
    bounds = {}
    if rotated:
        header.append(ROTATE_HEADER.format(deg=fmt_number(float(rotation_deg), 9),
                                           cx=fmt_number(float(center_mm[0]), 6),
                                           cy=fmt_number(float(center_mm[1]), 6)))
        bounds = header_bounds(program, float(rotation_deg), center_mm)
    written = None
    if rotated and not before and not cuts:     # the rotation alone: a compiled pass
        written = write_rotated(program, em, rewrite, header, bounds)
    if written is None:
        written = _write_lines(program, em, before, cuts, rewrite, header, bounds)
    out, added, splits = written
    return EmitResult("".join(out), added, instr, splits, moved, em.max_snap, float(rotation_deg),
                      (float(center_mm[0]), float(center_mm[1])), _notes(em, moved))


def _place_lines(program: Program, fw, placed):
    """(lines before each line index, cuts per row [(fraction, lines)], instructions moved out of
    an unsplittable step, instruction lines written) of the ``Placed`` groups, in time order."""
    n = program.n_steps
    before: dict[int, list[str]] = {}
    cuts: dict[int, list] = {}
    moved = instr = 0
    inside: dict[int, list[Placed]] = {}     # unsplittable row -> instructions that fall inside it
    whole = whole_steps(program.steps_motor(), program.kind, fw.split_moves)
    for pl in sorted(placed, key=lambda q: q.time_s):
        r = int(pl.row)
        if r < n and pl.fraction is not None and 0.0 < pl.fraction < 1.0 and whole[r]:
            inside.setdefault(r, []).append(pl)
            continue
        lines = fw.on_lines(pl.motors) if pl.on else fw.off_lines(pl.motors)
        if not lines:
            continue
        instr += len(lines)
        if r >= n:
            before.setdefault(int(program.line[n - 1]) + 1, []).extend(lines)
        elif pl.fraction is None or pl.fraction <= 0.0:
            before.setdefault(int(program.line[r]), []).extend(lines)
        elif pl.fraction >= 1.0:
            before.setdefault(int(program.line[r]) + 1, []).extend(lines)
        else:
            cuts.setdefault(r, []).append((float(pl.fraction), lines))
    for r, pls in inside.items():
        # A dwell, heat-up wait or homing cannot be split, nor is an extrude-only move
        # (``timeline.whole_steps``: Klipper plans each alone). Per motor only the last instruction
        # inside it matters: a final "on" goes before the step, a final "off" after it -- both on
        # the safe side of start-ahead / end-late (the motor is on for the whole step).
        last: dict[str, bool] = {}
        for pl in pls:
            for m in pl.motors:
                last[m] = pl.on
        moved += len(pls)
        on_m = tuple(m for m in AXES if last.get(m) is True)
        off_m = tuple(m for m in AXES if last.get(m) is False)
        for motors, on, at in ((on_m, True, int(program.line[r])), (off_m, False, int(program.line[r]) + 1)):
            lines = fw.on_lines(motors) if on else fw.off_lines(motors)
            if lines:
                instr += len(lines)
                before.setdefault(at, [])
                if on:
                    before[at].extend(lines)
                else:
                    before[at][:0] = lines     # right after the step, before anything placed there
    return before, cuts, moved, instr


def _rows_to_rewrite(program: Program, em: LineRewriter, cuts: dict) -> set:
    """Rows a rotated output rewrites: the split ones and every motion row the rotation moves."""
    n = program.n_steps
    rewrite = set(cuts)
    d = program.end_mm[:, :2] != program.start_mm[:, :2]
    xy = np.isin(program.kind, SPLITTABLE) & (d.any(axis=1) | (program.kind == Kind.ARC))
    rows = np.arange(n)
    in_range = (rows >= em.lo) & (rows <= em.hi)
    xy &= in_range
    rewrite |= set(np.flatnonzero(xy).tolist())
    # a move that names X or Y without changing them still names an absolute position
    # that the rotation moves
    for r in np.flatnonzero(in_range & ~xy & np.isin(program.kind, SPLITTABLE)):
        if _XY_WORD.search(program.line_text(int(program.line[r])).split(";", 1)[0]):
            rewrite.add(int(r))
    return rewrite


def header_bounds(program: Program, deg: float, center_mm) -> dict[int, str]:
    """{line: new text} of the slicer's bounds lines of ``program`` (``slicers.BOUNDS_FORMATS``)
    for the print rotated by ``deg`` about ``center_mm``: boxes become the box of the rotated
    extrusions (of the print's layers), outlines turn with it."""
    ext = np.flatnonzero(program.extruding & (program.layer >= 0))
    pts = np.concatenate((program.start_mm[ext, :2], program.end_mm[ext, :2]))
    return slicers.rotated_bounds(program.data, program.line_start,
                                  lambda p: rotate_xy(np.asarray(p, float), deg, center_mm), pts)


def _write_lines(program: Program, em: LineRewriter, before: dict, cuts: dict, rewrite: set,
                 header: list, replace: dict | None = None) -> tuple[list, int, int]:
    """(output text pieces, lines added, steps split): every line in order, the rows in
    ``rewrite`` through ``em.rewrite``, the lines in ``replace`` (line -> text) as given there,
    the others byte for byte."""
    replace = replace or {}
    n = program.n_steps
    nl = program.line_ending
    row_of_line = {int(program.line[r]): r for r in range(n)}
    out: list[str] = [h + nl for h in header]
    added = len(header)
    splits = 0
    for li in range(program.n_lines + 1):
        ins = before.get(li)
        if ins:
            out.extend(x + nl for x in ins)
            added += len(ins)
        if li == program.n_lines:
            break
        r = row_of_line.get(li)
        if r is None and li in replace:
            out.append(replace[li])
            continue
        if r is None or r not in rewrite:
            out.append(program.line_text(li))
            if r is not None:
                em.note_kept(r)
            continue
        cut = []
        for f, ls in sorted(cuts.get(r, []), key=lambda c: c[0]):
            if cut and f - cut[-1][0] <= 1e-12:      # several lines at one moment: one split
                cut[-1] = (cut[-1][0], cut[-1][1] + ls)
            else:
                cut.append((f, list(ls)))
        new = em.rewrite(r, cut)
        text = program.line_text(li)
        ending = text[len(text.rstrip("\r\n")):]
        out.extend(x + nl for x in new[:-1])
        out.append(new[-1] + ending)
        if cut:
            splits += 1
        added += len(new) - 1
    return out, added, splits


def _notes(em: LineRewriter, moved: int) -> tuple[str, ...]:
    notes = []
    if em.snap_missed:
        notes.append(f"{em.snap_missed} single-axis snaps could not be applied (no previous absolute text)")
    if em.snap_refused:
        notes.append(f"{em.snap_refused} single-axis snaps refused (earlier snaps had drifted the axis "
                     f"by more than {SNAP_MM * 1e3:g} um): those moves step both motors")
    if moved:
        notes.append(f"{moved} instruction(s) moved out of a dwell/wait/homing step or an extrude-only move "
                     "to its safe side")
    if em.placeholders:
        notes.append(f"{len(em.placeholders)} unexpanded placeholder axis word(s) (line "
                     f"{em.placeholders[0]}{', ...' if len(em.placeholders) > 1 else ''}) written as the "
                     f"number the firmware stays at (it ignores such a word)")
    return tuple(notes)


def _default_snap(em: LineRewriter, program: Program) -> np.ndarray:
    """(n, 2) bool: X/Y of line moves whose rotated change is at most ``SNAP_MM``."""
    n = program.n_steps
    rows = np.arange(n)
    s = program.start_mm[:, :2].astype(float).copy()
    e = program.end_mm[:, :2].astype(float).copy()
    srot = (rows > em.lo) & (rows <= em.hi) | ((rows == em.lo) & (em.lo == 0))
    erot = (rows >= em.lo) & (rows < em.hi)
    s[srot] = rotate_xy(s[srot], em.deg, em.center)
    e[erot] = rotate_xy(e[erot], em.deg, em.center)
    d = program.end_mm[:, :2] != program.start_mm[:, :2]
    xy = np.isin(program.kind, SPLITTABLE) & (program.kind != Kind.ARC) & d.any(axis=1)
    return (np.abs(e - s) <= SNAP_MM) & xy[:, None]


def render_switches(program: Program, switches, **kw) -> EmitResult:
    """``render`` for a list of ``Switch``es (time, motor, on)."""
    return render(program, place_switches(program, switches), **kw)


def emit_result(program: Program, solution, firmware=None) -> EmitResult:
    """Emit with the full report (lines added, splits, snaps). ``firmware`` defaults to the one
    the solution's options name.

    A solution at a rotation other than 0 is refused: its switch times were placed on the
    unrotated moves, and rotated moves snapped to one axis run a little longer or shorter, so a
    switch may land inside end-late or start-ahead of a rotated step ("motor Y steps while off").
    ``gatesopt.rewrite.run`` does the whole job: rotates, parses the rotated print and solves it
    again, then emits that."""
    fw = firmware or getattr(solution.problem.options, "firmware", "3dgates")
    prob = solution.problem
    rotated = float(solution.rotation_deg) % 360.0 != 0.0
    if rotated:
        raise EmitError(f"{program.source}: this solution rotates the print by {solution.rotation_deg:g} deg: "
                        "its switches were timed on the unrotated moves; use gatesopt.rewrite.run(program, "
                        "options), which rotates, solves the rotated print again and emits that (or build "
                        "with rotate='none')")
    return render(program, solution_arrays(solution), firmware=fw, rotation_deg=0.0,
                  rotate_rows=(prob.rotate_lo, prob.rotate_hi), snap=solution_snap(solution))


def emit(program: Program, solution, firmware="3dgates") -> str:
    """Gated G-code text for ``program`` under a ``GatingSolution``."""
    return emit_result(program, solution, firmware=firmware).text
