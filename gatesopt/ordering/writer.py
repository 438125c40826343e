"""The output text of a re-ordering and the machine state it has reached (``Writer``): original
lines copied (E re-numbered in absolute-E files, state tracked), new moves written in the file's
own number format, state lines re-issued where a curve would see another value than in the
original (formulations/ordering.md, "Emit").
"""
from __future__ import annotations

import re

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
    s = ("%.*f" % (nd, v)).rstrip("0").rstrip(".")
    if s[:2] == "0.":
        return s[1:]            # ".5" as PrusaSlicer writes; every firmware reads it
    if s[:3] == "-0.":
        return "-" + s[2:]
    if s in ("-0", "", "-"):
        return "0"
    return s



class Writer:
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
         self.command_lines, self.command_set, self.step_moves, self.texts,
         self.e_split, self.marker_moves) = lists or self.per_line(program, lay)
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
                (motion & np.isin(program.kind[s], TRAVEL_KINDS)).tolist(),
                program.relative_e.tolist(), program.feed_mm_s.tolist(),
                (program.end_mm[:, 3] - program.offset_mm[:, 3]).tolist(),
                np.ascontiguousarray(program.end_mm[:, :3]),    # rows are views: never written
                frozenset(program.layer_line.tolist()),
                frozenset(np.flatnonzero(program.kind == Kind.ARC).tolist()),
                commands, frozenset(commands),
                np.isin(program.kind, MOTION_KINDS).tolist(), line_texts(program),
                {},     # per line whose E word was re-numbered: its text around the number
                marker_moves(program, lay))

    # -- copying original lines -------------------------------------------------------------
    def copy_line(self, i: int) -> None:
        if i in self.command_set:
            # progress (M73) and messages (M117) travel with the next curve, so a re-ordered
            # layer would write them in another order: printers would show progress stepping
            # back. Written in the original's order instead (verify checks it): the k-th neutral
            # command written is the original's k-th, whichever curve carries it
            i = self.command_lines[self.n_commands]
            self.n_commands += 1
        text = self.texts[i]
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
                    around = self.e_split.get(i, False)
                    if around is False:
                        around = self.e_split[i] = e_word_split(text)
                    if around is not None:
                        text = around[0] + gcode_number(want, 6) + around[1]
            self.e = new_e
            self.xyz = self.step_end_xyz[s]     # replaced, never written in place
            self.feed = self.step_feed[s]
        else:
            code = text.split(";")[0].strip().upper()
            if code.startswith("G92"):
                m = E_WORD.search(code[3:])
                if m and m.group(2):
                    self.e_off = self.e - float(m.group(2))
                elif code == "G92":
                    self.e_off = self.e
            elif cls == LINE_NEUTRAL and code[:2] in ("G0", "G1"):
                m = F_WORD.search(code)
                if m:
                    self.feed = float(m.group(1)) / 60.0
            # a state line (the first of its key is a barrier, and still sets state)
            key = self.lay.state_key.get(i)
            if key is not None:
                self._set_state(key, text.rstrip("\r\n"))
            elif cls == LINE_NEUTRAL and not code:
                name = feature_of_comment(text, self.lay.feature_prefix)
                if name is not None:
                    self.feature = name
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
        return (tuple(self.xyz.tolist()), self.feed, tuple(self.state.items()),
                self.feature, self.n_commands, self.e - self.e_off, self.e, self.e_off)

    def snapshot(self) -> tuple:
        """The state a memoized layer leaves behind (``extend_from`` takes it)."""
        return (self.e, self.e_off, self.xyz.copy(), self.feed, dict(self.state), self.feature,
                self.n_commands)

    def extend_from(self, entry: tuple, chunk: list, exit_: tuple) -> None:
        """Append a memoized layer's text and take its exit state; E moves with the difference
        between this entry and the memoized one (logical E agrees within ``emitter.MEMO_E_TOL_MM``)."""
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
        return f" F{gcode_number(feed_mm_s * 60.0, 3)}"

    def move_e(self, d_e: float, feed_mm_s: float, relative: bool) -> None:
        self.e += d_e
        val = d_e if relative else self.e - self.e_off
        self.write(f"G1 E{gcode_number(val, 6)}{self._f(feed_mm_s)}")

    def move_xyz(self, xyz, feed_mm_s: float, cmd: str, offset) -> None:
        # plain floats: numpy scalar arithmetic, three axes per travel, was a tenth of the emit
        new = [float(v) for v in xyz]
        cur, off = self.xyz.tolist(), offset.tolist()
        words = ""
        for ax, k in (("X", 0), ("Y", 1), ("Z", 2)):
            if abs(new[k] - cur[k]) > 1e-9:
                words += f" {ax}{gcode_number(new[k] - off[k], 5)}"
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
            words = f" X{gcode_number(b[0] - off[0], 5)} Y{gcode_number(b[1] - off[1], 5)}"
            if abs(b[2] - a[2]) > 1e-9:
                words += f" Z{gcode_number(b[2] - off[2], 5)}"
            words += f" I{gcode_number(c[0] - a[0], 5)} J{gcode_number(c[1] - a[1], 5)}"
        else:
            cmd = "G1"
            words = ""
            for ax, k in (("X", 0), ("Y", 1), ("Z", 2)):
                if abs(b[k] - a[k]) > 1e-12 or (k < 2 and abs(b[k] - self.xyz[k]) > 1e-9):
                    words += f" {ax}{gcode_number(b[k] - off[k], 5)}"
        self.write(f"{cmd}{words} E{gcode_number(e_val, 6)}{self._f(float(p.feed_mm_s[s]))}")
        self.xyz = b[:3].copy()


def line_texts(program: Program) -> list[str]:
    """Every line of ``program`` as ``Program.line_text`` gives it (with its line ending), made
    once per program: the emit copies most lines, several times under the time guard."""
    data, ls = program.data, program.line_start.tolist()
    if data.isascii():
        # one decode; a character is a byte, so the byte offsets cut the text where they cut the data
        text = data.decode("ascii")
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
