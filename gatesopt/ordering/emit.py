"""Re-emit G-code with the curves in the solved order and direction.

Rules (formulations/ordering.md, "Emit"; gatesopt.ordering.build explains the line classes):

- A curve printed as the slicer printed it keeps its lines byte for byte, except the E word in
  absolute-E (M82) files, re-numbered from the cumulative E of the new order. A reversed curve,
  or a loop that starts at another vertex, is written move by move (``G1 X Y E F``; arcs with G2
  and G3 swapped and I/J re-computed from the new start point).
- A gap whose two neighbours are still neighbours (same curves, same ends) is copied as it was:
  the slicer's own retraction, wipe, z-hop, combing path.
- Any other gap is rebuilt the way the slicer builds its travels, with parameters read from the
  file (``TravelStyle``): retract (if the travel is at least the shortest travel the slicer
  retracted for), z-hop, one straight travel, lower, unretract. If the slicer combs (it made
  long travels without retracting), a rebuilt travel that crosses no wall of its layer and is
  no longer than the slicer's own dry travels skips the retraction, as the slicer would
  (``WallCrossing``). Its non-motion lines are kept:
  a boundary gap's lines (layer change, barriers) stay at the boundary in their order; a gap
  inside a group travels with the curve that followed it (minus ``;TYPE:``/wipe comments, which
  are re-derived).
- State every extrusion sees (fan, acceleration, jerk, flow, pressure advance, feature label,
  feedrate) is tracked through the output; before each curve, every value that differs from what
  that curve saw in the original is re-issued with the original line.
- An E-only G92 travels with the next curve (E after it continues from it: E is numbered from the
  output's own running total and the offset each copied G92 sets); a G92 with X/Y/Z is a barrier.
"""
from __future__ import annotations

import bisect
import math
import re
from dataclasses import dataclass

import numpy as np

from .. import verify as _verify
from ..program import MOTION_KINDS, Kind, Program
from ..slicers import WALL_FEATURE
from .build import (LINE_CURVE, LINE_FW_RETRACT, LINE_FW_UNRETRACT, LINE_MOTION, LINE_NEUTRAL,
                    Layout, layout)
from .problem import OrderingProblem, OrderingSolution

_E_WORD = re.compile(r"(?<![A-Za-z_])([Ee])([-+]?\d*\.?\d*)")
_F_WORD = re.compile(r"(?<![A-Za-z_])[Ff]([-+]?\d*\.?\d+)")
_TYPE_OR_WIPE = re.compile(r"^\s*;\s*(TYPE:|FEATURE:|feature |WIPE_START|WIPE_END)", re.I)


def _num(v: float, nd: int) -> str:
    s = ("%.*f" % (nd, v)).rstrip("0").rstrip(".")
    if s[:2] == "0.":
        return s[1:]            # ".5" as PrusaSlicer writes; every firmware reads it
    if s[:3] == "-0.":
        return "-" + s[2:]
    if s in ("-0", "", "-"):
        return "0"
    return s


@dataclass(frozen=True)
class TravelStyle:
    """How the slicer travels, read from its own gaps."""

    retract_mm: float = 0.0         # filament pulled back before a travel
    retract_feed_mm_s: float = 35.0
    unretract_feed_mm_s: float = 35.0
    min_travel_mm: float = np.inf   # shortest travel the slicer retracted for
    hop_mm: float = 0.0             # z-hop height (0: none)
    travel_feed_mm_s: float = 150.0
    z_feed_mm_s: float = 10.0
    travel_cmd: str = "G1"
    #: longest same-layer travel the slicer made without retracting (combing: Cura, ideaMaker,
    #: Creality Print, PrusaSlicer's "only retract when crossing perimeters"); 0: it does not comb
    comb_max_mm: float = 0.0
    #: the slicer retracts with bare G10 / G11 (the firmware's retraction, not E moves)
    firmware_retract: bool = False


#: travels shorter than this say nothing about combing (every slicer skips retracting for them)
COMB_MIN_TRAVEL_MM = 2.0
#: share of long same-layer travels without retraction that marks a combing slicer
COMB_SHARE = 0.2
#: a rebuilt travel is trimmed by this much at each end before the wall-crossing test (its ends
#: are curve ends, which touch walls)
COMB_TRIM_MM = 0.3


def _cross_z(o, v, w):
    """z of (v - o) x (w - o): which side of the line o -> v the point w lies on."""
    return (v[..., 0] - o[..., 0]) * (w[..., 1] - o[..., 1]) - (v[..., 1] - o[..., 1]) * (w[..., 0] - o[..., 0])


class WallCrossing:
    """Does a straight travel cross a wall of its layer? (A combing slicer's reason to retract.)

    Walls: the layer's closed curves and curves whose feature names a wall or perimeter. A travel
    that crosses none of them stays inside one region bounded by walls — over infill, where the
    slicer itself travels without retracting — so it may skip the retraction.
    """

    def __init__(self, program: Program, problem: OrderingProblem, lay: Layout):
        names = program.feature_names
        feat = program.feature[lay.curve_s0]
        is_wall = np.array([f >= 0 and bool(WALL_FEATURE.search(names[f])) for f in feat], bool)
        self.wall = is_wall | problem.curve_closed
        self.problem = problem
        self.cache: dict = {}

    def _segments(self, layer: int):
        seg = self.cache.get(layer)
        if seg is None:
            pr = self.problem
            cs = np.flatnonzero((pr.curve_layer == layer) & self.wall)
            parts = [pr.points_xy[pr.curve_point_start[c]:pr.curve_point_start[c + 1]] for c in cs]
            a = np.concatenate([q[:-1] for q in parts]) if parts else np.zeros((0, 2))
            b = np.concatenate([q[1:] for q in parts]) if parts else np.zeros((0, 2))
            seg = self.cache[layer] = (a, b)
        return seg

    def crosses(self, layer: int, p, q) -> bool:
        p, q = np.asarray(p[:2], float), np.asarray(q[:2], float)
        d = q - p
        length = float(np.hypot(*d))
        if length <= 2 * COMB_TRIM_MM:
            return False
        u = d / length
        p, q = p + COMB_TRIM_MM * u, q - COMB_TRIM_MM * u
        a, b = self._segments(layer)
        if not len(a):
            return False
        lo, hi = np.minimum(p, q), np.maximum(p, q)
        near = ((np.maximum(a, b) >= lo) & (np.minimum(a, b) <= hi)).all(axis=1)
        a, b = a[near], b[near]
        o1, o2 = _cross_z(p, q, a), _cross_z(p, q, b)
        o3, o4 = _cross_z(a, b, p), _cross_z(a, b, q)
        return bool(np.any((o1 * o2 <= 0) & (o3 * o4 <= 0) & ((o1 != 0) | (o2 != 0))))


def travel_style(program: Program, lay: Layout) -> TravelStyle:
    """Median retraction, z-hop and speeds over the file's gaps between curves."""
    kind, d = program.kind, program.delta_mm
    n = len(lay.curve_s0)
    if n < 2:
        return TravelStyle()
    g0 = lay.curve_s1[:-1]          # gap steps [g0, g1)
    g1 = lay.curve_s0[1:]
    retr = np.zeros(len(g0))
    hop = np.zeros(len(g0))
    xy_len = np.hypot(*(program.start_mm[g1, :2] - program.end_mm[g0 - 1, :2]).T)
    retract_rows = (d[:, 3] < 0)
    cum_r = np.concatenate(([0.0], np.cumsum(np.where(retract_rows, -d[:, 3], 0.0))))
    retr = cum_r[g1] - cum_r[g0]
    # gaps with a firmware retraction (bare G10 between the two curves' lines)
    cum_fw = np.concatenate(([0], np.cumsum(lay.line_class == LINE_FW_RETRACT)))
    fw = (cum_fw[lay.curve_l0[1:]] - cum_fw[lay.curve_l1[:-1] + 1]) > 0
    z_end = program.end_mm[:, 2]
    # z-hop: highest Z inside the gap above the next curve's Z (gaps within one layer only)
    same_layer = program.layer[g0 - 1] == program.layer[g1]
    has_e = retr > 1e-6
    has_r = has_e | fw
    for i in np.flatnonzero(has_r & same_layer)[:2000]:
        if g1[i] > g0[i]:
            hop[i] = z_end[g0[i]:g1[i]].max() - program.start_mm[g1[i], 2]
    style = {}
    if has_r.any():
        if has_e.any():
            style["retract_mm"] = float(np.median(retr[has_e]))
        style["firmware_retract"] = bool(fw.sum() > has_e.sum())
        internal = has_r & same_layer
        style["min_travel_mm"] = float(xy_len[internal].min()) if internal.any() else 1.0
        hops = hop[has_r & same_layer]
        if len(hops) and np.mean(hops > 1e-3) >= 0.5:
            style["hop_mm"] = float(np.median(hops[hops > 1e-3]))
        # combing: a fair share of the travels at least as long as a retracted one went without
        long_ = same_layer & (xy_len >= max(style["min_travel_mm"], COMB_MIN_TRAVEL_MM))
        combed = long_ & ~has_r
        if long_.sum() >= 10 and combed.sum() >= COMB_SHARE * long_.sum():
            style["comb_max_mm"] = float(np.percentile(xy_len[combed], 95))
    rr = (kind == Kind.RETRACT) & (np.hypot(d[:, 0], d[:, 1]) == 0)
    if rr.any():
        style["retract_feed_mm_s"] = float(np.median(program.feed_mm_s[rr]))
    ur = kind == Kind.UNRETRACT
    if ur.any():
        style["unretract_feed_mm_s"] = float(np.median(program.feed_mm_s[ur]))
    tr = (kind == Kind.TRAVEL) & (program.length_mm > 1.0)
    if tr.any():
        style["travel_feed_mm_s"] = float(np.median(program.feed_mm_s[tr]))
        lines = program.line[np.flatnonzero(tr)[:5000]]
        g0_share = np.mean(program.line_number[lines] == 0)
        style["travel_cmd"] = "G0" if g0_share > 0.5 else "G1"
    zr = kind == Kind.Z_ONLY
    if zr.any():
        style["z_feed_mm_s"] = float(np.median(program.feed_mm_s[zr]))
    return TravelStyle(**style)


class _Writer:
    """Output text plus the machine state the output has reached."""

    def __init__(self, program: Program, lay: Layout, lists: tuple | None = None):
        self.p, self.lay = program, lay
        self.nl = program.line_ending
        self.out: list[str] = []
        self.e = 0.0            # cumulative machine E of the output
        self.e_off = 0.0        # logical E = machine E - e_off (absolute-E mode)
        self.xyz = np.zeros(3)
        self.feed = None        # mm/s in force
        self.state: dict = {}
        self.feature = None
        (self.line_cls, self.line_step, self.line_de, self.line_travel, self.step_relative_e,
         self.step_feed, self.step_logical_e, self.step_end_xyz, self.layer_lines, self.arc_steps,
         self.command_lines, self.command_set, self.step_moves) = lists or self.per_line(program, lay)
        # neutral commands written so far: the k-th one written is the original's k-th (below)
        self.n_commands = 0

    @staticmethod
    def per_line(program: Program, lay: Layout) -> tuple:
        """Per line, what the gap rebuild asks of it, as Python lists (numpy scalar indexing line
        by line was ~40 % of the emit); the same for every emit of one program and problem."""
        cls, step = lay.line_class, lay.step_of_line
        # neutral commands (M73, M117), in order: a curve written move by move keeps its own
        commands = np.flatnonzero((program.line_letter == ord("M")) & (cls == LINE_NEUTRAL)).tolist()
        has = step >= 0
        motion = (cls == LINE_MOTION) & has
        s = np.where(has, step, 0)
        return (cls.tolist(), step.tolist(),
                np.where(has, program.end_mm[s, 3] - program.start_mm[s, 3], 0.0).tolist(),
                (motion & np.isin(program.kind[s], _TRAVEL_KINDS)).tolist(),
                program.relative_e.tolist(), program.feed_mm_s.tolist(),
                (program.end_mm[:, 3] - program.offset_mm[:, 3]).tolist(),
                np.ascontiguousarray(program.end_mm[:, :3]),    # rows are views: never written
                frozenset(program.layer_line.tolist()),
                frozenset(np.flatnonzero(program.kind == Kind.ARC).tolist()),
                commands, frozenset(commands),
                np.isin(program.kind, MOTION_KINDS).tolist())

    # -- copying original lines -------------------------------------------------------------
    def copy_line(self, i: int) -> None:
        p = self.p
        if i in self.command_set:
            # progress (M73) and messages (M117) travel with the next curve, so a re-ordered
            # layer would write them in another order: printers would show progress stepping
            # back. Written in the original's order instead (verify checks it): the k-th neutral
            # command written is the original's k-th, whichever curve carries it
            i = self.command_lines[self.n_commands]
            self.n_commands += 1
        text = p.line_text(i)
        s = self.line_step[i]
        cls = self.line_cls[i]
        if s >= 0:
            new_e = self.e + self.line_de[i]
            # only a move's E word is a position to re-number: a motor line's bare 'E' (Cura's
            # closing 'M84 X Y E') names the extruder motor, and writing a number there made it
            # an 'M84 ... E450.1' that verify read as an added gating line
            if not self.step_relative_e[s] and self.step_moves[s]:
                want = new_e - self.e_off
                if abs(want - self.step_logical_e[s]) > 1e-7:
                    code, sep, comment = text.partition(";")
                    m = _E_WORD.search(code)
                    if m:
                        code = code[:m.start(2)] + _num(want, 6) + code[m.end(2):]
                        text = code + sep + comment
            self.e = new_e
            self.xyz = self.step_end_xyz[s]     # replaced, never written in place
            self.feed = self.step_feed[s]
        else:
            code = text.split(";")[0].strip().upper()
            if code.startswith("G92"):
                m = _E_WORD.search(code[3:])
                if m and m.group(2):
                    self.e_off = self.e - float(m.group(2))
                elif code == "G92":
                    self.e_off = self.e
            elif cls == LINE_NEUTRAL and code[:2] in ("G0", "G1"):
                m = _F_WORD.search(code)
                if m:
                    self.feed = float(m.group(1)) / 60.0
            # a state line (the first of its key is a barrier, and still sets state)
            key = self.lay.state_key.get(i)
            if key is not None:
                self.state[key] = text.rstrip("\r\n")
            elif cls == LINE_NEUTRAL and not code:
                name = _feature_of_comment(text, self.lay.feature_prefix)
                if name is not None:
                    self.feature = name
        if not text.endswith("\n"):
            text += self.nl
        self.out.append(text)

    def copy_steps(self, l0: int, l1: int, b0: int, b1: int) -> bool:
        """Lines l0..l1, each an extruding step (bytes b0:b1 of the file), verbatim in one piece,
        with what ``copy_line`` line by line would leave behind; False (nothing written) where
        an E word would be re-numbered. In an absolute-E file every line of the block is off
        by what its first line is off (the block's own E deltas are the original's, rounding
        ~1e-12 mm apart), so a first line within 1e-8 mm of the original is a block whose
        every line ``copy_line`` keeps (it re-numbers beyond 1e-7)."""
        s0 = self.line_step[l0]
        if (not self.step_relative_e[s0]
                and abs(self.e + self.line_de[l0] - self.e_off - self.step_logical_e[s0]) > 1e-8):
            return False
        e = self.e
        for d in self.line_de[l0:l1 + 1]:      # summed in copy_line's order: the same float
            e += d
        self.e = e
        s1 = self.line_step[l1]
        self.xyz, self.feed = self.step_end_xyz[s1], self.step_feed[s1]
        self.out.append(self.p.data[b0:b1].decode("utf-8", "surrogateescape"))
        return True

    def write(self, text: str) -> None:
        self.out.append(text + self.nl)

    def reissue(self, states: list, k: int) -> None:
        """Write each state line ``states`` (``_states_at``) holds at its k-th place that is not
        what the output has in force."""
        for key, texts in states:
            text = texts[k]
            if text is not None and self.state.get(key) != text:
                self.write(text)
                self.state[key] = text

    # -- the per-layer memo of ``emit`` -----------------------------------------------------------
    def entry_key(self) -> tuple:
        """What a layer's text depends on besides its own curves (E apart: ``_same_entry``)."""
        return (tuple(self.xyz.tolist()), self.feed, tuple(sorted(self.state.items())),
                self.feature, self.n_commands, self.e - self.e_off, self.e, self.e_off)

    def snapshot(self) -> tuple:
        """The state a memoized layer leaves behind (``extend_from`` takes it)."""
        return (self.e, self.e_off, self.xyz.copy(), self.feed, dict(self.state), self.feature,
                self.n_commands)

    def extend_from(self, entry: tuple, chunk: list, exit_: tuple) -> None:
        """Append a memoized layer's text and take its exit state; E moves with the difference
        between this entry and the memoized one (logical E agrees within MEMO_E_TOL_MM)."""
        self.out.extend(chunk)
        d_e, d_off = self.e - entry[6], self.e_off - entry[7]
        e, e_off, xyz, feed, state, feature, self.n_commands = exit_
        self.e, self.e_off = e + d_e, e_off + d_off
        self.xyz, self.feed, self.state, self.feature = xyz.copy(), feed, dict(state), feature

    # -- new moves ------------------------------------------------------------------------------
    def _f(self, feed_mm_s: float) -> str:
        if self.feed is not None and abs(self.feed - feed_mm_s) < 1e-9:
            return ""
        self.feed = feed_mm_s
        return f" F{_num(feed_mm_s * 60.0, 3)}"

    def move_e(self, d_e: float, feed_mm_s: float, relative: bool) -> None:
        self.e += d_e
        val = d_e if relative else self.e - self.e_off
        self.write(f"G1 E{_num(val, 6)}{self._f(feed_mm_s)}")

    def move_xyz(self, xyz, feed_mm_s: float, cmd: str, offset) -> None:
        # plain floats: numpy scalar arithmetic, three axes per travel, was a tenth of the emit
        new = [float(v) for v in xyz]
        cur, off = self.xyz.tolist(), offset.tolist()
        words = ""
        for ax, k in (("X", 0), ("Y", 1), ("Z", 2)):
            if abs(new[k] - cur[k]) > 1e-9:
                words += f" {ax}{_num(new[k] - off[k], 5)}"
        if words:
            self.write(f"{cmd}{words}{self._f(feed_mm_s)}")
            self.xyz = np.array(new)

    def step(self, s: int, reverse: bool) -> None:
        """One extruding step of the original, forwards or backwards, as a new line."""
        p = self.p
        a, b = (p.end_mm[s], p.start_mm[s]) if reverse else (p.start_mm[s], p.end_mm[s])
        off = p.offset_mm[s]
        d_e = p.end_mm[s, 3] - p.start_mm[s, 3]
        self.e += d_e
        e_val = d_e if p.relative_e[s] else self.e - self.e_off
        if s in self.arc_steps:
            ccw = bool(p.arc_ccw[s]) != reverse
            c = p.arc_center_mm[s]
            cmd = "G3" if ccw else "G2"
            words = f" X{_num(b[0] - off[0], 5)} Y{_num(b[1] - off[1], 5)}"
            if abs(b[2] - a[2]) > 1e-9:
                words += f" Z{_num(b[2] - off[2], 5)}"
            words += f" I{_num(c[0] - a[0], 5)} J{_num(c[1] - a[1], 5)}"
        else:
            cmd = "G1"
            words = ""
            for ax, k in (("X", 0), ("Y", 1), ("Z", 2)):
                if abs(b[k] - a[k]) > 1e-12 or (k < 2 and abs(b[k] - self.xyz[k]) > 1e-9):
                    words += f" {ax}{_num(b[k] - off[k], 5)}"
        self.write(f"{cmd}{words} E{_num(e_val, 6)}{self._f(float(p.feed_mm_s[s]))}")
        self.xyz = b[:3].copy()


def _feature_of_comment(text: str, prefix: str):
    t = text.strip()
    pre = prefix.strip()
    if pre and t.startswith(pre):
        return t[len(pre):].strip()
    return None


def _required_state(program: Program, lay: Layout):
    """key -> (sorted state lines, their texts): what was in force at any line."""
    by_key: dict = {}
    for i in sorted(lay.state_key):
        by_key.setdefault(lay.state_key[i], []).append(i)
    out = {}
    for k, lines in by_key.items():
        arr = np.asarray(lines, np.int64)
        out[k] = (arr, [program.line_text(int(i)).rstrip("\r\n") for i in arr])
    return out


def _states_at(req, lines) -> list:
    """Per state key (in ``req``'s order), the text in force at each of ``lines``: the key's last
    line before it, None before its first."""
    out = []
    for key, (arr, texts) in req.items():
        opts = [None] + texts
        out.append((key, [opts[j] for j in np.searchsorted(arr, lines, side="left").tolist()]))
    return out


def emit(program: Program, problem: OrderingProblem, solution: OrderingSolution,
         memo: dict | None = None) -> str:
    """G-code text with the curves of ``problem`` in the order of ``solution``.

    ``memo``: a dict kept between calls on the same program and problem (the time guard emits
    again after putting a few layers back, ``rewrite.order.emit_guarded``). A layer whose curves, in
    the same order and directions, are entered from the same state (previous curve, position,
    feedrate, state lines, feature, E up to ``MEMO_E_TOL_MM``) gets the text it got before; E
    words differ from a fresh emit by at most that tolerance, where rounding tips a last digit."""
    program.check_rewritable()
    lay = problem.layout if problem.layout is not None else layout(program)
    p = program
    n = len(lay.curve_s0)
    if n == 0:
        return program.to_gcode()
    order = np.asarray(solution.curve_order, np.int64)
    rev = np.asarray(solution.curve_reversed, bool)
    seam = np.asarray(solution.curve_seam, np.int64)
    if len(order) != n or not np.array_equal(np.sort(order), np.arange(n)):
        raise ValueError("solution does not order every curve of the program exactly once")
    # what depends on the program and problem only (travel style, walls and their per-layer
    # segments, per-line and per-curve lists) is made once per memo, not once per guard pass
    fixed = memo.get(_FIXED) if memo is not None else None
    if fixed is None:
        style = travel_style(program, lay)
        walls = WallCrossing(program, problem, lay) if style.comb_max_mm > 0 else None
        fixed = (style, walls, _Writer.per_line(program, lay), _Plan.per_curve(p, problem, lay))
        if memo is not None:
            memo[_FIXED] = fixed
    style, walls, lists, per_curve = fixed
    w = _Writer(program, lay, lists)
    plan = _Plan(p, lay, style, walls, order, rev, seam, per_curve)
    changed, gap_lines = plan.changed, plan.gap_lines

    # prefix + first gap: verbatim (the first layer keeps its order, so curve 0 stays first)
    prev = -1
    for i in gap_lines(order[0]) if order[0] == 0 else gap_lines(0):
        w.copy_line(i)
    # one block of the order per layer (a layer's curves are contiguous in any solution)
    lay_of = problem.curve_layer[order]
    cuts = np.flatnonzero(np.diff(lay_of)) + 1
    starts, ends = np.concatenate(([0], cuts)), np.concatenate((cuts, [n]))
    for k0, k1 in zip(starts.tolist(), ends.tolist()):
        key = None
        if memo is not None:
            blk = order[k0:k1]
            key = (int(lay_of[k0]), prev, bool(changed[prev]) if prev >= 0 else False,
                   blk.tobytes(), rev[blk].tobytes(), seam[blk].tobytes(), w.entry_key())
            hit = memo.get(key[:-1])
            if hit is not None and _same_entry(hit[0], key[-1]):
                w.extend_from(hit[0], hit[1], hit[2])
                prev = int(order[k1 - 1])
                continue
            start = len(w.out)
        for k in range(k0, k1):
            prev = _emit_curve(plan, w, k, prev)
        if key is not None:
            memo[key[:-1]] = (key[-1], w.out[start:], w.snapshot())
    # state the remainder of the file expects, then the remainder verbatim
    last = plan.l1[n - 1]
    w.reissue(_states_at(plan.req, [last + 1]), 0)
    for i in range(last + 1, p.n_lines):
        w.copy_line(i)
    text = "".join(w.out)
    if p.n_lines and not p.data.endswith(b"\n") and text.endswith(w.nl):
        # the file ends without a line ending (FullControl's closing "M84 ; disable steppers"):
        # so does the output. ``copy_line`` ends every line, for the lines a re-ordering moves;
        # the added one made the original's last line differ from its copy byte for byte
        text = text[:-len(w.nl)]
    if text != p.to_gcode():
        # says what this file is to ``gatesopt verify ORIG OUT``: a re-ordering, checked curve
        # by curve, even where no curve visibly moved (kept order, rebuilt travels)
        text = ORDER_HEADER + w.nl + text
    return text


#: the first line of a re-ordered file (``gatesopt.verify.ORDER_PREFIX`` reads it)
ORDER_HEADER = _verify.ORDER_PREFIX

_FIXED = "fixed"                # the memo's entry for what every emit of the program shares

#: a memoized layer is reused when its entry's logical E (absolute-E files) differs by at most
#: this: re-ordered layers sum the same E in another order, so E at the next layer's start drifts
#: by ~1e-12 mm; the output writes E with 6 decimals
MEMO_E_TOL_MM = 1e-7


def _same_entry(memo_entry: tuple, entry: tuple) -> bool:
    return memo_entry[:5] == entry[:5] and abs(memo_entry[5] - entry[5]) <= MEMO_E_TOL_MM


class _Plan:
    """What ``emit`` knows about the file and the solution, per curve as Python lists (numpy
    scalar indexing curve by curve was a fifth of the emit)."""

    def __init__(self, p: Program, lay: Layout, style: TravelStyle, walls, order, rev, seam,
                 per_curve: tuple):
        self.p, self.lay, self.style, self.walls = p, lay, style, walls
        self.order, self.rev, self.seam = order.tolist(), rev.tolist(), seam.tolist()
        self.changed = (rev | (seam != 0)).tolist()
        (self.group_first, self.layer, self.l0, self.l1, self.feature, self.req,
         self.curve_state, self.block) = per_curve

    @staticmethod
    def per_curve(p: Program, problem: OrderingProblem, lay: Layout) -> tuple:
        """What does not depend on the order: each curve's group's original first curve, layer,
        first and last line, feature, the state lines in force at any line and, per state key,
        the text in force at each curve's first line (``_states_at``)."""
        gidx = np.repeat(np.arange(problem.n_groups), np.diff(problem.group_curve_start))
        req = _required_state(p, lay)
        curve_state = _states_at(req, lay.curve_l0)
        # a curve whose lines are all extruding steps, not the file's last line, is copied in
        # one piece when unchanged (``_Writer.copy_steps``): (first byte, end byte), else None
        steps_before = np.concatenate(([0], np.cumsum(lay.step_of_line >= 0)))
        l0, l1 = lay.curve_l0, lay.curve_l1
        whole = ((steps_before[l1 + 1] - steps_before[l0] == l1 - l0 + 1)
                 & (l1 + 1 < p.n_lines)).tolist()
        block = [(b0, b1) if ok else None for ok, b0, b1 in
                 zip(whole, p.line_start[l0].tolist(), p.line_start[l1 + 1].tolist())]
        return (problem.group_curve_start[gidx].tolist(), problem.curve_layer.tolist(),
                l0.tolist(), l1.tolist(), p.feature[lay.curve_s0].tolist(), req, curve_state,
                block)

    def gap_lines(self, c: int) -> range:
        """The original lines between curve c - 1 and curve c."""
        return range(self.l1[c - 1] + 1 if c > 0 else 0, self.l0[c])


def _emit_curve(plan: _Plan, w: _Writer, k: int, prev: int) -> int:
    """The k-th curve of the new order with the gap before it; returns that curve."""
    p, lay = plan.p, plan.lay
    c = plan.order[k]
    if k > 0:
        if prev == c - 1 and not plan.changed[prev] and not plan.changed[c]:
            for i in plan.gap_lines(c):
                w.copy_line(i)
        else:
            lines = []
            first = plan.group_first[c]
            if first != plan.group_first[prev]:             # crossing into c's group
                lines.append((plan.gap_lines(first), True))
                if c != first:
                    lines.append((plan.gap_lines(c), False))
            elif c != first:
                lines.append((plan.gap_lines(c), False))
            _rebuilt_gap(w, p, lay, plan.style, lines, c,
                         _entry_mm(p, lay, c, plan.rev[c], plan.seam[c]), plan.walls, plan.layer[c])
    w.reissue(plan.curve_state, c)      # state the curve saw in the original
    fi = plan.feature[c]
    if fi >= 0 and w.feature != p.feature_names[fi]:
        w.write(f"{lay.feature_prefix}{p.feature_names[fi]}")
        w.feature = p.feature_names[fi]
    _curve(w, p, lay, c, plan.rev[c], plan.seam[c], plan.block[c])
    return c


def _curve(w: _Writer, p: Program, lay: Layout, c: int, reverse: bool, seam: int,
           block=None) -> None:
    a, b = int(lay.curve_s0[c]), int(lay.curve_s1[c])
    if not reverse and seam == 0:
        if w.feed is None or abs(w.feed - p.feed_mm_s[a]) > 1e-9:
            # the first move may rely on a modal F set before it: set it explicitly
            if not _F_WORD.search(p.line_text(int(p.line[a])).split(";")[0]):
                w.write(f"G1 F{_num(p.feed_mm_s[a] * 60.0, 3)}")
                w.feed = float(p.feed_mm_s[a])
        l0, l1 = int(lay.curve_l0[c]), int(lay.curve_l1[c])
        if block is not None and w.copy_steps(l0, l1, *block):
            return
        for i in range(l0, l1 + 1):
            w.copy_line(i)
        return
    # neutral commands inside the curve (progress M73, messages M117) are not moves: written
    # move by move the curve would lose them, so they go first, in their order
    cmd = w.command_lines
    for k in range(bisect.bisect_right(cmd, int(lay.curve_l0[c])),
                   bisect.bisect_left(cmd, int(lay.curve_l1[c]))):
        w.copy_line(cmd[k])
    steps = range(b - 1, a - 1, -1) if reverse else list(range(a + seam, b)) + list(range(a, a + seam))
    for s in steps:
        w.step(s, reverse)


_TRAVEL_KINDS = (int(Kind.TRAVEL), int(Kind.ARC))     # plain ints: an enum lookup per line is slow


def _entry_mm(p: Program, lay: Layout, c: int, reverse: bool, seam: int) -> np.ndarray:
    """XYZ where curve c starts when printed ``reverse``d / from vertex ``seam``."""
    if reverse:
        return p.end_mm[int(lay.curve_s1[c]) - 1, :3]
    return p.start_mm[int(lay.curve_s0[c]) + seam, :3]


def _rebuilt_gap(w: _Writer, p: Program, lay: Layout, style: TravelStyle, line_sets, c: int,
                 target, walls: WallCrossing | None = None, layer: int = -1) -> None:
    """One rebuilt travel into curve c, with the non-motion lines of the given original gaps.

    Each gap's lines split where the slicer retracted, travelled and unretracted: lines before
    its first retraction come before ours, lines after its last travel after our travel, lines
    after its unretraction after ours. The filament
    the consumed gaps pulled back and pushed forward is kept: the retraction length is the
    slicer's own for this gap (else the file's median), and the net E of the consumed gaps is
    unchanged, so E per layer (and across a layer change) stays what it was.
    """
    pre, mid, post, late = [], [], [], []
    boundary_retracted = early_push = False
    # firmware retraction (bare G10 / G11): rebuilt as one G10 before our travel and one G11
    # after it, unless the consumed gaps do not end as retracted as they began (then copied)
    fw_lines, fw_net, fw_boundary, fw_retracted = set(), 0, False, False
    r_boundary = r_internal = 0.0
    net = 0.0
    cls_of, de_of, travel_of = w.line_cls, w.line_de, w.line_travel
    gap: list[int] = []
    for lines, boundary in line_sets:
        lines = list(lines)
        gap += lines
        cls = [cls_of[i] for i in lines]
        travel_pos = [j for j, i in enumerate(lines) if travel_of[i]]
        retract_pos = [j for j, i in enumerate(lines)
                       if (cls[j] == LINE_MOTION and de_of[i] < 0) or cls[j] == LINE_FW_RETRACT]
        split_t = travel_pos[-1] if travel_pos else len(lines)
        split_r = min(retract_pos[0], split_t) if retract_pos else split_t
        push_pos = [j for j, i in enumerate(lines)
                    if (cls[j] == LINE_MOTION and de_of[i] > 0) or cls[j] == LINE_FW_UNRETRACT]
        split_u = push_pos[-1] if push_pos else len(lines)
        if boundary and push_pos and push_pos[-1] < split_t:
            early_push = True           # the slicer unretracted before its last travel
        for j, i in enumerate(lines):
            if cls[j] == LINE_MOTION:
                d_e = de_of[i]
                net += d_e
                if d_e < 0:
                    if boundary:
                        boundary_retracted = True
                        r_boundary -= d_e
                    else:
                        r_internal -= d_e
                continue
            if cls[j] == LINE_CURVE:
                continue
            if cls[j] == LINE_FW_RETRACT or cls[j] == LINE_FW_UNRETRACT:
                fw_lines.add(i)
                if cls[j] == LINE_FW_RETRACT:
                    fw_net -= 1
                    fw_retracted = True
                    fw_boundary = fw_boundary or boundary
                else:
                    fw_net += 1
            if not boundary and cls[j] == LINE_NEUTRAL and _TYPE_OR_WIPE.match(p.line_text(i)):
                continue
            (pre if j < split_r else mid if j < split_t else post if j < split_u else late).append(i)
    use_fw = fw_net == 0 and (fw_retracted or (
        style.firmware_retract and r_boundary <= 0 and r_internal <= 0))
    if use_fw and fw_lines:
        pre, mid, post, late = ([i for i in b if i not in fw_lines] for b in (pre, mid, post, late))
    s = int(lay.curve_s0[c])
    off = p.offset_mm[s]
    relative_e = bool(p.relative_e[s])
    # E per layer must not change: where a layer's first line lies inside these gaps, what this
    # gap has emitted when that line is copied must equal what the slicer's gap lines before it
    # moved (net_before)
    net_before = {}
    markers = [i for i in gap if i in w.layer_lines]
    if markers:
        mot = [i for i in gap if cls_of[i] == LINE_MOTION]
        de = np.asarray([de_of[i] for i in mot], float)
        mot = np.asarray(mot, np.int64)
        net_before = {m: float(de[mot < m].sum()) for m in markers}
    emitted = 0.0

    def move_e(d_e: float, feed_mm_s: float = style.unretract_feed_mm_s) -> None:
        nonlocal emitted
        w.move_e(d_e, feed_mm_s, relative_e)
        emitted += d_e

    def copy(i: int) -> None:
        if i in net_before and abs(net_before[i] - emitted) > 1e-9:
            move_e(net_before[i] - emitted)
        w.copy_line(i)

    for i in pre:
        copy(i)
    (tx, ty, tz), (x0, y0, z0) = target.tolist(), w.xyz.tolist()
    dist = math.hypot(tx - x0, ty - y0)
    moving = dist > 1e-9 or abs(tz - z0) > 1e-9
    r = r_boundary if r_boundary > 0 else (r_internal if r_internal > 0 else style.retract_mm)
    if use_fw:
        retract = moving and (fw_boundary or (style.firmware_retract and dist >= style.min_travel_mm))
    else:
        retract = moving and r > 0 and (boundary_retracted
                                        or (style.retract_mm > 0 and dist >= style.min_travel_mm))
    if (retract and walls is not None and dist <= style.comb_max_mm
            and abs(target[2] - w.xyz[2]) <= 1e-9 and not walls.crosses(layer, w.xyz, target)):
        retract = False     # the slicer combs: a travel over infill that crosses no wall goes dry
    if retract and use_fw:
        w.write("G10")
    elif retract:
        move_e(-r, style.retract_feed_mm_s)
    for i in mid:
        copy(i)
    if moving:
        x_now, y_now, z_now = w.xyz.tolist()
        z_to = tz
        if retract and style.hop_mm > 0:
            z_up = max(z_now, z_to) + style.hop_mm
        else:
            z_up = max(z_now, z_to)
        if z_up > z_now + 1e-9:
            w.move_xyz([x_now, y_now, z_up], style.z_feed_mm_s, "G1", off)
        z_now = float(w.xyz[2])
        w.move_xyz([tx, ty, z_now], style.travel_feed_mm_s, style.travel_cmd, off)
        if abs(z_now - z_to) > 1e-9:
            w.move_xyz([tx, ty, z_to], style.z_feed_mm_s, "G1", off)
    # unretract, plus any prime the slicer's gaps added: whatever brings the gap to its net E
    if (early_push or not boundary_retracted) and abs(net - emitted) > 1e-9:
        # a retraction the slicer did not make here: undo it at once, on this side of any marker
        move_e(net - emitted)
    for i in post:                      # e.g. the next layer's marker: before the unretract, as the slicer
        copy(i)
    if retract and use_fw:
        w.write("G11")
    if abs(net - emitted) > 1e-9:
        move_e(net - emitted)
    for i in late:
        copy(i)
