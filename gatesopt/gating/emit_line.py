"""Writing motion lines: the per-line rewriter of the emitter (rotation, splits, single-axis
snaps) and the vocabulary the emitter's modules share (decimals, ``EmitError``, ``EmitResult``).

``LineRewriter`` writes every rotated output and every split move the compiled pass
(``emit_plain``) leaves to it; it is also the reference that pass must equal byte for byte. The
rules the text follows are in ``gating.emit``'s docstring.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from decimal import Decimal

import numpy as np

from ..errors import GatesoptError
from ..firmware.klipper import arc_turn as klipper_arc_turn
from ..program import AXES, Kind, Program
from .rotation import rotated_run_end


# Decimals written (mm). Rotated end points: 0.1 um (slicers write 1 um; a rotation makes every
# coordinate irrational, and 0.1 um keeps the time of each move within 20 us of the solver's at
# >= 5 mm/s, which the verifier's start-ahead check needs). Split points: 0.01 um and 1 nm of E,
# so that an instruction lands where the solver put it. In inches two more decimals.
DECIMALS_MM = {"X": 4, "Y": 4, "Z": 3, "E": 5, "I": 4, "J": 4}
DECIMALS_SPLIT_MM = {"X": 5, "Y": 5, "Z": 5, "E": 6, "I": 5, "J": 5}
DECIMALS_INCH = {k: v + 2 for k, v in DECIMALS_MM.items()}
DECIMALS_SPLIT_INCH = {k: v + 2 for k, v in DECIMALS_SPLIT_MM.items()}
SNAP_MM = 1e-3
SPLITTABLE = (Kind.TRAVEL, Kind.EXTRUDE, Kind.RETRACT, Kind.UNRETRACT, Kind.Z_ONLY, Kind.ARC)
SPLITTABLE_INT = frozenset(int(k) for k in SPLITTABLE)
_ARC = int(Kind.ARC)
#: I/J nudges (units of the last decimal) tried for a rotated arc Klipper would turn otherwise than
#: the original (``LineRewriter._klipper_same_turn``), nearest first
_NUDGES = sorted(((i, j) for i in range(-4, 5) for j in range(-4, 5)), key=lambda t: (abs(t[0]) + abs(t[1]), t))

# a word's value: a number, or an unexpanded slicer placeholder ("Y{machine_depth}"), which the
# parser drops as the firmware does (``_scan_words.parse_words``) and ``MotionLine.value`` reads as absent
_WORD = re.compile(r"([A-Za-z])\s*(\{[^}]*\}?|[-+]?(?:\d+\.?\d*|\.\d+)?)")


class EmitError(GatesoptError, ValueError):
    """The program cannot be rewritten as asked."""



@dataclass(frozen=True)
class EmitResult:
    """What ``emit.render`` wrote, and what it had to do to write it."""

    text: str
    lines_added: int            # motor lines + extra pieces of split moves + the rotation header
    instruction_lines: int      # motor on/off lines written
    splits: int                 # steps split
    moved: int                  # switches moved to the safe side of an unsplittable step
    max_snap_mm: float          # largest single-axis snap
    rotation_deg: float = 0.0
    center_mm: tuple = (0.0, 0.0)
    notes: tuple = field(default=())



# number text
def fmt_number(x: float, d: int) -> str:
    """``x`` with at most ``d`` decimals, trailing zeros dropped ("-0" is "0")."""
    s = f"{x:.{d}f}"
    if "." in s:
        s = s.rstrip("0").rstrip(".")
    if s in ("-0", "", "+0"):
        s = "0"
    return s


def _dec_text(v: Decimal) -> str:
    """A Decimal as G-code number text (trailing zeros dropped)."""
    s = format(v, "f")
    if "." in s:
        s = s.rstrip("0").rstrip(".")
    if s in ("-0", ""):
        s = "0"
    return s


def rotate_xy(xy: np.ndarray, deg: float, center) -> np.ndarray:
    """Rotate points (..., 2) counter-clockwise by ``deg`` about ``center``."""
    k, rest = divmod(float(deg), 90.0)
    if rest == 0.0:     # quarter turns exactly (as gating.rotation.rotation_matrix)
        c, s = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))[int(k) % 4]
    else:
        a = math.radians(deg)
        c, s = math.cos(a), math.sin(a)
    cx, cy = center
    if xy.ndim == 1:      # one point: plain floats (called once per rewritten move)
        x, y = float(xy[0]) - cx, float(xy[1]) - cy
        return np.array([cx + c * x - s * y, cy + s * x + c * y])
    x = xy[..., 0] - cx
    y = xy[..., 1] - cy
    return np.stack([cx + c * x - s * y, cy + s * x + c * y], axis=-1)


@dataclass
class MotionLine:
    """A motion line split into its G word, its other words (in order) and its comment suffix."""

    gword: str
    words: list            # [(LETTER, value_text)] in the original order, G word excluded
    suffix: str            # from the end of the code to the end of the line (comment), no ending
    first: dict = field(default_factory=dict, repr=False)   # letter -> its first word's value text

    def __post_init__(self):
        first = {}
        for k, v in self.words:
            if k not in first:
                first[k] = v
        self.first = first

    @classmethod
    def parse(cls, text: str) -> "MotionLine":
        body = text.rstrip("\r\n")
        cut = body.find(";")
        code = body if cut < 0 else body[:cut]
        code_r = code.rstrip()
        suffix = body[len(code_r):]
        words = [(m.group(1).upper(), m.group(2)) for m in _WORD.finditer(code_r)]
        if not words or words[0][0] != "G":
            raise EmitError(f"not a motion line: {body.strip()[:60]}")
        g = code_r.strip().split()[0] if code_r.strip()[:1] in "Gg" else "G" + words[0][1]
        # keep the G word as written when it is a clean token ("G1", "G01"), else normalise
        if not re.fullmatch(r"[Gg]\d+(\.\d+)?", g):
            g = "G" + words[0][1]
        return cls(g.upper(), words[1:], suffix)

    def value(self, letter: str) -> str | None:
        """The number text of the first word ``letter``; None if absent or a placeholder (which the
        firmware ignores: a rewrite writes the axis as a number where it must, see ``rewrite``)."""
        v = self.first.get(letter)
        return None if v is None or v.startswith("{") else v

    def placeholder(self, letter: str) -> bool:
        return any(k == letter and v.startswith("{") for k, v in self.words)


class LineRewriter:
    """Rewrites motion lines: rotation, splits, single-axis snaps. One pass in line order."""

    def __init__(self, program: Program, rotation_deg: float, center, rotate_rows, snap):
        self.p = program
        self.deg = float(rotation_deg)
        self.rotated = self.deg % 360.0 != 0.0
        self.center = (float(center[0]), float(center[1]))
        lo, hi = (0, program.n_steps) if rotate_rows is None else (int(rotate_rows[0]), int(rotate_rows[1]))
        if self.rotated:
            # relative moves after the run stay in the rotated frame (``rotation.rotated_rows``
            # already does this; a caller's own ``rotate_rows`` gets it here)
            hi = rotated_run_end(program, hi)
        self.lo, self.hi = lo, hi
        self.snap = snap
        self.max_snap = 0.0
        self.snap_missed = 0
        self.snap_refused = 0
        self.placeholders: list[int] = []     # lines whose placeholder axis word became a number
        # the last text written on X/Y, the offset it was written in, and the machine XY it means
        self.em_text = {"X": None, "Y": None}
        self.em_off = [math.nan, math.nan]
        # (before the first row: where the parser puts the head at the start, unrotated -- the
        # machine does not know about the rotation, so a relative first move starts there)
        self.em_val = (np.asarray(program.start_mm[0, :2], float).copy() if program.n_steps
                       else np.array([math.nan, math.nan]))
        # every row's start and end point (X Y Z E), XY in the output's frame, computed once for
        # the whole file: ``_point`` at fractions 0 and 1 is a lookup (as rows (lo, hi] start and
        # rows [lo, hi) end rotated, ``start_rot`` / ``end_rot``)
        self._start = np.asarray(program.start_mm, float).copy()
        self._end = np.asarray(program.end_mm, float).copy()
        if self.rotated and program.n_steps:
            rows = np.arange(program.n_steps)
            srot = ((rows > lo) & (rows <= hi)) | ((rows == lo) & (lo == 0))
            erot = (rows >= lo) & (rows < hi)
            self._start[srot, :2] = rotate_xy(self._start[srot, :2], self.deg, self.center)
            self._end[erot, :2] = rotate_xy(self._end[erot, :2], self.deg, self.center)

    # -- rotation of one row's end points (rows [lo, hi) end rotated; a row starts where the
    # previous one ended, so rows (lo, hi] start rotated) --------------------------------------------
    def end_rot(self, r: int) -> bool:
        return self.rotated and self.lo <= r < self.hi

    def start_rot(self, r: int) -> bool:
        return self.rotated and (self.lo < r <= self.hi or r == self.lo == 0)

    def _rot(self, xy):
        return rotate_xy(np.asarray(xy, float), self.deg, self.center)

    def _point(self, r: int, f: float) -> np.ndarray:
        """Machine X Y Z E at fraction f of step r, XY in the output's (rotated) frame."""
        if f == 0.0:
            return self._start[r].copy()
        if f == 1.0:
            return self._end[r].copy()
        p = self.p
        a = p.start_mm[r].astype(float).copy()
        b = p.end_mm[r].astype(float).copy()
        if int(p.kind[r]) == _ARC and 0.0 < f < 1.0:
            cx, cy = p.arc_center_mm[r]
            a0 = math.atan2(a[1] - cy, a[0] - cx)
            a1 = math.atan2(b[1] - cy, b[0] - cx)
            sweep = _sweep(a0, a1, bool(p.arc_ccw[r]))
            rad = math.hypot(a[0] - cx, a[1] - cy)
            ang = a0 + f * sweep
            q = np.array([cx + rad * math.cos(ang), cy + rad * math.sin(ang),
                          a[2] + f * (b[2] - a[2]), a[3] + f * (b[3] - a[3])])
            if self.end_rot(r):
                q[:2] = self._rot(q[:2])
            return q
        if self.start_rot(r):
            a[:2] = self._rot(a[:2])
        if self.end_rot(r):
            b[:2] = self._rot(b[:2])
        if f == 0.0:
            return a
        if f == 1.0:
            return b
        return a + f * (b - a)

    # -- bookkeeping for lines kept as written ----------------------------------------------------
    def note_kept(self, r: int) -> None:
        p = self.p
        if not self.rotated:
            return
        if int(p.kind[r]) not in SPLITTABLE_INT:
            if (p.end_mm[r, :2] != p.start_mm[r, :2]).any():   # homing moved XY
                self.em_text = {"X": None, "Y": None}
                self.em_val = p.end_mm[r, :2].astype(float).copy()
            return
        end = self._point(r, 1.0)
        if (p.end_mm[r, :2] == p.start_mm[r, :2]).all():
            # Z/E only: X/Y text unchanged, and the head is still where the text before put it
            # (not at the exact rotated point): a relative move after it is written from there
            if np.isnan(self.em_val).any():
                self.em_val = end[:2].copy()
            return
        self.em_val = end[:2].copy()
        ln = MotionLine.parse(p.line_text(int(p.line[r])))
        for k, a in enumerate(("X", "Y")):
            v = ln.value(a)
            if p.relative_xyz[r]:
                self.em_text[a] = None
            elif v is not None:
                self.em_text[a] = v
                self.em_off[k] = float(p.offset_mm[r, k])

    # -- one rewritten row ---------------------------------------------------------------------------

    # -- one rewritten row ---------------------------------------------------------------------------
    def rewrite(self, r: int, cuts: list) -> list[str]:
        """Lines (no endings) for step r, cut at ``cuts`` = [(fraction, [lines between])]."""
        p = self.p
        ln = MotionLine.parse(p.line_text(int(p.line[r])))
        scale = 25.4 if p.inch[r] else 1.0
        rel = {a: (bool(p.relative_e[r]) if a == "E" else bool(p.relative_xyz[r])) for a in AXES}
        off = p.offset_mm[r].astype(float)
        arc = int(p.kind[r]) == _ARC
        rot_row = self.end_rot(r) or self.start_rot(r)
        write = self._axes_to_write(r, ln, rot_row, arc)
        if arc and ln.value("P") not in (None, "", "1") and cuts:
            raise EmitError(f"{p.source}:{int(p.line[r]) + 1}: cannot split a G2/G3 with P (several turns)")
        start = self._point(r, 0.0)
        end = self._point(r, 1.0)
        snapped = self._snapped(r, start, end, rel, off, rot_row, arc)
        bounds = [0.0] + [c[0] for c in cuts] + [1.0]
        out: list[str] = []
        sums = {a: Decimal(0) for a in AXES}
        cur_xy = start[:2].copy()     # where the firmware is when this piece starts (arc centre base)
        if rot_row and not np.isnan(self.em_val).any():
            cur_xy = self.em_val.copy()
        # A relative X/Y is the rotated delta (rotation only, no translation: both ends are in the
        # output's frame), taken from where the text before left the head (``cur_xy``), not from
        # the exact rotated start: each rounded delta then corrects the rounding of the ones
        # before, and a G91 print does not drift off its rotated geometry move by move.
        base = start.copy()
        base[:2] = cur_xy
        vals: dict = {}
        for k in range(len(bounds) - 1):
            last = k == len(bounds) - 2
            q = self._point(r, bounds[k + 1])
            vals = self._piece_values(r, ln, write, snapped, rel, off, scale, last, rot_row, q, end,
                                      base, sums)
            ij = None
            if arc:
                dec = (DECIMALS_INCH if p.inch[r] else DECIMALS_MM) if last else (
                    DECIMALS_SPLIT_INCH if p.inch[r] else DECIMALS_SPLIT_MM)
                c = np.array(p.arc_center_mm[r], float)
                if self.end_rot(r):
                    c = self._rot(c)
                ij = (fmt_number((c[0] - cur_xy[0]) / scale, dec["I"]),
                      fmt_number((c[1] - cur_xy[1]) / scale, dec["J"]))
                if rot_row and len(bounds) == 2 and scale == 1.0:
                    ij = self._klipper_same_turn(r, ln, vals, ij, dec["I"], rel, off)
            if k == 0:
                new_ij = arc and (rot_row or len(bounds) > 2 or ln.value("R") is not None)
                words = _first_piece_words(ln, write, vals, ij, rot_row, new_ij)
                out.append(" ".join([ln.gword] + words) + ln.suffix)
            else:
                words = [f"{a}{vals[a]}" for a in write]
                if ij is not None:
                    words += [f"I{ij[0]}", f"J{ij[1]}"]
                out.append(" ".join([ln.gword] + words))
            if not last:
                out.extend(cuts[k][1])
            cur_xy = _written_xy(vals, rel, off, scale, cur_xy)
        if self.rotated:
            self.em_val = cur_xy
            for k, a in enumerate(("X", "Y")):
                if a in vals:
                    self.em_text[a] = None if rel[a] else vals[a]
                    self.em_off[k] = off[k]
        return out

    def _klipper_same_turn(self, r: int, ln: MotionLine, vals: dict, ij: tuple, dec: int, rel, off) -> tuple:
        """I/J of a rotated arc that Klipper turns as far as the original (a full circle or none).

        Klipper's gcode_arcs (``planArc``) makes a full circle of an arc whose target is its start
        only when its float sums give an angle of exactly 0; a turn of a hair either way is a
        null arc or a full one. Orca's spiral lift (``G3 Z.. I.. J.. P1``) is such an arc: turned
        and rounded, about half of them flipped (real_orca230_arcs at 45 deg: +4.6 s in Klipper's
        planner, +/-0.145 s each). Where the rotated numbers (as Klipper reads the text) would
        flip, I and J move by a few units of their last decimal (<= 0.4 um), nearest first, until
        they do not (the float error of nearby values is correlated: one unit is often not enough)."""
        p = self.p
        i0, j0 = ln.value("I"), ln.value("J")
        texts = [self.em_text[a] for a in ("X", "Y")]
        if (not i0 or not j0 or ln.value("R") is not None or rel["X"] or rel["Y"] or off[:2].any()
                or any(v != 0.0 for v in self.em_off) or None in texts or "X" not in vals or "Y" not in vals):
            return ij
        cw = ln.gword.upper() in ("G2", "G02")
        want = klipper_arc_turn(p.start_mm[r, :2], p.end_mm[r, :2], (float(i0), float(j0)), cw)
        cur = (float(texts[0]), float(texts[1]))
        tgt = (float(vals["X"]), float(vals["Y"]))
        unit = 10.0 ** -dec
        for di, dj in _NUDGES:
            cand = (fmt_number(float(ij[0]) + di * unit, dec), fmt_number(float(ij[1]) + dj * unit, dec))
            if abs(klipper_arc_turn(cur, tgt, (float(cand[0]), float(cand[1])), cw) - want) < math.pi:
                return cand
        return ij

    def _axes_to_write(self, r: int, ln: MotionLine, rot_row: bool, arc: bool) -> list[str]:
        """The axis words step r's pieces carry: those it names, and X and Y both where the
        rotation moves it. Checks each (a word without a number is an error; a placeholder is
        noted: it is written as the number the firmware stays at)."""
        p = self.p
        present = [a for a in AXES if ln.value(a) is not None]
        write = list(present)
        if rot_row and (arc or "X" in present or "Y" in present or
                        (p.end_mm[r, :2] != p.start_mm[r, :2]).any()):
            write = sorted(set(write) | {"X", "Y"}, key=AXES.index)
        for a in write:
            if ln.value(a) == "":
                raise EmitError(f"{p.source}:{int(p.line[r]) + 1}: axis word {a} without a number")
            if ln.placeholder(a):
                # "G1 X0 Y{machine_depth}" (Cura's end G-code, unexpanded): the firmware ignores
                # the Y word and Y stays put; the rotation must write where it stays, as a number
                self.placeholders.append(int(p.line[r]) + 1)
        return write

    def _snapped(self, r: int, start, end, rel, off, rot_row: bool, arc: bool) -> dict:
        """Single-axis snap: the other axis gets exactly the text written before (or 0 if
        relative). {axis letter: text} of the axes snapped."""
        snapped = {}
        if not (rot_row and self.snap is not None and not arc):
            return snapped
        for k, a in enumerate(("X", "Y")):
            if not self.snap[r, k]:
                continue
            ref = self.em_val[k] if not np.isnan(self.em_val[k]) else start[k]
            if abs(ref - end[k]) > SNAP_MM:
                # snapping again would carry the drift of earlier snaps past the tolerance
                self.snap_refused += 1
                continue
            if rel[a]:
                snapped[a] = "0"
            elif self.em_text[a] is not None and self.em_off[k] == off[k]:
                snapped[a] = self.em_text[a]
            else:
                self.snap_missed += 1
                continue
            self.max_snap = max(self.max_snap, abs(ref - end[k]))
        return snapped

    def _piece_values(self, r: int, ln: MotionLine, write, snapped, rel, off, scale, last: bool,
                      rot_row: bool, q, end, base, sums) -> dict:
        """{axis letter: number text} of one piece of step r, ending at ``q`` (the last piece at
        ``end``). Relative values add up exactly (``sums``, updated) to the line's own number or
        to the rotated delta from ``base``; an absolute last piece keeps the line's own text."""
        p = self.p
        dec_end = DECIMALS_INCH if p.inch[r] else DECIMALS_MM
        dec = dec_end if last else (DECIMALS_SPLIT_INCH if p.inch[r] else DECIMALS_SPLIT_MM)
        vals = {}
        for a in write:
            ai = AXES.index(a)
            if a in snapped:
                vals[a] = snapped[a]
                continue
            keep_text = not (rot_row and ai < 2) and ln.value(a) is not None
            if rel[a]:
                if last:
                    total = (Decimal(ln.value(a)) if keep_text
                             else Decimal(fmt_number((end[ai] - base[ai]) / scale, dec_end[a])))
                    vals[a] = _dec_text(total - sums[a])
                else:
                    t = Decimal(fmt_number((q[ai] - base[ai]) / scale - float(sums[a]), dec[a]))
                    vals[a] = _dec_text(t)
                    sums[a] += t
            elif last and keep_text:
                vals[a] = ln.value(a)
            else:
                vals[a] = fmt_number((q[ai] - off[ai]) / scale, dec[a])
        return vals


def _first_piece_words(ln: MotionLine, write, vals: dict, ij, rot_row: bool, new_ij: bool) -> list[str]:
    """The words of a rewritten line's first piece, in the line's own order: its other words (F
    ...) kept, X and Y together where the rotation writes both, I/J new where the arc changed."""
    words, done = [], set()
    for letter, v in ln.words:
        if letter in ("X", "Y") and "X" in vals and "Y" in vals and rot_row:
            if "X" not in done:
                words += [f"X{vals['X']}", f"Y{vals['Y']}"]
                done |= {"X", "Y"}
        elif letter in AXES and letter in vals:
            words.append(f"{letter}{vals[letter]}")
            done.add(letter)
        elif letter in ("I", "J", "R") and new_ij:
            if "IJ" not in done:
                words += [f"I{ij[0]}", f"J{ij[1]}"]
                done.add("IJ")
        else:
            words.append(f"{letter}{v}")
    for a in write:  # an axis the rotation added (the line named only one of X/Y)
        if a not in done:
            words.insert(_axis_insert_at(words), f"{a}{vals[a]}")
            done.add(a)
    if new_ij and "IJ" not in done:
        words += [f"I{ij[0]}", f"J{ij[1]}"]
    return words


def _written_xy(vals, rel, off, scale, prev_xy) -> np.ndarray:
    out = np.array(prev_xy, float)
    for k, a in enumerate(("X", "Y")):
        if a in vals:
            out[k] = prev_xy[k] + float(vals[a]) * scale if rel[a] else float(vals[a]) * scale + off[k]
    return out


def _axis_insert_at(words: list[str]) -> int:
    """Index after the last X/Y/Z word (so an added Y lands beside X)."""
    idx = 0
    for k, w in enumerate(words):
        if w[:1] in ("X", "Y", "Z"):
            idx = k + 1
    return idx


def _sweep(a0: float, a1: float, ccw: bool) -> float:
    """Signed angle from a0 to a1, counter-clockwise (> 0) or clockwise (< 0); equal: full turn."""
    d = a1 - a0
    if ccw:
        while d <= 1e-12:
            d += 2 * math.pi
    else:
        while d >= -1e-12:
            d -= 2 * math.pi
    return d
