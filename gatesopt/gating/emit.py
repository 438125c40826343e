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
  motion line, counter-clockwise by ``rotate_deg`` about ``center`` in machine coordinates, and
  adds the line ``; gatesopt: rotate_deg=<deg> center_x=<x> center_y=<y>`` at the top. A move that
  is single-axis after rotation (other-axis change <= ``snap_mm``) gets exactly the previous text
  on the other axis, so the firmware does not step that motor; ``EmitResult.max_snap_mm`` is the
  largest such correction. A relative move (G91) that starts in the rotated print says where to go
  *from there*: its XY delta is rotated (no translation) and it stays in the rotated frame
  (``rotated_run_end``), and its delta is written from the position the text before it reached,
  so rounding does not add up over a run of relative moves.

Without rotation the text is written by a compiled pass over the lines (``_emit_kernel``); the
per-line ``_Emitter`` below is the reference it must equal byte for byte, and still writes the
rotated output and any split move the kernel leaves to it (arcs, unusual spelling).

Files with line numbers and checksums (``N12 G1 ... *34``) are refused when anything must change:
inserting lines would mean renumbering every following line, and hosts resend by number.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from decimal import Decimal

import numpy as np

from .. import firmware as fwmod
from ..errors import GatesoptError
from ..headers import ROTATE_HEADER
from ..program import AXES, Kind, Program, X, Y
from .problem import rotated_run_end

# Decimals written (mm). Rotated end points: 0.1 um (slicers write 1 um; a rotation makes every
# coordinate irrational, and 0.1 um keeps the time of each move within 20 us of the solver's at
# >= 5 mm/s, which the verifier's start-ahead check needs). Split points: 0.01 um and 1 nm of E,
# so that an instruction lands where the solver put it. In inches two more decimals.
DECIMALS_MM = {"X": 4, "Y": 4, "Z": 3, "E": 5, "I": 4, "J": 4}
DECIMALS_SPLIT_MM = {"X": 5, "Y": 5, "Z": 5, "E": 6, "I": 5, "J": 5}
DECIMALS_INCH = {k: v + 2 for k, v in DECIMALS_MM.items()}
DECIMALS_SPLIT_INCH = {k: v + 2 for k, v in DECIMALS_SPLIT_MM.items()}
SNAP_MM = 1e-3
TIME_EPS_S = 1e-9
SPLITTABLE = (Kind.TRAVEL, Kind.EXTRUDE, Kind.RETRACT, Kind.UNRETRACT, Kind.Z_ONLY, Kind.ARC)
_SPLITTABLE_INT = frozenset(int(k) for k in SPLITTABLE)
_ARC = int(Kind.ARC)

# a word's value: a number, or an unexpanded slicer placeholder ("Y{machine_depth}"), which the
# parser drops as the firmware does (``_scan._parse_words``) and ``_Line.value`` reads as absent
_WORD = re.compile(r"([A-Za-z])\s*(\{[^}]*\}?|[-+]?(?:\d+\.?\d*|\.\d+)?)")
_XY_WORD = re.compile(r"[XYxy]\s*[-+.0-9]")
_LINE_NUMBER = re.compile(rb"(?m)^[ \t]*N\d+")


class EmitError(GatesoptError, ValueError):
    """The program cannot be rewritten as asked."""


@dataclass(frozen=True)
class Switch:
    """One motor instruction: at ``time_s`` (paper time from program start) ``motor`` goes on/off."""

    time_s: float
    motor: int          # 0..3 = X Y Z E
    on: bool


@dataclass(frozen=True)
class EmitResult:
    text: str
    lines_added: int            # motor lines + extra pieces of split moves + the rotation header
    instruction_lines: int      # motor on/off lines written
    splits: int                 # steps split
    moved: int                  # switches moved to the safe side of an unsplittable step
    max_snap_mm: float          # largest single-axis snap
    rotate_deg: float = 0.0
    center_mm: tuple = (0.0, 0.0)
    notes: tuple = field(default=())


# ------------------------------------------------------------------------------------------------
# number text
def _fmt(x: float, d: int) -> str:
    s = f"{x:.{d}f}"
    if "." in s:
        s = s.rstrip("0").rstrip(".")
    if s in ("-0", "", "+0"):
        s = "0"
    return s


def _dec_text(v: Decimal) -> str:
    s = format(v, "f")
    if "." in s:
        s = s.rstrip("0").rstrip(".")
    if s in ("-0", ""):
        s = "0"
    return s


def rotate_xy(xy: np.ndarray, deg: float, center) -> np.ndarray:
    """Rotate points (..., 2) counter-clockwise by ``deg`` about ``center``."""
    k, rest = divmod(float(deg), 90.0)
    if rest == 0.0:     # quarter turns exactly (as gatesopt.gating.problem.rotation_matrix)
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


# ------------------------------------------------------------------------------------------------
@dataclass
class _Line:
    """A motion line split into its G word, its other words (in order) and its comment suffix."""

    gword: str
    words: list            # [(LETTER, value_text)] in the original order, G word excluded
    suffix: str            # from the end of the code to the end of the line (comment), no ending

    @classmethod
    def parse(cls, text: str) -> "_Line":
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
        for k, v in self.words:
            if k == letter:
                return None if v.startswith("{") else v
        return None

    def placeholder(self, letter: str) -> bool:
        return any(k == letter and v.startswith("{") for k, v in self.words)


@dataclass(frozen=True)
class Placed:
    """One instruction line group placed in the program (what ``render`` writes).

    ``fraction`` None: the lines go right before step ``row`` (``row == n_steps``: after the last
    step); else step ``row`` is split at that fraction of its duration and the lines go between.
    """

    time_s: float
    row: int
    on: bool
    motors: tuple           # motor letters
    fraction: float | None = None


@dataclass(frozen=True, eq=False)
class PlacedArrays:
    """``Placed`` groups as arrays, one entry each: what the unrotated emitter works on."""

    time_s: np.ndarray      # (k,) float
    row: np.ndarray         # (k,) int64
    on: np.ndarray          # (k,) bool
    motor_mask: np.ndarray  # (k,) uint8: bit m = motor AXES[m]
    split: np.ndarray       # (k,) bool: ``fraction`` is given (``Placed.fraction`` not None)
    fraction: np.ndarray    # (k,) float

    @classmethod
    def from_placed(cls, placed) -> "PlacedArrays":
        k = len(placed)
        return cls(np.fromiter((pl.time_s for pl in placed), float, k),
                   np.fromiter((pl.row for pl in placed), np.int64, k),
                   np.fromiter((pl.on for pl in placed), bool, k),
                   np.fromiter((sum(1 << AXES.index(m) for m in set(pl.motors)) for pl in placed), np.uint8, k),
                   np.fromiter((pl.fraction is not None for pl in placed), bool, k),
                   np.fromiter((0.0 if pl.fraction is None else pl.fraction for pl in placed), float, k))

    def to_placed(self) -> list[Placed]:
        return [Placed(float(t), int(r), bool(on), tuple(a for m, a in enumerate(AXES) if mask >> m & 1),
                       float(f) if s else None)
                for t, r, on, mask, s, f in zip(self.time_s, self.row, self.on, self.motor_mask.tolist(),
                                                 self.split, self.fraction)]

    def motors(self) -> list[str]:
        """Every motor letter switched, in X Y Z E order."""
        bits = int(np.bitwise_or.reduce(self.motor_mask)) if len(self.motor_mask) else 0
        return [a for m, a in enumerate(AXES) if bits >> m & 1]


class _Emitter:
    """Rewrites motion lines: rotation, splits, single-axis snaps. One pass in line order."""

    def __init__(self, program: Program, rotate_deg: float, center, rotate_rows, snap):
        self.p = program
        self.deg = float(rotate_deg)
        self.rotated = self.deg % 360.0 != 0.0
        self.center = (float(center[0]), float(center[1]))
        lo, hi = (0, program.n_steps) if rotate_rows is None else (int(rotate_rows[0]), int(rotate_rows[1]))
        if self.rotated:
            # relative moves after the run stay in the rotated frame (``problem._rotate_rows``
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
        if int(p.kind[r]) not in _SPLITTABLE_INT:
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
        ln = _Line.parse(p.line_text(int(p.line[r])))
        for k, a in enumerate(("X", "Y")):
            v = ln.value(a)
            if p.relative_xyz[r]:
                self.em_text[a] = None
            elif v is not None:
                self.em_text[a] = v
                self.em_off[k] = float(p.offset_mm[r, k])

    # -- one rewritten row ---------------------------------------------------------------------------
    def rewrite(self, r: int, cuts: list) -> list[str]:
        """Lines (no endings) for step r, cut at ``cuts`` = [(fraction, [lines between])]."""
        p = self.p
        ln = _Line.parse(p.line_text(int(p.line[r])))
        scale = 25.4 if p.inch[r] else 1.0
        dec_end = DECIMALS_INCH if p.inch[r] else DECIMALS_MM
        dec_cut = DECIMALS_SPLIT_INCH if p.inch[r] else DECIMALS_SPLIT_MM
        rel = {a: (bool(p.relative_e[r]) if a == "E" else bool(p.relative_xyz[r])) for a in AXES}
        off = p.offset_mm[r].astype(float)
        arc = int(p.kind[r]) == _ARC
        rot_row = self.end_rot(r) or self.start_rot(r)
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
        if arc and ln.value("P") not in (None, "", "1") and cuts:
            raise EmitError(f"{p.source}:{int(p.line[r]) + 1}: cannot split a G2/G3 with P (several turns)")
        start = self._point(r, 0.0)
        end = self._point(r, 1.0)
        # single-axis snap: the other axis gets exactly the text written before (or 0 if relative)
        snapped = {}
        if rot_row and self.snap is not None and not arc:
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
            dec = dec_end if last else dec_cut
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
                                 else Decimal(_fmt((end[ai] - base[ai]) / scale, dec_end[a])))
                        vals[a] = _dec_text(total - sums[a])
                    else:
                        t = Decimal(_fmt((q[ai] - base[ai]) / scale - float(sums[a]), dec[a]))
                        vals[a] = _dec_text(t)
                        sums[a] += t
                elif last and keep_text:
                    vals[a] = ln.value(a)
                else:
                    vals[a] = _fmt((q[ai] - off[ai]) / scale, dec[a])
            ij = None
            if arc:
                c = np.array(p.arc_center_mm[r], float)
                if self.end_rot(r):
                    c = self._rot(c)
                ij = (_fmt((c[0] - cur_xy[0]) / scale, dec["I"]), _fmt((c[1] - cur_xy[1]) / scale, dec["J"]))
            if k == 0:
                words, done = [], set()
                new_ij = arc and (rot_row or len(bounds) > 2 or ln.value("R") is not None)
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


# ------------------------------------------------------------------------------------------------
def place_switches(program: Program, switches) -> list[Placed]:
    """Group ``Switch``es into instruction moments and locate each in the program's steps.

    Same time (within 1 ns) and same direction -> one moment. A moment on a step boundary goes
    right before the step that starts there; one strictly inside a step splits it.
    """
    items = sorted(((float(s.time_s), bool(s.on), int(s.motor)) for s in switches))
    moments: list[list] = []
    for t, on, m in items:
        if moments and moments[-1][1] == on and abs(moments[-1][0] - t) <= TIME_EPS_S:
            moments[-1][2].add(AXES[m])
        else:
            moments.append([t, on, {AXES[m]}])
    dur = np.asarray(program.duration_s, float)
    t_end = np.cumsum(dur)
    t_start = t_end - dur
    n = program.n_steps
    out = []
    for t, on, ms in moments:
        motors = tuple(a for a in AXES if a in ms)
        i = int(np.searchsorted(t_end, t + TIME_EPS_S, side="right"))
        if i >= n:
            out.append(Placed(t, n, on, motors))
        elif t <= t_start[i] + TIME_EPS_S:
            out.append(Placed(t, i, on, motors))
        else:
            out.append(Placed(t, i, on, motors, (t - t_start[i]) / dur[i]))
    return out


def render(program: Program, placed, *, firmware="3dgates", rotate_deg: float = 0.0,
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
    rotated = float(rotate_deg) % 360.0 != 0.0
    if not n_placed and not rotated:
        return EmitResult(program.to_gcode(), 0, 0, 0, 0, 0.0)
    if _LINE_NUMBER.search(program.data):
        raise EmitError(f"{program.source}: the file uses line numbers/checksums (N.. *..); inserting "
                        "lines would renumber every following line and break host resends: strip them first")
    n = program.n_steps
    if not rotated and (n < 2 or bool((program.line[1:] > program.line[:-1]).all())):
        arrays = placed if isinstance(placed, PlacedArrays) else PlacedArrays.from_placed(placed)
        return _render_plain(program, fw, arrays, float(rotate_deg), center_mm)
    if isinstance(placed, PlacedArrays):
        placed = placed.to_placed()
    em = _Emitter(program, rotate_deg, center_mm, rotate_rows, snap)
    if rotated:
        lo, hi = em.lo, em.hi
        o = program.offset_mm[lo:min(hi + 1, n), :2]
        if len(o) and (o != o[0]).any():
            raise EmitError(f"{program.source}: a G92 sets X/Y inside the part to rotate: cannot rotate")
        if snap is None:
            em.snap = _default_snap(em, program)
    nl = program.line_ending
    before: dict[int, list[str]] = {}
    cuts: dict[int, list] = {}
    moved = instr = 0
    inside: dict[int, list[Placed]] = {}     # unsplittable row -> instructions that fall inside it
    for pl in sorted(placed, key=lambda q: q.time_s):
        r = int(pl.row)
        if r < n and pl.fraction is not None and 0.0 < pl.fraction < 1.0 and program.kind[r] not in SPLITTABLE:
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
        # A dwell, heat-up wait or homing cannot be split. Per motor only the last instruction
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
    rewrite = set(cuts)
    if rotated:
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
    row_of_line = {int(program.line[r]): r for r in range(n)}
    out: list[str] = []
    added = 0
    if rotated:
        out.append(ROTATE_HEADER.format(deg=_fmt(float(rotate_deg), 9), cx=_fmt(float(center_mm[0]), 6),
                                        cy=_fmt(float(center_mm[1]), 6)) + nl)
        added += 1
    splits = 0
    for li in range(program.n_lines + 1):
        ins = before.get(li)
        if ins:
            out.extend(x + nl for x in ins)
            added += len(ins)
        if li == program.n_lines:
            break
        r = row_of_line.get(li)
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
    notes = []
    if em.snap_missed:
        notes.append(f"{em.snap_missed} single-axis snaps could not be applied (no previous absolute text)")
    if em.snap_refused:
        notes.append(f"{em.snap_refused} single-axis snaps refused (earlier snaps had drifted the axis "
                     f"by more than {SNAP_MM * 1e3:g} um): those moves step both motors")
    if moved:
        notes.append(f"{moved} instruction(s) moved out of a dwell/wait/homing step to its safe side")
    if em.placeholders:
        notes.append(f"{len(em.placeholders)} unexpanded placeholder axis word(s) (line "
                     f"{em.placeholders[0]}{', ...' if len(em.placeholders) > 1 else ''}) written as the "
                     f"number the firmware stays at (it ignores such a word)")
    return EmitResult("".join(out), added, instr, splits, moved, em.max_snap, float(rotate_deg),
                      (float(center_mm[0]), float(center_mm[1])), tuple(notes))


def _instruction_table(fw):
    """The instruction lines of each (direction, motors) code ``16 * on + motor mask``, as texts
    (a list per code) and as the kernel's table: (texts, code_ptr (33,), txt_id, txt_buf, txt_ptr,
    bytes per code (32,) without line endings)."""
    texts = [fw.on_lines(motors) if code >= 16 else fw.off_lines(motors)
             for code in range(32) for motors in [tuple(a for m, a in enumerate(AXES) if code >> m & 1)]]
    distinct = list(dict.fromkeys(t for lines in texts for t in lines))
    blobs = [t.encode("utf-8", "surrogateescape") for t in distinct]
    txt_ptr = np.concatenate([[0], np.cumsum([len(b) for b in blobs])]).astype(np.int64)
    txt_id = np.array([distinct.index(t) for lines in texts for t in lines], np.int64)
    code_ptr = np.concatenate([[0], np.cumsum([len(lines) for lines in texts])]).astype(np.int64)
    cum = np.concatenate([[0], np.cumsum(np.diff(txt_ptr)[txt_id])]).astype(np.int64)
    return (texts, code_ptr, txt_id, np.frombuffer(b"".join(blobs), np.uint8), txt_ptr,
            cum[code_ptr[1:]] - cum[code_ptr[:-1]])


def _render_plain(program: Program, fw, placed: PlacedArrays, rotate_deg: float, center_mm,
                  split_in_kernel: bool = True) -> EmitResult:
    """``render`` without rotation, over arrays: where each instruction goes is decided here with
    numpy (the same rules as the per-line loop in ``render``), the text is written by
    ``_emit_kernel.render_plain``; split moves it leaves are written by ``_Emitter.rewrite`` (all
    of them with ``split_in_kernel=False``: the reference the tests compare the kernel with)."""
    from . import _emit_kernel

    n = program.n_steps
    o = np.argsort(placed.time_s, kind="stable")         # time order; ties keep the given order
    row, on, split, frac = placed.row[o], placed.on[o], placed.split[o], placed.fraction[o]
    code = on.astype(np.int64) * 16 + placed.motor_mask[o]
    texts, code_ptr, txt_id, txt_buf, txt_ptr, code_bytes = _instruction_table(fw)
    code_lines = np.diff(code_ptr)
    in_prog = row < n
    r0 = np.minimum(row, n - 1)
    line_r = program.line[r0]
    strictly_inside = split & (frac > 0.0) & (frac < 1.0)
    unsplittable = in_prog & strictly_inside & ~np.isin(program.kind[r0], SPLITTABLE)
    live = ~unsplittable & (code_lines[code] > 0)
    cut = live & in_prog & split & ~(frac <= 0.0) & ~(frac >= 1.0)
    put = live & ~cut
    slot = np.where(~in_prog, program.line[n - 1] + 1,
                    np.where(~split | (frac <= 0.0), line_r, line_r + 1))
    instr = int(code_lines[code[live]].sum())
    # instruction lines before a line: (slot, rank, time order); rank 0 = an "off" moved out of the
    # step ending right before (first), 1 = placed there, 2 = an "on" moved out of the step there
    ins_slot, ins_rank, ins_code = [slot[put]], [np.ones(int(put.sum()), np.int64)], [code[put]]
    moved = int(unsplittable.sum())
    if moved:
        # A dwell, heat-up wait or homing cannot be split. Per motor only the last instruction
        # inside it matters: a final "on" goes before the step, a final "off" after it -- both on
        # the safe side of start-ahead / end-late (the motor is on for the whole step).
        idx = np.flatnonzero(unsplittable)
        for r in dict.fromkeys(row[idx].tolist()):
            last = {}
            for k in idx[row[idx] == r]:
                for m in range(4):
                    if placed.motor_mask[o[k]] >> m & 1:
                        last[m] = bool(on[k])
            for is_on, at, rank in ((True, int(program.line[r]), 2), (False, int(program.line[r]) + 1, 0)):
                mask = sum(1 << m for m, v in last.items() if v is is_on)
                c = 16 * is_on + mask
                if mask and code_lines[c]:
                    instr += int(code_lines[c])
                    ins_slot.append(np.array([at]))
                    ins_rank.append(np.array([rank]))
                    ins_code.append(np.array([c]))
    ins_slot, ins_rank, ins_code = (np.concatenate(v).astype(np.int64) for v in (ins_slot, ins_rank, ins_code))
    oi = np.lexsort((np.arange(len(ins_slot)), ins_rank, ins_slot))
    ins_slot, ins_code = ins_slot[oi], ins_code[oi]
    # cuts: by row, then fraction (stable: moments at one fraction keep their time order)
    c_row, c_frac, c_code = row[cut], frac[cut], code[cut]
    oc = np.argsort(c_frac, kind="stable")
    oc = oc[np.argsort(c_row[oc], kind="stable")]
    c_row, c_frac, c_code = c_row[oc], c_frac[oc], c_code[oc]
    split_rows, cut_start = np.unique(c_row, return_index=True)
    cut_ptr = np.append(cut_start, len(c_row)).astype(np.int64)
    split_line = program.line[split_rows].astype(np.int64)
    nl = program.line_ending.encode()
    ls = program.line_start
    line_len = ls[split_line + 1] - ls[split_line]
    cap = (len(program.data) + int((code_bytes[ins_code] + len(nl) * code_lines[ins_code]).sum())
           + int((code_bytes[c_code] + len(nl) * code_lines[c_code]).sum())
           + int(((np.diff(cut_ptr) + 1) * (line_len + 100 + len(nl))).sum()))
    out = np.empty(cap, np.uint8)
    left_at = np.full(len(split_rows), -1, np.int64)
    buf = np.frombuffer(program.data, np.uint8)
    size, added = _emit_kernel.render_plain(
        buf, ls, ins_slot, ins_code, split_rows.astype(np.int64), split_line, cut_ptr, c_frac, c_code,
        code_ptr, txt_id, txt_buf, txt_ptr, np.frombuffer(nl, np.uint8), program.kind == Kind.ARC,
        program.start_mm, program.end_mm, program.offset_mm, program.relative_xyz, program.relative_e,
        program.inch, split_in_kernel, out, left_at)
    added += int(code_lines[ins_code].sum())
    pieces, at = [], 0
    em = _Emitter(program, 0.0, (0.0, 0.0), None, None)
    for k in np.flatnonzero(left_at >= 0):
        # a split the kernel leaves (an arc, an unusual spelling, a rounding tie): the reference
        r = int(split_rows[k])
        cuts = []
        for f, c in zip(c_frac[cut_ptr[k]:cut_ptr[k + 1]].tolist(), c_code[cut_ptr[k]:cut_ptr[k + 1]].tolist()):
            if cuts and f - cuts[-1][0] <= 1e-12:      # several lines at one moment: one split
                cuts[-1] = (cuts[-1][0], cuts[-1][1] + texts[c])
            else:
                cuts.append((f, list(texts[c])))
        new = em.rewrite(r, cuts)
        text = program.line_text(int(split_line[k]))
        ending = text[len(text.rstrip("\r\n")):]
        pieces += [out[at:left_at[k]], "".join(x + program.line_ending for x in new[:-1]).encode(
            "utf-8", "surrogateescape") + (new[-1] + ending).encode("utf-8", "surrogateescape")]
        at = int(left_at[k])
        added += len(new) - 1
    pieces.append(out[at:size])
    data = b"".join(pieces) if len(pieces) > 1 else out[:size].tobytes()
    notes = (f"{moved} instruction(s) moved out of a dwell/wait/homing step to its safe side",) if moved else ()
    return EmitResult(data.decode("utf-8", "surrogateescape"), added, instr, len(split_rows), moved, 0.0,
                      rotate_deg, (float(center_mm[0]), float(center_mm[1])), notes)


def _default_snap(em: _Emitter, program: Program) -> np.ndarray:
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


# ------------------------------------------------------------------------------------------------
# GatingSolution -> text
def solution_placed(solution) -> list[Placed]:
    """The solution's instruction lines (``GatingSolution.instructions()``) as ``Placed`` groups."""
    ins = solution.instructions()
    out = []
    for k in range(len(ins.time_s)):
        motors = tuple(AXES[m] for m in ins.motors[k])
        frac = float(ins.fraction[k]) if bool(ins.split[k]) else None
        out.append(Placed(float(ins.time_s[k]), int(ins.row[k]), bool(ins.on[k]), motors, frac))
    return out


def solution_snap(solution) -> np.ndarray | None:
    """(n, 2) bool: X/Y of rows the solution takes as not stepping under its rotation."""
    prob = solution.problem
    if float(solution.rotation_deg) % 360.0 == 0.0:
        return None
    from .problem import steps_motor_at
    steps, _ = steps_motor_at(prob, solution.angle_index)
    xy0 = (prob.steps_motor0[:, X] | prob.steps_motor0[:, Y]) & ~prob.arc
    return ~steps[:, :2] & xy0[:, None]


def solution_arrays(solution) -> PlacedArrays:
    """``solution_placed`` as arrays (no object per instruction line)."""
    ins = solution.instructions()
    return PlacedArrays(np.asarray(ins.time_s, float), np.asarray(ins.row, np.int64), np.asarray(ins.on, bool),
                        np.asarray(ins.motor_mask, np.uint8), np.asarray(ins.split, bool),
                        np.asarray(ins.fraction, float))


def emit_result(program: Program, solution, firmware=None) -> EmitResult:
    """Emit with the full report (lines added, splits, snaps). ``firmware`` defaults to the one
    the solution's options name."""
    fw = firmware or getattr(solution.problem.options, "firmware", "3dgates")
    prob = solution.problem
    rotated = float(solution.rotation_deg) % 360.0 != 0.0
    placed = solution_placed(solution) if rotated else solution_arrays(solution)
    return render(program, placed, firmware=fw, rotate_deg=solution.rotation_deg,
                  center_mm=tuple(float(v) for v in solution.center_xy),
                  rotate_rows=(prob.rotate_lo, prob.rotate_hi), snap=solution_snap(solution))


def emit(program: Program, solution, firmware="3dgates") -> str:
    """Gated G-code text for ``program`` under a ``GatingSolution``."""
    return emit_result(program, solution, firmware=firmware).text
