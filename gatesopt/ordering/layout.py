"""Where the curves and gaps of a Program lie: every line classified, the curves found, the layers
that keep their order (formulations/ordering.md, "Build"). ``groups.build`` makes the
OrderingProblem from this ``Layout``; ``emitter.emit`` rewrites the file along it.

A *curve* is a maximal run of extruding steps (layer >= 0) whose lines are separated only by
neutral lines (comments, blank lines, F-only ``G1 F..``, progress ``M73``, messages ``M117``). Between two curves lies a *gap*: the
slicer's travel (retract, wipe, z-hop, travel, unretract) plus any other lines. A line in a gap is

- *motion*: a non-extruding move; it is rebuilt when the curves around it change;
- *firmware retraction*: a bare ``G10`` / ``G11`` (the slicer's "use firmware retraction"): the
  firmware pulls the filament back and pushes it forward; rebuilt with the travel, like an E move;
- *neutral*: comments, F-only moves, M73 / M117; they travel with the next curve;
- *state*: a command that sets state an extrusion sees (acceleration M204/M201,
  jerk M205, speed/flow M220/M221, linear advance M900, Klipper SET_VELOCITY_LIMIT and
  SET_PRESSURE_ADVANCE, the part-cooling fan M106/M107 without P or with P0); it travels with the
  next curve, and ``emit`` re-issues it wherever a curve would otherwise see another value than in
  the original; the first line of each state is also a barrier (before it the value is the
  firmware's, which emit cannot re-issue);
- *E reset*: an E-only ``G92 E..``; it ends a curve and travels with the next one;
- *label*: an object label that opens or closes an object's moves (``slicers.OBJECT_LABELS``:
  ``; printing object`` / ``; stop printing object``, ``M486 S<id>`` / ``M486 S-1``,
  ``EXCLUDE_OBJECT_START`` / ``_END``, Cura's ``;MESH:``): a boundary like a barrier, but safe mode
  may move a whole object's run of a layer, labels and all, past another (``blocks.py``);
- *barrier*: anything else (heaters, other fans, G92 with X/Y/Z, modal switches, other object
  lines such as ``M486 T4`` or ``EXCLUDE_OBJECT_DEFINE``, dwells, unknown commands): no curve
  crosses it;
- *fatal*: tool changes (T), filament change (M600...), homing: the layer keeps its order (so does
  a layer with an X/Y motor switched off between its curves: an already gated file).

A gap is a *boundary* when it holds a barrier or the layer changes (groups never span one:
``groups.build``). The first layer with curves keeps its order (adhesion, and start G-code purges),
and so do layers with a fatal line and the others ``_kept_layers`` names.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from .._text import code_words
from ..firmware import HANDOFF_M, xy_disable_rows
from ..limits import LIMIT_COMMANDS
from ..program import Kind, Program
from ..slicers import LABEL_OTHER, OBJECT_LABEL_WORDS, object_label

LINE_MOTION, LINE_NEUTRAL, LINE_STATE, LINE_BARRIER, LINE_FATAL, LINE_CURVE = range(6)
LINE_FW_RETRACT, LINE_FW_UNRETRACT = 6, 7
LINE_E_RESET = 8
LINE_LABEL = 9

#: state commands by M number; the part-cooling fan (M106 / M107 without P or with P0, the fan
#: ``Program.fan`` follows) is state too: verify checks the fan duty every extrusion sees. Other
#: fans (``M106 P2``) stay barriers, their order kept
STATE_M = (201, 203, 204, 205, 220, 221, 900)
#: commands that change nothing an extrusion sees: progress (M73) and display messages (M117),
#: which slicers write mid-layer by print time (Bambu, Orca, PrusaSlicer, Creality Print,
#: Kiri:Moto); neutral, they travel with the next curve instead of splitting the layer's groups
NEUTRAL_M = (73, 117)
#: the lines that hand the machine over (pauses, filament and tool changes: ``firmware.HANDOFF_M``)
FATAL_M = HANDOFF_M
STATE_EXT = (b"SET_VELOCITY_LIMIT", b"SET_PRESSURE_ADVANCE", b"M204")
FEATURE_LINE = re.compile(rb"\n(;[ \t]*(?:TYPE:|FEATURE:|feature )[ \t]*)([^\r\n]*)")
MOTION_KINDS = (Kind.TRAVEL, Kind.RETRACT, Kind.UNRETRACT, Kind.Z_ONLY, Kind.ARC, Kind.EXTRUDE)


@dataclass(frozen=True, eq=False)
class Layout:
    """Where curves and gaps lie in the file (shared by ``groups.build`` and ``emitter.emit``)."""

    line_class: np.ndarray      # (n_lines,) int8: LINE_*
    step_of_line: np.ndarray    # (n_lines,) int64: the step a line holds (-1: none)
    curve_s0: np.ndarray        # (n,) first step of each curve
    curve_s1: np.ndarray        # (n,) one past its last step
    curve_l0: np.ndarray        # (n,) first line
    curve_l1: np.ndarray        # (n,) last line (inclusive)
    gap_boundary: np.ndarray    # (n,) bool: the gap *before* curve i is a boundary
    layer_fatal: np.ndarray     # (n_layers,) bool
    layer_keep: np.ndarray      # (n_layers,) bool: the layer keeps its order (why: layer_why)
    layer_why: tuple = ()
    feature_prefix: str = ";TYPE:"
    state_key: dict = field(default_factory=dict)     # line -> state key
    notes: tuple = ()
    #: line -> (family, kind, object name) of each LINE_LABEL line (``slicers.object_label``)
    labels: dict = field(default_factory=dict)
    #: (n,) bool: the curve ends in the slicer's coasting (``_coast_tails``), its moves included
    curve_coast: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))


def _line_text_bytes(program: Program, i: int) -> bytes:
    return program.data[program.line_start[i]:program.line_start[i + 1]]


def _code_words(program: Program, i: int) -> list[bytes]:
    """The words of line ``i`` before its comment, upper-cased, line number dropped."""
    return code_words(_line_text_bytes(program, i))


def state_key_of(program: Program, i: int):
    """The state a state line sets (the part fan, M204 words, Klipper command name)."""
    words = _code_words(program, i)
    head = words[0] if words else b""
    if head in (b"M106", b"M107"):
        # only the part-cooling fan is state (``Program.part_fan_lines``: no P, or P0 written
        # any way, ``P0.0`` too): one key, whatever the line's P word
        return ("fan",)
    if head in (b"M204", b"M201", b"M203", b"M205"):
        return (head.decode(),) + tuple(sorted({w[:1].decode() for w in words[1:]}))
    if head in STATE_EXT:
        # Klipper's extended commands set only the parameters they name: Creality Print / Orca
        # restate SQUARE_CORNER_VELOCITY on some SET_VELOCITY_LIMIT lines and not on others
        # (bridges: "ACCEL=2500 ACCEL_TO_DECEL=1250"), so one key per command left a curve moved
        # past another feature's line under that feature's corner velocity
        # (real_crealityprint514 free, layer 17: a bridge of 899 moves at 7 mm/s instead of 12,
        # 2.95 s slower). One key per set of parameter names, as for M204's letters; the writer
        # keeps their order (``writer.Writer.reissue``)
        return (head.decode(),) + tuple(sorted({w.split(b"=")[0].decode("ascii", "replace")
                                                for w in words[1:]}))
    return (head.decode(),)


#: state commands that set the planner's motion limits (those ``limits.py`` reads; M566 is not a
#: state line): a rebuilt travel runs under those in force at the slicer's travel it replaces
#: (``link_travel_steps``)
LIMIT_STATE_HEADS = LIMIT_COMMANDS


def link_travel_steps(program: Program, lay: "Layout") -> np.ndarray:
    """Per curve c of ``lay``, the step of the slicer's last travel in the gap before c (its last
    motion step without one, c's first step in a gap without motion): the motion limits in force
    there are those a link into c runs under -- priced so (``curve_time.gap_rows``) and written so
    (``emitter``: the limit state lines in force at that step are re-issued before a rebuilt
    travel, wherever the output stands when it leaves the curve before)."""
    n = len(lay.curve_s0)
    s0 = np.asarray(lay.curve_s0, np.int64)
    a = np.concatenate(([0], np.asarray(lay.curve_s1, np.int64)[:-1])) if n else s0
    step = s0.copy()
    for kinds in ((Kind.TRAVEL,), MOTION_KINDS):
        at = np.flatnonzero(np.isin(program.kind, np.asarray(kinds, program.kind.dtype)))
        j = np.searchsorted(at, s0) - 1
        ok = (j >= 0) & (step == s0)
        found = np.where(ok, at[np.maximum(j, 0)], -1) if len(at) else np.full(n, -1)
        ok &= found >= a
        step = np.where(ok, found, step)
    return step


def firmware_retraction(program: Program) -> tuple[np.ndarray, np.ndarray]:
    """Lines of firmware retractions and unretractions: a bare ``G10`` / ``G11`` (Marlin, Klipper,
    RepRapFirmware; the slicer's "use firmware retraction"). With words ``G10`` is something else:
    tool offsets and temperatures on RepRapFirmware (``G10 P0 S200``), Marlin's swap retraction
    (``G10 S1``); those stay barriers."""
    cand = np.flatnonzero((program.line_letter == ord("G"))
                          & ((program.line_number == 10) | (program.line_number == 11)))
    bare = [i for i in cand.tolist() if len(_code_words(program, i)) == 1]
    bare = np.asarray(bare, np.int64)
    is_g10 = program.line_number[bare] == 10
    return bare[is_g10], bare[~is_g10]


def layout(program: Program) -> Layout:
    """Classify every line and find the curves (see module docstring)."""
    step_of_line = np.full(program.n_lines, -1, np.int64)
    step_of_line[program.line] = np.arange(program.n_steps)
    cls, g92_xyz, labels = _line_classes(program, step_of_line)
    skey = {int(i): state_key_of(program, int(i)) for i in np.flatnonzero(cls == LINE_STATE)}
    # the first line of each state key is a barrier as well: before it the file sets no value
    # (the firmware's default, unknown here), which emit could not re-issue to a curve moved
    # from before it to after it. It stays in ``state_key``: emit still tracks what it sets
    first_of_key: dict = {}
    for i, k in skey.items():
        first_of_key.setdefault(k, i)
    cls[list(first_of_key.values())] = LINE_BARRIER
    s0, s1, l0, l1 = _curves(program, cls)
    s1, l1, coast = _coast_tails(program, cls, s1, l1)
    n = len(s0)
    barrier_count = np.concatenate(([0], np.cumsum((cls == LINE_BARRIER) | (cls == LINE_FATAL)
                                                   | (cls == LINE_LABEL))))
    gap_boundary = np.ones(n, bool)
    if n > 1:
        gl0, gl1 = l1[:-1] + 1, l0[1:]                         # gap lines [gl0, gl1)
        gap_boundary[1:] = ((barrier_count[gl1] - barrier_count[gl0]) > 0) | (
            program.layer[s0[1:]] != program.layer[s0[:-1]])
    layer_fatal, layer_keep, why, notes = _kept_layers(program, cls, s0, l0, l1, g92_xyz)
    fm = FEATURE_LINE.search(b"\n" + program.data)
    prefix = fm.group(1).decode() if fm else ";TYPE:"
    return Layout(cls, step_of_line, s0.astype(np.int64), s1.astype(np.int64), l0.astype(np.int64),
                  l1.astype(np.int64), gap_boundary, layer_fatal, layer_keep, tuple(why), prefix,
                  skey, tuple(notes), labels, coast)


def _line_classes(program: Program, step_of_line: np.ndarray) -> tuple[np.ndarray, list[int], dict]:
    """LINE_* of every line before the curves are found (module docstring), the lines of
    G92 with X, Y or Z (each keeps its layer's order: ``_kept_layers``) and the object labels
    (``Layout.labels``)."""
    n_lines = program.n_lines
    letter, number = program.line_letter, program.line_number
    cls = np.full(n_lines, LINE_BARRIER, np.int8)
    is_step = step_of_line >= 0
    cls[(letter == 0) & ~is_step] = LINE_NEUTRAL
    g = letter == ord("G")
    cls[g & np.isin(number, (0, 1, 2, 3)) & ~is_step] = LINE_NEUTRAL       # F-only moves
    m = letter == ord("M")
    cls[m & np.isin(number, STATE_M)] = LINE_STATE
    cls[program.part_fan_lines] = LINE_STATE
    cls[m & np.isin(number, NEUTRAL_M)] = LINE_NEUTRAL
    cls[m & np.isin(number, FATAL_M)] = LINE_FATAL
    cls[letter == ord("T")] = LINE_FATAL
    cls[g & np.isin(number, (28, 29))] = LINE_FATAL
    # an E-only G92 (``G92 E0``: PrusaSlicer and Slic3r after a retraction, Cura at a layer
    # change): emit numbers E from its own running total and the offset each copied G92 sets, so
    # it may travel with the next curve; it still ends a curve (one written move by move would
    # drop it). G92 with X, Y or Z moves the coordinate system: a barrier (and see below)
    g92_xyz = []
    for i in np.flatnonzero(g & (number == 92)).tolist():
        words = _code_words(program, i)
        if len(words) == 2 and words[1][:1] == b"E":
            cls[i] = LINE_E_RESET
        elif any(w[:1] in (b"X", b"Y", b"Z") for w in words[1:]):
            g92_xyz.append(i)
    fw_retract, fw_unretract = firmware_retraction(program)
    cls[fw_retract] = LINE_FW_RETRACT
    cls[fw_unretract] = LINE_FW_UNRETRACT
    ext = np.flatnonzero(letter == ord("@"))
    for i in ext:
        words = _code_words(program, int(i))
        head = words[0] if words else b""
        if head in STATE_EXT:
            cls[i] = LINE_STATE
    # object labels that open or close an object's moves are labels; other object lines
    # (M486 T4, EXCLUDE_OBJECT_DEFINE, a label the table does not read) are barriers
    labels = {}
    for i in object_label_lines(program).tolist():
        if cls[i] not in (LINE_NEUTRAL, LINE_BARRIER) or step_of_line[i] >= 0:
            continue
        got = object_label(program.line_text(i))
        if got is None or got[0].kind == LABEL_OTHER:
            cls[i] = LINE_BARRIER
        else:
            cls[i] = LINE_LABEL
            labels[i] = (got[0].family, got[0].kind, got[1])
    kind = program.kind
    steps = np.flatnonzero(is_step)
    sk = kind[step_of_line[steps]]
    motion = np.isin(sk, MOTION_KINDS)
    cls[steps[motion]] = LINE_MOTION
    cls[steps[~motion]] = LINE_BARRIER           # dwell, heat wait, homing handled as FATAL above
    cls[steps[sk == Kind.HOME]] = LINE_FATAL
    return cls, g92_xyz, labels


def object_label_lines(program: Program) -> np.ndarray:
    """Lines that may carry an object label (``slicers.OBJECT_LABEL_WORDS`` anywhere in them,
    any case): M486, EXCLUDE_OBJECT_*, ``; printing object``, ``; stop printing object``,
    ``;MESH:``."""
    at = []
    low = program.data.lower()
    for word in OBJECT_LABEL_WORDS:
        i = low.find(word)
        while i >= 0:
            at.append(i)
            i = low.find(word, i + 1)
    if not at:
        return np.zeros(0, np.int64)
    return np.unique(np.searchsorted(program.line_start, np.asarray(at), side="right") - 1)


def _curves(program: Program, cls: np.ndarray) -> tuple:
    """(first step, one past the last step, first line, last line) of each curve: runs of
    extruding steps in layers >= 0 separated only by neutral lines. Marks their lines LINE_CURVE
    in ``cls``."""
    extr = program.extruding & (program.layer >= 0)
    es = np.flatnonzero(extr)
    cls[program.line[es]] = LINE_CURVE
    not_neutral = np.concatenate(([0], np.cumsum(cls != LINE_NEUTRAL)))   # prefix count per line
    if len(es):
        lines = program.line[es]
        # non-neutral lines strictly between consecutive extruding steps' lines
        between = not_neutral[lines[1:]] - not_neutral[lines[:-1] + 1]
        new = np.ones(len(es), bool)
        new[1:] = ((es[1:] != es[:-1] + 1) | (between > 0)
                   | (program.layer[es[1:]] != program.layer[es[:-1]])
                   | (program.feature[es[1:]] != program.feature[es[:-1]]))
        first = np.flatnonzero(new)
        s0 = es[first]
        last = np.concatenate((first[1:] - 1, [len(es) - 1]))
        s1 = es[last] + 1
    else:
        s0 = s1 = np.zeros(0, np.int64)
    l0, l1 = program.line[s0], program.line[s1 - 1] if len(s1) else np.zeros(0, np.int64)
    return s0, s1, l0, l1


#: the longest coasting ``_coast_tails`` keeps with its curve (Cura's coasting_volume of 0.064 mm3
#: is ~0.8 mm of a 0.4 mm wall; Simplify3D's coasting distance ~0.2-1 mm): longer non-extruding
#: runs before a retraction are the travel's
COAST_MAX_MM = 5.0
#: at most this many moves of it
COAST_MAX_MOVES = 8


def _coast_tails(program: Program, cls: np.ndarray, s1: np.ndarray, l1: np.ndarray):
    """Curves that end in the slicer's coasting (Cura ``coasting_enable``: the last stretch of a
    wall printed as moves without extrusion, on the ooze, at ``coasting_speed``, 90 % of the
    wall's): a run of at most ``COAST_MAX_MOVES`` XY moves without E at the curve's height,
    ``COAST_MAX_MM`` long in all, at one feed slower than the curve's last extrusion (coasting at
    the print feed, as Simplify3D writes it, is not told from a travel: left in the gap), straight
    after it, ended by a retraction (an E-only move back, a firmware ``G10``) or by the travel (a
    move at another feed), only neutral lines between. It belongs to what is printed there, not
    to the travel: the curve takes it (``s1``, ``l1`` extended, its lines LINE_CURVE), so that a
    re-ordered print keeps it with its curve; such a curve is printed in its own direction only
    (``candidates``). Returns (s1, l1, coast per curve)."""
    n = len(s1)
    coast = np.zeros(n, bool)
    kind, n_steps = program.kind, program.n_steps
    if n == 0:
        return s1, l1, coast
    nxt = np.minimum(s1, n_steps - 1)
    cand = np.flatnonzero((s1 < n_steps) & (kind[nxt] == Kind.TRAVEL))
    if not len(cand):
        return s1, l1, coast
    s1, l1 = s1.copy(), l1.copy()
    start, end, length = program.start_mm, program.end_mm, program.length_mm
    feed = program.feed_mm_s
    neutral = cls == LINE_NEUTRAL
    for c in cand.tolist():
        a = int(s1[c])
        z, f = end[a - 1, 2], feed[a]
        if f >= feed[a - 1] * (1.0 - 1e-9):
            # no slower than it printed: the travel, or Cura's infill wipe (a line's tail at the
            # line's own feed, into the wall), which the gap keeps (``gaps.ReversibleGaps``
            # writes it backwards with the gap where two lines swap)
            continue
        k, mm = a, 0.0
        while (k < n_steps and k - a < COAST_MAX_MOVES and kind[k] == Kind.TRAVEL
               and feed[k] == f and start[k, 2] == z and end[k, 2] == z):
            mm += length[k]
            k += 1
        if mm > COAST_MAX_MM or k - a == COAST_MAX_MOVES:
            continue
        # what comes next: a retraction, with only neutral lines (and the run's own) before it
        last_line = int(program.line[k - 1])
        lines = program.line[a:k]
        if not (neutral[l1[c] + 1:last_line + 1] | np.isin(
                np.arange(l1[c] + 1, last_line + 1), lines)).all():
            continue
        j = last_line + 1
        while j < program.n_lines and neutral[j]:
            j += 1
        ends = j < program.n_lines and (
            cls[j] == LINE_FW_RETRACT
            or (k < n_steps and program.line[k] == j
                and ((kind[k] == Kind.RETRACT and start[k, 0] == end[k, 0]
                      and start[k, 1] == end[k, 1])
                     or (kind[k] in (Kind.TRAVEL, Kind.Z_ONLY) and feed[k] != f))))
        if not ends:
            continue
        cls[lines] = LINE_CURVE
        s1[c], l1[c] = k, last_line
        coast[c] = True
    return s1, l1, coast


#: a layer whose travels run at a median feed below this share of the file's keeps the slicer's
#: order: a rebuilt travel runs at the file's travel feed (``travel.TravelStyle``), faster than
#: the slicer moved there -- Cura's slower first layers (its second layer at 125 of 150 mm/s on
#: an Ender-3 profile: re-ordered, its rebuilt travels ran at 150)
SLOW_TRAVEL_SHARE = 0.9
SLOW_TRAVEL_WHY = ("its travels run slower than the file's (the slicer's slower first layers): a "
                   "rebuilt travel would run at the file's travel speed")


def feed_travels(program: Program) -> np.ndarray:
    """(n_steps,) bool: the travel moves the file's travel feed is read from (``travel.
    travel_style``'s median, the feed of every rebuilt travel): travels longer than 1 mm."""
    return (program.kind == Kind.TRAVEL) & (program.length_mm > 1.0)


def slow_travel_layers(program: Program) -> np.ndarray:
    """Layers whose travels (``feed_travels``) run at a median feed below ``SLOW_TRAVEL_SHARE``
    of the file's travel feed."""
    tr = feed_travels(program)
    if not tr.any():
        return np.zeros(0, np.int64)
    feed = program.feed_mm_s[tr]
    ref = float(np.median(feed))
    lay = program.layer[tr]
    keep = lay >= 0
    lay, feed = lay[keep], feed[keep]
    if not len(lay):
        return np.zeros(0, np.int64)
    order = np.argsort(lay, kind="stable")
    lay, feed = lay[order], feed[order]
    cuts = np.flatnonzero(np.diff(lay)) + 1
    layers = lay[np.concatenate(([0], cuts))]
    med = np.array([np.median(part) for part in np.split(feed, cuts)])
    return layers[med < SLOW_TRAVEL_SHARE * ref].astype(np.int64)


def _kept_layers(program: Program, cls: np.ndarray, s0, l0, l1, g92_xyz) -> tuple:
    """Per layer: whether it holds a fatal line, whether it keeps the slicer's order and why;
    and the notes to report (module docstring: tool changes, G92 with X/Y/Z, an X/Y motor
    switched off, spiral vase, the first layer, relative XYZ or inch units)."""
    n = len(s0)
    es = np.flatnonzero(program.extruding & (program.layer >= 0))
    fatal_count = np.concatenate(([0], np.cumsum(cls == LINE_FATAL)))
    n_layers = max(program.n_layers, int(program.layer.max()) + 1 if program.n_steps else 0)
    layer_fatal = np.zeros(n_layers, bool)
    layer_keep = np.zeros(n_layers, bool)
    why = [""] * n_layers
    curve_layer = program.layer[s0]
    if n:
        # fatal lines anywhere from a layer's first curve to its last one, or in the gap before it
        for lay in np.unique(curve_layer):
            cs = np.flatnonzero(curve_layer == lay)
            a = l1[cs[0] - 1] + 1 if cs[0] > 0 else l0[cs[0]]
            if fatal_count[l1[cs[-1]] + 1] - fatal_count[a] > 0:
                layer_fatal[lay] = True
                layer_keep[lay] = True
                why[lay] = "tool change, filament change or homing in the layer"
        # G92 with X, Y or Z sets the coordinate system from where the head is when it is read:
        # the curves before it must end where the slicer's did (its layer, and the layer before
        # it when it lies in the gap between the two), or every move after it shifts
        for i in g92_xyz:
            after = int(np.searchsorted(l0, i))
            for c in (after - 1, after):
                if 0 <= c < n:
                    layer_keep[curve_layer[c]] = True
                    why[curve_layer[c]] = why[curve_layer[c]] or "G92 sets X, Y or Z in the layer"
        # an X/Y motor switched off between the first curve and the last (an already gated file):
        # its place was chosen for the moves around it; curves re-ordered or reversed around it
        # would step a motor it holds off (a closing M84 after the last curve is not one)
        for i in program.line[xy_disable_rows(program)].tolist():
            if not l0[0] < i < l1[-1]:
                continue
            after = int(np.searchsorted(l0, i))
            for c in (after - 1, after):
                if 0 <= c < n:
                    layer_keep[curve_layer[c]] = True
                    why[curve_layer[c]] = why[curve_layer[c]] or "an X/Y motor switched off in the layer (already gated?)"
        # Z that changes while extruding (spiral vase): reversing would run Z backwards
        dz = np.abs(program.end_mm[es, 2] - program.start_mm[es, 2]) > 1e-6
        for lay in np.unique(program.layer[es[dz]]):
            layer_keep[lay] = True
            why[lay] = why[lay] or "Z changes while extruding (spiral vase, or a prime moving up)"
    if n:
        first = int(curve_layer[0])
        layer_keep[first] = True
        why[first] = why[first] or "first layer keeps the slicer's order"
        for lay in slow_travel_layers(program):
            if lay < n_layers:
                layer_keep[lay] = True
                why[lay] = why[lay] or SLOW_TRAVEL_WHY
    notes = []
    # extrusion in relative XYZ (G91) or inch units (G20): a curve's moves mean something else
    # elsewhere, and a travel rebuilt into one in G91 would be read as relative. Its layer keeps
    # the slicer's order, and the layer before it too, so the travel into it stays the slicer's
    # (as for G92 above). Only those layers: Ultimaker's stock end G-code primes in G91 after the
    # last layer (``G91`` / ``G0 F10000 Z1.5 E4.5``), which once kept every layer of the print
    rel = es[program.relative_xyz[es] | program.inch[es]] if len(es) else es
    if len(rel):
        rel_layers = np.unique(program.layer[rel])
        for lay in np.unique(np.concatenate((rel_layers, rel_layers - 1))):
            if 0 <= lay < n_layers:
                layer_keep[lay] = True
                why[lay] = why[lay] or ("relative XYZ (G91) or inch units (G20) while extruding"
                                        + ("" if lay in rel_layers else " in the next layer"))
        notes.append(f"relative XYZ (G91) or inch units (G20) while extruding in "
                     f"{len(rel_layers)} layer(s) from layer {int(rel_layers[0])}: "
                     "their order kept")
    return layer_fatal, layer_keep, why, notes
