"""The output text of a re-ordering and the machine state it has reached (``Writer``): original
lines copied (E re-numbered in absolute-E files, state tracked), new moves written in the file's
own number format, state lines re-issued where a curve would see another value than in the
original (formulations/ordering.md, "Emit").
"""
from __future__ import annotations

import bisect
import functools
import operator
import re
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..program import MOTION_KINDS, Kind, Program
from .layout import LINE_MOTION, LINE_NEUTRAL, Layout

E_WORD = re.compile(r"(?<![A-Za-z_])([Ee])([-+]?\d*\.?\d*)")
F_WORD = re.compile(r"(?<![A-Za-z_])[Ff]([-+]?\d*\.?\d+)")
#: step kinds whose line is a travel the gap rebuild replaces (plain ints: an enum lookup per
#: line is slow)
TRAVEL_KINDS = (int(Kind.TRAVEL), int(Kind.ARC))


def marker_moves(program: Program, lay: Layout) -> frozenset:
    """Moves in gaps that carry their layer's marker after the G-code (``slicers.TRAILING``:
    Slic3r's verbose ``G1 Z1.000 F7800.000 ; move to next layer (4)``), where the file's layers
    come from markers. A rebuilt travel replaces such a move and must keep its marker: the output
    is read by the same markers (verify, slicer previews, layer-based post-processors), and
    without them its layers merge (Slic3r 1.3 with gcode_comments and retract_lift: layer 4's
    walls printed in "layer 3", refused by verify)."""
    if not program.layer_method.startswith("marker:"):
        return frozenset()
    lines = np.asarray(sorted(set(program.layer_line.tolist())), np.int64)
    lines = lines[(lines >= 0) & (lines < program.n_lines)]
    moves = lines[(lay.step_of_line[lines] >= 0) & (lay.line_class[lines] == LINE_MOTION)]
    return frozenset(i for i in moves.tolist() if b";" in program.data[
        program.line_start[i]:program.line_start[i + 1]])


def gcode_number(v: float, nd: int) -> str:
    """``v`` with at most ``nd`` decimals, as slicers write numbers (no trailing zeros, ".5")."""
    return _short(("%.*f" % (nd, v)).rstrip("0").rstrip("."))


def _short(s: str) -> str:
    """A number written with its trailing zeros and point dropped, as ``gcode_number`` returns it."""
    head = s[:1]
    if head == "0":
        # ".5" as PrusaSlicer writes; every firmware reads it
        return s[1:] if s[1:2] == "." else s
    if head == "-":
        if s[1:3] == "0.":
            return "-" + s[2:]
        return "0" if s in ("-0", "-") else s
    return s or "0"



@dataclass(frozen=True, eq=False)
class PerLine:
    """Per line of a program, what copying it asks (``Writer.per_line``), as Python lists (numpy
    scalar indexing line by line was ~40 % of the emit); the same for every emit of one program
    and problem, so the time guard's emits share it (``emitter.emit``'s memo)."""

    line_cls: list          # layout class
    line_step: list         # its step, -1 for none
    line_de: list           # its step's E delta (0.0 for none)
    line_travel: list       # a travel the gap rebuild replaces
    step_relative_e: list   # per step: M83 in force
    step_feed: list         # per step: mm/s
    step_logical_e: list    # per step: E the original's E word says at its end
    step_end_xyz: np.ndarray    # (n_steps, 3): rows are views, never written
    layer_lines: frozenset
    arc_steps: frozenset
    command_lines: list     # neutral commands (M73, M117) in order: a moved curve keeps its own
    command_set: frozenset
    step_moves: list        # per step: a motion kind (only a move's E word is a position)
    texts: list             # each line with its ending
    text: str | None        # the whole file, where a character is a byte (ASCII): a run of lines
    #                         is one slice of it
    line_start: list        # offsets of the lines in ``text`` (n_lines + 1)
    effects: dict           # line (not a step) -> ``LineEffect`` where copying it sets any state
    special: list           # sorted lines ``copy_lines`` hands to ``copy_line`` (not a step, a
    #                         neutral command, the last line without its ending) + [n_lines]
    renumber_before: list   # lines before i whose E word may be re-numbered (absolute-E moves)
    line_logical_e: list    # per line: its step's ``step_logical_e`` (0.0 for none)
    block_end: list         # per line: l1 where an absolute-E curve l0..l1 of extruding steps
    #                         starts (``copy_lines``' one-piece test), else -1
    e_split: dict           # per line whose E word was re-numbered: its text around the number
    marker_moves: frozenset = frozenset()   # ``marker_moves``: moves carrying a layer marker


class LineEffect(NamedTuple):
    """What copying a line that is not a step sets (``Writer.copy_line``): E's origin (a G92:
    logical E := ``g92_e``), the feed (a neutral G0/G1 with F only), a state line's key and text,
    a feature comment's name; None where it sets nothing of that."""

    g92_e: float | None
    feed_mm_s: float | None
    state: tuple | None
    feature: str | None


def _may_set_state(program: Program, lay: Layout, steps: np.ndarray) -> list:
    """The lines, not steps, whose ``line_effect`` may be one: state lines and lines holding a
    'G' or 'g' (G92, a G0/G1 with F) or the feature prefix (a label); the others set nothing
    (most lines that are not steps are comments: each looked at was a third of the lists' time).
    Bytes of the file: a 'G' or the prefix's ASCII is never part of a UTF-8 character."""
    data = np.frombuffer(program.data, np.uint8)
    at = [np.flatnonzero((data == ord("G")) | (data == ord("g")))]
    pre = lay.feature_prefix.strip().encode("utf-8", "surrogateescape")
    if pre:
        at.append(np.asarray([m.start() for m in re.finditer(re.escape(pre), program.data)], np.int64))
    hit = np.zeros(program.n_lines, bool)
    for pos in at:
        hit[np.searchsorted(program.line_start, pos, side="right") - 1] = True
    hit[list(lay.state_key)] = True
    return np.flatnonzero(hit & ~steps).tolist()


def line_effect(text: str, cls: int, key, prefix: str) -> LineEffect | None:
    """``LineEffect`` of a line that is not a step; None where it sets nothing."""
    if text[:1] == ";" and key is None:
        # a comment (most lines that are not steps): a feature label at most
        name = feature_of_comment(text, prefix) if cls == LINE_NEUTRAL else None
        return None if name is None else LineEffect(None, None, None, name)
    code = text.split(";")[0].strip().upper()
    g92 = feed = feature = None
    if code.startswith("G92"):
        m = E_WORD.search(code[3:])
        if m and m.group(2):
            g92 = float(m.group(2))
        elif code == "G92":
            g92 = 0.0
    elif cls == LINE_NEUTRAL and code[:2] in ("G0", "G1"):
        m = F_WORD.search(code)
        if m:
            feed = float(m.group(1)) / 60.0
    # a state line (the first of its key is a barrier, and still sets state)
    state = (key, text.rstrip("\r\n")) if key is not None else None
    if key is None and cls == LINE_NEUTRAL and not code:
        feature = feature_of_comment(text, prefix)
    if g92 is None and feed is None and state is None and feature is None:
        return None
    return LineEffect(g92, feed, state, feature)


def gcode_numbers(values: np.ndarray, nd: int) -> list[str]:
    """``gcode_number(v, nd)`` of each of ``values`` (float64; ``nd`` >= 1), made at once: one
    formatting of them all, then only numbers under 1 looked at one by one ("0." -> ".")."""
    if not len(values):
        return []
    parts = ((f"%.{nd}f\n" * len(values)) % tuple(values.tolist())).split("\n")
    parts.pop()
    out = [x.rstrip("0").rstrip(".") for x in parts]
    for i in np.flatnonzero(~(np.abs(values) >= 1.0)).tolist():
        out[i] = _short(out[i])
    return out


@dataclass(frozen=True, eq=False)
class CurveMoves:
    """The steps of the curves an emit writes move by move (printed backwards or from another
    vertex: ``Writer.steps``), in the order it writes them, with what does not depend on where
    the output is (each move's ends, its X Y Z words, its E and, where E is relative, its E
    word): made for all of them at once (numpy scalars, a call per number and numpy per curve
    were most of a re-ordered layer's emit)."""

    steps: list         # per move: its step
    a_xyz: list         # per move 3: where it starts (x, y, z; flat: a list per move made the
    #                     garbage collector run often)
    b_xyz: list         # per move 3: where it ends
    xyz_words: list     # per move 3: ``gcode_number(b - offset, 5)`` of X, Y, Z
    d_e: list           # per move: its E (mm of filament)
    e_words: list       # per move: ``gcode_number(d_e, 6)`` where E is relative, else None
    first: dict         # curve -> its first move (its moves: first[c] .. first[c + 1])

    @staticmethod
    def of(program: Program, lay: Layout, curves: list, reverse: list, seam: list) -> "CurveMoves":
        """The moves of ``curves`` (each printed ``reverse``d or from vertex ``seam``)."""
        steps, first, backwards = [], {}, []
        at = np.asarray(curves, np.int64)
        for c, r, k, a, b in zip(curves, reverse, seam, lay.curve_s0[at].tolist(),
                                 lay.curve_s1[at].tolist()):
            first[c] = len(steps)
            steps += range(b - 1, a - 1, -1) if r else [*range(a + k, b), *range(a, a + k)]
            backwards += [r] * (len(steps) - first[c])
        idx = np.asarray(steps, np.int64)
        back = np.asarray(backwards, bool)[:, None]
        start, end = program.start_mm[idx], program.end_mm[idx]
        a, b = np.where(back, end, start), np.where(back, start, end)
        d_e = end[:, 3] - start[:, 3]
        rel = program.relative_e[idx]
        e_words = [None] * len(steps)
        for j, word in zip(np.flatnonzero(rel).tolist(), gcode_numbers(d_e[rel], 6)):
            e_words[j] = word
        return CurveMoves(steps, a[:, :3].ravel().tolist(), b[:, :3].ravel().tolist(),
                          gcode_numbers((b[:, :3] - program.offset_mm[idx, :3]).ravel(), 5),
                          d_e.tolist(), e_words, first)


class Writer:
    """Output text plus the machine state the output has reached."""

    def __init__(self, program: Program, lay: Layout, lists: PerLine | None = None):
        self.p, self.lay = program, lay
        self.nl = program.line_ending
        self.out: list[str] = []
        self.e = 0.0            # cumulative machine E of the output
        self.e_off = 0.0        # logical E = machine E - e_off (absolute-E mode)
        # where the head is: a row of ``PerLine.step_end_xyz`` (a view, never written) or, after
        # a new move, a tuple of floats
        self.xyz = (0.0, 0.0, 0.0)
        self.feed = None        # mm/s in force
        self.state: dict = {}
        self.feature = None
        L = self.lines = lists or self.per_line(program, lay)
        # (the fields the gap rebuild and the curve writer read, as the Writer's own)
        self.line_cls, self.line_de, self.line_travel = L.line_cls, L.line_de, L.line_travel
        self.layer_lines, self.arc_steps, self.texts = L.layer_lines, L.arc_steps, L.texts
        self.command_lines, self.command_set = L.command_lines, L.command_set
        self.marker_moves = L.marker_moves
        # neutral commands written so far: the k-th one written is the original's k-th (below)
        self.n_commands = 0

    @staticmethod
    def per_line(program: Program, lay: Layout) -> PerLine:
        """``PerLine`` of ``program``."""
        cls, step = lay.line_class, lay.step_of_line
        n = program.n_lines
        # neutral commands (M73, M117), in order: a curve written move by move keeps its own
        commands = np.flatnonzero((program.line_letter == ord("M")) & (cls == LINE_NEUTRAL)).tolist()
        has = step >= 0
        motion = (cls == LINE_MOTION) & has
        s = np.where(has, step, 0)
        logical_e = program.end_mm[:, 3] - program.offset_mm[:, 3]
        moves = np.isin(program.kind, MOTION_KINDS)
        data = program.data
        text = data.decode("ascii") if data.isascii() else None
        texts = line_texts(program, text)
        prefix = lay.feature_prefix
        effects = {}
        for i in _may_set_state(program, lay, has):
            eff = line_effect(texts[i], int(cls[i]), lay.state_key.get(i), prefix)
            if eff is not None:
                effects[i] = eff
        special = ~has
        special[commands] = True
        if n and not texts[-1].endswith("\n"):
            special[n - 1] = True       # copied with a line ending added (``copy_line``)
        renumber = has & ~program.relative_e[s] & moves[s]
        # an absolute-E curve whose lines are all extruding steps, not the file's last line: its
        # first line's E decides for the whole curve (``copy_lines``)
        l0, l1 = lay.curve_l0, lay.curve_l1
        steps_before = np.concatenate(([0], np.cumsum(has)))
        whole = ((steps_before[l1 + 1] - steps_before[l0] == l1 - l0 + 1) & (l1 + 1 < n)
                 & ~program.relative_e[lay.curve_s0])
        block_end = np.full(n, -1, np.int64)
        block_end[l0[whole]] = l1[whole]
        return PerLine(
            cls.tolist(), step.tolist(),
            np.where(has, program.end_mm[s, 3] - program.start_mm[s, 3], 0.0).tolist(),
            (motion & np.isin(program.kind[s], TRAVEL_KINDS)).tolist(),
            program.relative_e.tolist(), program.feed_mm_s.tolist(), logical_e.tolist(),
            np.ascontiguousarray(program.end_mm[:, :3]),
            frozenset(program.layer_line.tolist()),
            frozenset(np.flatnonzero(program.kind == Kind.ARC).tolist()),
            commands, frozenset(commands), moves.tolist(), texts, text,
            program.line_start.tolist(), effects, np.flatnonzero(special).tolist() + [n],
            np.concatenate(([0], np.cumsum(renumber))).tolist(),
            np.where(has, logical_e[s], 0.0).tolist(), block_end.tolist(), {},
            marker_moves(program, lay))

    # -- copying original lines -------------------------------------------------------------
    def copy_line(self, i: int) -> None:
        L = self.lines
        if i in L.command_set:
            # progress (M73) and messages (M117) travel with the next curve, so a re-ordered
            # layer would write them in another order: printers would show progress stepping
            # back. Written in the original's order instead (verify checks it): the k-th neutral
            # command written is the original's k-th, whichever curve carries it
            i = L.command_lines[self.n_commands]
            self.n_commands += 1
        text = L.texts[i]
        s = L.line_step[i]
        if s >= 0:
            new_e = self.e + L.line_de[i]
            # only a move's E word is a position to re-number: a motor line's bare 'E' (Cura's
            # closing 'M84 X Y E') names the extruder motor, and writing a number there made it
            # an 'M84 ... E450.1' that verify read as an added gating line
            if not L.step_relative_e[s] and L.step_moves[s]:
                want = new_e - self.e_off
                if abs(want - L.step_logical_e[s]) > 1e-7:
                    text = self._renumbered(i, text, want)
            self.e = new_e
            self.xyz = L.step_end_xyz[s]        # replaced, never written in place
            self.feed = L.step_feed[s]
        else:
            eff = L.effects.get(i)
            if eff is not None:
                if eff.g92_e is not None:
                    self.e_off = self.e - eff.g92_e
                if eff.feed_mm_s is not None:
                    self.feed = eff.feed_mm_s
                if eff.state is not None:
                    self._set_state(*eff.state)
                if eff.feature is not None:
                    self.feature = eff.feature
        if not text.endswith("\n"):
            text += self.nl
        self.out.append(text)

    def copy_gap_line(self, i: int) -> None:
        """A line of a gap whose travel is rebuilt (``gaps.rebuilt_gap``, ``gaps.reversed_gap``):
        copied, except a move of ``marker_moves``, whose layer marker alone is written, as a
        comment line (the rebuilt travel makes the move)."""
        if i in self.marker_moves:
            text = self.texts[i]
            self.write(text[text.index(";"):].rstrip("\r\n"))
        else:
            self.copy_line(i)

    def _renumbered(self, i: int, text: str, want: float) -> str:
        """Line i (a move, ``text``) with its E word saying ``want``."""
        around = self.lines.e_split.get(i, False)
        if around is False:
            around = self.lines.e_split[i] = e_word_split(text)
        return text if around is None else around[0] + gcode_number(want, 6) + around[1]

    def copy_lines(self, a: int, b: int) -> None:
        """Lines a..b-1 as ``copy_line`` one by one writes them, but each run of steps between two
        other lines (``PerLine.special``) in one pass: its E summed in ``copy_line``'s order (the
        same float), its unchanged lines as one slice of the file. An unchanged absolute-E curve
        of extruding steps (``PerLine.block_end``) whose first line is within 1e-8 mm of the
        original is copied whole (its lines are off by what its first is, rounding ~1e-12 mm
        apart): the text a curve got when it was copied in one piece (emit checks this curve
        by curve: ``tests/test_ordering.py``)."""
        special = self.lines.special
        k = bisect.bisect_left(special, a)
        while a < b:
            y = min(special[k], b)
            if a < y:
                self._copy_steps(a, y)
            if y == b:
                return
            self.copy_line(y)
            a, k = y + 1, k + 1

    def _copy_steps(self, a: int, b: int) -> None:
        """Lines a..b-1, every one a step (``copy_lines``)."""
        L = self.lines
        de = L.line_de
        if L.renumber_before[b] == L.renumber_before[a]:
            # no E word to re-number (relative E): the lines as they are, E summed
            self.e = functools.reduce(operator.add, de[a:b], self.e)
            self.out.append(self._slice(a, b))
        else:
            e, off, out = self.e, self.e_off, self.out
            loge, block_end, rb = L.line_logical_e, L.block_end, L.renumber_before
            texts = L.texts
            j = a               # lines j..i-1 are still to write as they are
            whole_to = -1       # a curve copied whole ends at this line
            for i in range(a, b):
                e += de[i]
                if i <= whole_to:
                    continue
                if block_end[i] >= 0 and abs(e - off - loge[i]) <= 1e-8:
                    whole_to = block_end[i]
                    continue
                if rb[i + 1] != rb[i] and abs(e - off - loge[i]) > 1e-7:
                    if j < i:
                        out.append(self._slice(j, i))
                    out.append(self._renumbered(i, texts[i], e - off))
                    j = i + 1
            if j < b:
                out.append(self._slice(j, b))
            self.e = e
        s = L.line_step[b - 1]
        self.xyz, self.feed = L.step_end_xyz[s], L.step_feed[s]

    def _slice(self, a: int, b: int) -> str:
        """Lines a..b-1 as they are in the file."""
        L = self.lines
        if L.text is not None:
            return L.text[L.line_start[a]:L.line_start[b]]
        return "".join(L.texts[a:b])

    def write(self, text: str) -> None:
        self.out.append(text + self.nl)

    def _set_state(self, key, text: str) -> None:
        # ``state`` keeps its keys in the order their lines were last written: where two keys
        # of one command set the same parameter (M204 S and M204 P T, SET_VELOCITY_LIMIT with
        # and without SQUARE_CORNER_VELOCITY), the later line's value is in force
        self.state.pop(key, None)
        self.state[key] = text

    def reissue(self, states: list, k: int) -> None:
        """Make the state lines in force what ``states`` (``states_at``) holds at its k-th place:
        per command (a key's first word), its keys' texts in the original's order. Where the
        output's differ from the first differing key on, those lines are written again in that
        order (a line sets only the parameters it names, so the value of each is the last line's
        that names it, as in the original)."""
        for head in states:
            want = [(key, texts[k], lines[k]) for key, texts, lines in head if texts[k] is not None]
            if not want:
                continue
            if len(head) == 1:
                key, text, _ = want[0]
                if self.state.get(key) != text:
                    self.write(text)
                    self._set_state(key, text)
                continue
            want.sort(key=lambda x: x[2])
            name = want[0][0][0]
            have = [(key, text) for key, text in self.state.items() if key[0] == name]
            j = 0
            while j < len(want) and j < len(have) and have[j] == want[j][:2]:
                j += 1
            if j == len(want) and j == len(have):
                continue
            for key, text, _ in want[j:]:
                self.write(text)
                self._set_state(key, text)

    # -- the per-layer memo of ``emitter.emit`` -------------------------------------------------------
    def entry_key(self) -> tuple:
        """What a layer's text depends on besides its own curves (E apart: ``emitter.same_entry``)."""
        return (tuple(float(v) for v in self.xyz), self.feed, tuple(self.state.items()),
                self.feature, self.n_commands, self.e - self.e_off, self.e, self.e_off)

    def snapshot(self) -> tuple:
        """The state a memoized layer leaves behind (``extend_from`` takes it)."""
        return (self.e, self.e_off, self.xyz, self.feed, dict(self.state), self.feature,
                self.n_commands)

    def extend_from(self, entry: tuple, chunk: list, exit_: tuple) -> None:
        """Append a memoized layer's text and take its exit state; E moves with the difference
        between this entry and the memoized one (logical E agrees within ``emitter.MEMO_E_TOL_MM``)."""
        self.out.extend(chunk)
        d_e, d_off = self.e - entry[6], self.e_off - entry[7]
        e, e_off, xyz, feed, state, feature, self.n_commands = exit_
        self.e, self.e_off = e + d_e, e_off + d_off
        self.xyz, self.feed, self.state, self.feature = xyz, feed, dict(state), feature

    # -- new moves ------------------------------------------------------------------------------
    def _f(self, feed_mm_s: float) -> str:
        if self.feed is not None and abs(self.feed - feed_mm_s) < 1e-9:
            return ""
        self.feed = feed_mm_s
        return f" F{gcode_number(feed_mm_s * 60.0, 3)}"

    def move_e(self, d_e: float, feed_mm_s: float, relative: bool) -> None:
        self.e += d_e
        val = d_e if relative else self.e - self.e_off
        self.write(f"G1 E{gcode_number(val, 6)}{self._f(feed_mm_s)}")

    def move_xy_e(self, x: float, y: float, d_e: float, feed_mm_s: float, relative: bool,
                  offset) -> None:
        """``G1 X Y E`` to (x, y) moving the filament by ``d_e`` (a wipe: ``wipes``; 0: an XY
        travel among its moves)."""
        ox, oy = offset[:2] if isinstance(offset, (list, tuple)) else offset[:2].tolist()
        e_word = ""
        if d_e != 0.0:
            self.e += d_e
            val = d_e if relative else self.e - self.e_off
            e_word = f" E{gcode_number(val, 6)}"
        self.write(f"G1 X{gcode_number(x - ox, 5)} Y{gcode_number(y - oy, 5)}{e_word}"
                   f"{self._f(feed_mm_s)}")
        self.xyz = (x, y, self.xyz[2])

    def move_xyz(self, xyz, feed_mm_s: float, cmd: str, offset) -> None:
        # plain floats: numpy scalar arithmetic, three axes per travel, was a tenth of the emit
        x, y, z = (float(v) for v in xyz)
        cx, cy, cz = self.xyz
        ox, oy, oz = offset[:3] if isinstance(offset, (list, tuple)) else offset[:3].tolist()
        words = ""
        if abs(x - cx) > 1e-9:
            words += f" X{gcode_number(x - ox, 5)}"
        if abs(y - cy) > 1e-9:
            words += f" Y{gcode_number(y - oy, 5)}"
        if abs(z - cz) > 1e-9:
            words += f" Z{gcode_number(z - oz, 5)}"
        if words:
            self.write(f"{cmd}{words}{self._f(feed_mm_s)}")
            self.xyz = (x, y, z)

    def steps(self, moves: CurveMoves, j0: int, j1: int, reverse: bool) -> None:
        """Moves j0..j1-1 of ``moves`` (one curve, ``reverse``d or not) as new lines: which words
        each writes depends on where the output is, its E on the output's E (absolute E)."""
        p = self.p
        steps, a_xyz, b_xyz, words_of = moves.steps, moves.a_xyz, moves.b_xyz, moves.xyz_words
        d_es, e_words = moves.d_e, moves.e_words
        feeds, arcs, out, nl = self.lines.step_feed, self.arc_steps, self.out, self.nl
        xyz, e, e_off, feed = self.xyz, self.e, self.e_off, self.feed
        for j in range(j0, j1):
            s = steps[j]
            j3 = 3 * j
            ax, ay, az, bx, by, bz = (a_xyz[j3], a_xyz[j3 + 1], a_xyz[j3 + 2],
                                      b_xyz[j3], b_xyz[j3 + 1], b_xyz[j3 + 2])
            e += d_es[j]
            e_word = e_words[j]
            if e_word is None:
                e_word = gcode_number(e - e_off, 6)
            if s in arcs:
                ccw = bool(p.arc_ccw[s]) != reverse
                c = p.arc_center_mm[s].tolist()
                cmd = "G3" if ccw else "G2"
                words = f" X{words_of[j3]} Y{words_of[j3 + 1]}"
                if abs(bz - az) > 1e-9:
                    words += f" Z{words_of[j3 + 2]}"
                words += f" I{gcode_number(c[0] - ax, 5)} J{gcode_number(c[1] - ay, 5)}"
            else:
                cmd = "G1"
                words = ""
                if abs(bx - ax) > 1e-12 or abs(bx - xyz[0]) > 1e-9:
                    words += f" X{words_of[j3]}"
                if abs(by - ay) > 1e-12 or abs(by - xyz[1]) > 1e-9:
                    words += f" Y{words_of[j3 + 1]}"
                if abs(bz - az) > 1e-12:
                    words += f" Z{words_of[j3 + 2]}"
            f = feeds[s]
            if feed is not None and abs(feed - f) < 1e-9:         # as ``_f``
                f_word = ""
            else:
                feed, f_word = f, f" F{gcode_number(f * 60.0, 3)}"
            out.append(f"{cmd}{words} E{e_word}{f_word}{nl}")
            xyz = (bx, by, bz)
        self.xyz, self.e, self.feed = xyz, e, feed


def line_texts(program: Program, text: str | None = None) -> list[str]:
    """Every line of ``program`` as ``Program.line_text`` gives it (with its line ending), made
    once per program: the emit copies most lines, several times under the time guard. ``text``:
    the file decoded already (ASCII)."""
    data, ls = program.data, program.line_start.tolist()
    if data.isascii():
        # one decode; a character is a byte, so the byte offsets cut the text where they cut the data
        text = data.decode("ascii") if text is None else text
        return [text[a:b] for a, b in zip(ls[:-1], ls[1:])]
    return [data[a:b].decode("utf-8", "surrogateescape") for a, b in zip(ls[:-1], ls[1:])]


def e_word_split(text: str):
    """(the line before its E word's number, the line after it) of a move's line, None where its
    code (before any ';') has no E word: ``copy_line`` writes a re-numbered E between them."""
    code, sep, comment = text.partition(";")
    m = E_WORD.search(code)
    if m is None:
        return None
    return code[:m.start(2)], code[m.end(2):] + sep + comment


def feature_of_comment(text: str, prefix: str):
    t = text.strip()
    pre = prefix.strip()
    if pre and t.startswith(pre):
        return t[len(pre):].strip()
    return None


def required_state(program: Program, lay: Layout):
    """key -> (sorted state lines, their texts): what was in force at any line."""
    by_key: dict = {}
    for i in sorted(lay.state_key):
        by_key.setdefault(lay.state_key[i], []).append(i)
    out = {}
    for k, lines in by_key.items():
        arr = np.asarray(lines, np.int64)
        out[k] = (arr, [program.line_text(int(i)).rstrip("\r\n") for i in arr])
    return out


def states_at(req, lines) -> list:
    """Per command (a state key's first word), per key of it (in ``req``'s order), the text in
    force at each of ``lines`` and the line it is on: the key's last line before it (None, -1
    before its first)."""
    heads: dict = {}
    for key, (arr, texts) in req.items():
        opts, at = [None] + texts, [-1] + arr.tolist()
        j = np.searchsorted(arr, lines, side="left").tolist()
        heads.setdefault(key[0], []).append((key, [opts[i] for i in j], [at[i] for i in j]))
    return list(heads.values())
