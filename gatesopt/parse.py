"""parse: G-code text -> Program. Modal state is resolved here, once, and nowhere else.

The sequential work (tokenizing, modal state, one row per timed step) is the compiled kernel in
``_scan.py`` (its tokenizer ``_scan_words.py``, its table readers ``_scan_tables.py``); this module reads the input, rejects what cannot be G-code with a one-line message
naming file and line, and adds what regular expressions over the whole text find faster than a
loop: layers (each slicer's own markers, or a Z-change fallback), feature types, header facts.
"""
from __future__ import annotations

import gzip
import os
import re
from pathlib import Path

import numpy as np

from . import _scan, _scan_tables, slicers
from .errors import GcodeError
from .firmware import EXTENDED_MOTOR_COMMANDS
from .program import AXES, Kind, Program

GZIP_MAGIC = b"\x1f\x8b"
BGCODE_MAGIC = b"GCDE"      # PrusaSlicer 2.7+ binary G-code
DEFAULT_FEED_MM_S = 25.0    # F1500: what Marlin-based slicers assume before the first F word

#: what the scanner knows, as the arrays it reads: the slicers' comment markers
#: (``slicers.LAYER_MARKERS`` written on comment lines, ``Z_MARKERS``, ``FEATURE_MARKERS``) and the
#: extended commands that switch motors (``firmware.EXTENDED_MOTOR_COMMANDS``)
SCAN_TABLES = (
    *_scan_tables.pack_comment_markers([m for m in slicers.LAYER_MARKERS if m.where == slicers.COMMENT_LINE],
                                       slicers.LAYER_KINDS, slicers.Z_MARKERS, slicers.FEATURE_MARKERS),
    *_scan_tables.pack_motor_commands(EXTENDED_MOTOR_COMMANDS, AXES))
#: layer markers written as a comment after the G-code of a line (``slicers.TRAILING``), each with
#: its kind (1-based, ``slicers.LAYER_KINDS``): found here, by ``bytes.find`` over the whole text
#: (the scanner reads the markers of comment lines only, not the comments of G-code lines)
TRAILING_MARKERS = tuple((m.text, slicers.LAYER_KINDS.index(m.slicer) + 1)
                         for m in slicers.LAYER_MARKERS if m.where == slicers.TRAILING)

_ERR_TEXT = {
    _scan.ERR_BAD_NUMBER: "bad number for {L}",
    _scan.ERR_MISSING_NUMBER: "{L} has no number",
    _scan.ERR_ABSURD: "absurd coordinate for {L} (beyond {lim:g} mm)",   # lim: per axis, see _scan
    _scan.ERR_BAD_FEED: "feedrate F must be positive",
    _scan.ERR_ARC: "arc needs I/J or an R that reaches the end point",
    _scan.ERR_BAD_CHAR: "unexpected character in a G command (not G-code, or a damaged line)",
    # klippy/gcode.py reads a run of letters as one parameter name, Marlin's parser.cpp each letter
    # as a word of its own without a value: the two firmwares move differently
    _scan.ERR_LETTER_RUN: "a letter straight after a letter, with no number between: Marlin and "
                          "Klipper read this line differently",
    _scan.ERR_HEX: "a hexadecimal number (0x..): Klipper reads 0 and an X word, Marlin reads it as "
                   "hexadecimal or as 0 depending on its board; write it in decimal",
}


# ------------------------------------------------------------------------------------------------
# input
def read_input(path_or_text, source: str | None = None) -> tuple[bytes, str]:
    """Bytes and a display name from a path (``.gz`` too), bytes, or G-code text.

    A ``str`` names a file unless it holds a line break: a name that is no file is "no such
    file", never read as G-code text (``parse("benchy")``); one line of G-code text goes through
    ``parse_text``.
    """
    if isinstance(path_or_text, bytes):
        data, name = path_or_text, source or "<bytes>"
    elif isinstance(path_or_text, os.PathLike) or (
            isinstance(path_or_text, str) and path_or_text.strip()
            and "\n" not in path_or_text and "\r" not in path_or_text):
        p = Path(path_or_text)
        name = source or str(p)
        try:
            data = p.read_bytes()
        except FileNotFoundError:
            hint = (" (G-code text given as one line: use gatesopt.parse_text)"
                    if _looks_like_gcode(str(path_or_text)) else "")
            raise GcodeError(name, None, "no such file" + hint) from None
        except IsADirectoryError:
            raise GcodeError(name, None, "is a directory, not a G-code file") from None
        except OSError as exc:
            raise GcodeError(name, None, f"cannot read: {exc.strerror}") from None
    elif isinstance(path_or_text, str):
        data, name = path_or_text.encode("utf-8", "surrogateescape"), source or "<text>"
    else:
        raise TypeError(f"parse() takes a path, bytes or G-code text, not {type(path_or_text).__name__}")
    if data[:2] == GZIP_MAGIC:
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError) as exc:
            raise GcodeError(name, None, f"corrupt gzip file: {exc}") from None
    return data, name


def _looks_like_gcode(text: str) -> bool:
    """``text`` starts like a G-code line (a G/M/T word or a comment), for a hint."""
    return re.match(r"\s*(?:[GMT]\d|;)", text, re.I) is not None


def _check_bytes(data: bytes, name: str) -> list[str]:
    """Reject what is not text G-code; return warnings for what is odd but usable."""
    if data[:4] == BGCODE_MAGIC:
        raise GcodeError(name, None, "binary G-code (.bgcode, 'GCDE' magic) is not supported: in "
                         "PrusaSlicer turn off Printer Settings > General > Firmware > "
                         "'Supports binary G-code' and export again")
    if not data.strip():
        raise GcodeError(name, None, "empty file: no G-code in it")
    nul = data.find(b"\x00")
    if nul >= 0:
        line = data.count(b"\n", 0, nul) + 1
        raise GcodeError(name, line, "binary data (NUL byte): this is not a text G-code file")
    warnings = []
    try:
        if not data.isascii():          # isascii is a fast scan; decode only when it must
            data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        # Kept byte-exact (surrogateescape); commands are ASCII, so only comments are affected.
        warnings.append(f"{name}:{line}: bytes that are not UTF-8 (kept as they are)")
    return warnings


def _line_starts(arr: np.ndarray) -> np.ndarray:
    return _scan.line_starts(arr)


# ------------------------------------------------------------------------------------------------
# layers and features
def _trailing_layer_markers(data: bytes, line_start: np.ndarray, markers):
    """``markers`` with the layer markers of ``TRAILING_MARKERS`` on G-code lines added (line
    order kept)."""
    mk_line, mk_kind, mk_z, mk_span = markers
    add_line, add_code = [], []
    for pattern, code in TRAILING_MARKERS:
        if ((mk_kind > 0) & (mk_kind < code)).any():
            continue        # markers of a kind ahead of it are what ``_find_layers`` takes
        at = data.find(pattern)
        while at >= 0:
            ln = int(np.searchsorted(line_start, at, side="right")) - 1
            if data[line_start[ln]:at].strip():             # a comment line is the scanner's
                add_line.append(ln)
                add_code.append(code)
            at = data.find(pattern, at + len(pattern))
    if not add_line:
        return markers
    line = np.concatenate((mk_line, np.asarray(add_line, mk_line.dtype)))
    order = np.argsort(line, kind="stable")
    return (line[order], np.concatenate((mk_kind, np.asarray(add_code, mk_kind.dtype)))[order],
            np.concatenate((mk_z, np.full(len(add_line), np.nan)))[order],
            np.concatenate((mk_span, np.full((len(add_line), 2), -1, mk_span.dtype)))[order])


#: a first layer (found by Z change) whose extrusion lies this far outside the rest of the print's
#: footprint is the start G-code's purge (prime) line, not part of the print
PURGE_CLEARANCE_MM = 1.0


def _purge_layer(idx, layer_of_ext, start, end) -> int:
    """How many of the first extruding steps ``idx`` are a purge line: all of the first layer
    found by Z change (there are more) if its extrusion lies outside the bounding box of every
    later layer's extrusion by ``PURGE_CLEARANCE_MM``: a skirt or brim is at the first layer's Z,
    a purge line at its own Z before the first layer (Slic3r 1.x without verbose comments: ``G1 X5
    Y5 Z0.3`` / ``G1 X100 E12`` at the bed's edge, then the print from Z 0.35). Else 0."""
    first = layer_of_ext == 0
    if first.all():
        return 0
    rest = idx[~first]
    lo = np.minimum(start[rest, :2].min(axis=0), end[rest, :2].min(axis=0)) - PURGE_CLEARANCE_MM
    hi = np.maximum(start[rest, :2].max(axis=0), end[rest, :2].max(axis=0)) + PURGE_CLEARANCE_MM
    # a segment can cross the box with both ends outside it; the test is on each segment's box
    a, b = start[idx[first], :2], end[idx[first], :2]
    seg_lo, seg_hi = np.minimum(a, b), np.maximum(a, b)
    overlaps = ((seg_hi >= lo) & (seg_lo <= hi)).all(axis=1)
    return 0 if overlaps.any() else int(first.sum())


def _find_layers(markers, step_line, kind, start, end):
    """Layer index per step, Z per layer, first line per layer, and the method used.

    ``markers`` are the kernel's comment markers (line, layer kind, Z, name span).
    """
    mk_line, layer_kind, mk_z, _ = markers
    n_steps = len(step_line)
    extruding = (end[:, 3] > start[:, 3]) & ((kind == Kind.EXTRUDE) | (kind == Kind.ARC))
    for k, name in enumerate(slicers.LAYER_KINDS, 1):      # each slicer's own markers, in priority
        sel = layer_kind == k
        if not sel.any():
            continue
        marker_line = mk_line[sel]
        layer = (np.searchsorted(marker_line, step_line, side="right") - 1).astype(np.int32)
        n_layers = len(marker_line)
        # Z of a layer: the first Z comment at or after its marker and before the next marker
        # (';Z:0.2' follows ';LAYER_CHANGE'), else the first extruding step's Z in it
        z = np.full(n_layers, np.nan)
        has_z = ~np.isnan(mk_z)
        if has_z.any():
            zl = np.searchsorted(marker_line, mk_line[has_z], side="right") - 1
            ok = zl >= 0
            uniq, first = np.unique(zl[ok], return_index=True)
            z[uniq] = mk_z[has_z][ok][first]
        ext_layers = layer[extruding]
        ext_z = end[extruding, 2]
        valid = ext_layers >= 0
        if valid.any():
            uniq, first = np.unique(ext_layers[valid], return_index=True)
            missing = np.isnan(z[uniq])
            z[uniq[missing]] = ext_z[valid][first][missing]
        return layer, z, marker_line.astype(np.int64), f"marker:{name}"
    # Fallback: a new layer where an extrusion starts at a Z different from the Z where the previous
    # extrusion ended, i.e. the Z changed in between, by a move that deposits nothing (a layer
    # change). Z-hops come back down before extruding, so they make no layer; in spiral vase mode
    # each extrusion starts where the last one ended, so the spiral is one layer (no invented
    # per-revolution layers without a marker); lines between extrusions that do not move Z (motor
    # instructions, dwells, fan changes) change nothing.
    idx = np.flatnonzero(extruding)
    if len(idx) == 0:
        return np.full(n_steps, -1, np.int32), np.zeros(0), np.zeros(0, np.int64), "none"
    zs = start[idx, 2]
    new = np.ones(len(idx), bool)
    new[1:] = np.abs(zs[1:] - end[idx[:-1], 2]) > 1e-6
    layer_of_ext = np.cumsum(new) - 1
    purge = _purge_layer(idx, layer_of_ext, start, end)
    if purge:
        # the start G-code's purge line at its own Z: before the print, as a marker would put it
        purge_end = int(idx[purge - 1])
        idx, zs, layer_of_ext, new = idx[purge:], zs[purge:], layer_of_ext[purge:] - 1, new[purge:]
    # each step belongs to the layer of the next extruding step (the layer change travel is the
    # new layer's first step); steps after the last extrusion belong to the last layer
    nxt = np.minimum(np.searchsorted(idx, np.arange(n_steps), side="left"), len(idx) - 1)
    layer = layer_of_ext[nxt].astype(np.int32)
    if purge:       # up to the purge's last extrusion; the travel after it is the first layer's
        layer[:purge_end + 1] = -1
    z = zs[new]
    # a layer starts at the first step after the previous layer's last extrusion
    starts = np.zeros(int(new.sum()), np.int64)
    if len(starts) > 1:
        starts[1:] = idx[np.flatnonzero(new)[1:] - 1] + 1
    first_line = step_line[np.minimum(starts, n_steps - 1)]
    return layer, z, first_line.astype(np.int64), "z-change"


def _find_features(data: bytes, markers, step_line):
    """Feature type per step from ';TYPE:' / '; FEATURE:' / '; feature' comments."""
    mk_line, _, _, span = markers
    sel = span[:, 0] >= 0
    if not sel.any():
        return np.full(len(step_line), -1, np.int16), ()
    names = [data[a:b].decode("utf-8", "replace") for a, b in span[sel]]
    uniq = list(dict.fromkeys(names))
    code = {nm: i for i, nm in enumerate(uniq)}
    mcode = np.array([code[nm] for nm in names], np.int16)
    j = np.searchsorted(mk_line[sel], step_line, side="right") - 1
    feature = np.where(j >= 0, mcode[np.maximum(j, 0)], -1).astype(np.int16)
    return feature, tuple(uniq)


_HEADER_PATTERNS = [  # anchored on a literal "\n;" for speed, like the layer markers
    ("slicer", re.compile(rb"\n;[ \t]*(?:generated by|Generated with|Sliced by)[ \t]+([^\r\n]+)")),
    ("slicer", re.compile(rb"\n; ?((?:Cura_SteamEngine|KISSlicer|ideaMaker|Kiri:Moto|IceSL)[^\r\n]*)")),
    ("flavor", re.compile(rb"\n;[ \t]*(?:FLAVOR:|gcode_flavor[ \t]*=[ \t]*|firmware_type[ \t]*=[ \t]*)([^\r\n]+)")),
    ("bed_shape", re.compile(rb"\n;[ \t]*(?:bed_shape|printable_area)[ \t]*=[ \t]*([^\r\n]+)")),
    ("estimated_time", re.compile(rb"\n;[ \t]*estimated printing time(?: \(normal mode\))?[ \t]*=[ \t]*([^\r\n]+)")),
    ("cura_time", re.compile(rb"\n;TIME:(\d+)")),
]
HEADER_BYTES = 100_000   # slicers write their facts in the first and last ~100 kB (config blocks)


def _read_header(data: bytes) -> dict:
    """Facts the slicer wrote about the print: slicer, firmware flavor, bed shape, time estimate."""
    if len(data) <= 2 * HEADER_BYTES:
        head = b"\n" + data
    else:
        head = b"\n" + data[:HEADER_BYTES] + b"\n" + data[-HEADER_BYTES:]
    out = {}
    for key, pat in _HEADER_PATTERNS:
        if key in out:
            continue
        m = pat.search(head)
        if m:
            out[key] = m.group(1).decode("utf-8", "replace").strip()
    bed = out.get("bed_shape")
    if bed:
        try:
            pts = np.array([[float(v) for v in p.split("x")] for p in bed.split(",")])
            out["bed_min_mm"] = tuple(pts.min(axis=0).tolist())
            out["bed_size_mm"] = tuple((pts.max(axis=0) - pts.min(axis=0)).tolist())
        except ValueError:
            pass
    return out


# ------------------------------------------------------------------------------------------------
# what firmware would read differently, or would not do as written: one warning line each
_EXPONENT = re.compile(r"([A-Za-z])([+-]?(?:\d+\.?\d*|\.\d+))[eE]([+-]?\d+)(?![\d.])")


def _exponent_reason(text: str, refused: bool) -> str:
    """What firmware makes of a number with an exponent on ``text`` (``_scan.FLAG_EXPONENT``):
    Marlin's parser.h ``value_float`` stops at 'E'/'e' ("to prevent scientific notation
    interpretation") and its parser.cpp starts a new word there; Klipper's gcode.py splits the
    upper-cased line at every letter. Both read ``X1e400`` as X1 E400."""
    m = _EXPONENT.search(text.split(";")[0])
    if m is None:
        return "a number with an exponent: no firmware reads exponents (it reads an E word)"
    letter, mant, exp = m.group(1).upper(), m.group(2), m.group(3)
    what = f"{m.group(0)}: no firmware reads exponents: Marlin and Klipper both read {letter}{mant} E{exp}"
    if refused:
        return f"{what}, an extruder move nobody meant; write the number without the exponent"
    return f"{what}, and so does gatesopt"


#: feeds beyond any printer, or so slow a move would take minutes per mm (mm/s)
ABSURD_FEED_MM_S = 5000.0       # F300000; the fastest slicer output seen: 500 mm/s
CRAWL_FEED_MM_S = 0.1           # F6; the slowest seen: 2.3 mm/s


def _line_text(data: bytes, line_start, ln: int) -> str:
    return data[line_start[ln]:line_start[ln + 1]].decode("utf-8", "replace").strip()


#: words of the reasons ``per_command`` gives (``stream`` counts those warnings over its chunks)
PER_COMMAND_WORDS = ("unexpanded slicer placeholder", "no firmware reads exponents",
                     "a letter given twice", "a hexadecimal number")


def per_command(lines, data, line_start, l_letter, l_number, name, line_offset, say) -> list[str]:
    """One warning line per command among ``lines`` (its letter and number: M624, G1), at its
    first line, with how many more lines of that command it is said of: a warning repeated on many
    lines is said once, and one on another command is not hidden under it (a Bambu Studio file:
    one ``M970.3`` line with a letter given twice, then 128 base64 ``M624`` lines, once said as
    "M970.3 ... (128 more lines like it)"). ``say(text)``: the reason, from the first line's text."""
    if not len(lines):
        return []
    from ._text import code_words
    key = np.stack([l_letter[lines].astype(np.float64),
                    np.nan_to_num(l_number[lines].astype(np.float64), nan=-1.0)], axis=1)
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    out = []
    for i in np.argsort(first, kind="stable"):
        ln = int(lines[first[i]])
        text = _line_text(data, line_start, ln)
        cmd = (code_words(text) or [text])[0]
        more = f" ({counts[i] - 1} more {cmd} lines like it)" if counts[i] > 1 else ""
        out.append(f"{name}:{ln + 1 + line_offset}: {text[:60]}: {say(text)}{more}")
    return out


def _number_warnings(data, line_start, l_flags, l_letter, l_number, name, line_offset) -> list[str]:
    """Numbers written with an exponent (not on a move: those are refused), letters given twice
    and hexadecimal numbers: a line per command each is on (``per_command``)."""
    out = []
    for flag, say in ((_scan.FLAG_EXPONENT, lambda t: _exponent_reason(t, refused=False)),
                      # Marlin's FASTER_GCODE_PARSER (its default) keeps the last pointer set per
                      # letter (parser.cpp ``set``); Klipper's params dict the last value
                      (_scan.FLAG_REPEATED, lambda t: "a letter given twice: Marlin and Klipper "
                       "take the last value, and so does gatesopt"),
                      (_scan.FLAG_HEX, lambda t: "a hexadecimal number (0x..): firmware reads it "
                       "as 0 and an X word, or as hexadecimal (Marlin on some boards); read here "
                       "as 0 and an X word")):
        out += per_command(np.flatnonzero(l_flags & flag), data, line_start, l_letter, l_number,
                           name, line_offset, say)
    return out


def _feed_warnings(data, line_start, step_line, kind, feed_mm_s, name, line_offset) -> list[str]:
    """A line each for moves at a feed beyond any printer, and at a crawl (``ABSURD_FEED_MM_S``,
    ``CRAWL_FEED_MM_S``): what the firmware does with them (Marlin's planner caps each axis at
    max_feedrate, Klipper's toolhead.py ``Move`` at max_velocity; neither has a minimum feed by
    default), and what the time models do."""
    out = []
    moving = kind <= Kind.ARC
    for bad, say in (
            (moving & (feed_mm_s > ABSURD_FEED_MM_S),
             "beyond any printer: the firmware moves at its own limit instead (Marlin: max_feedrate, "
             "M203; Klipper: max_velocity), as gatesopt's planner time model does; the paper's "
             "T = L/F takes it as written"),
            (moving & (feed_mm_s < CRAWL_FEED_MM_S),
             "a crawl, and the firmware runs it that slowly; F is in mm/min")):
        rows = np.flatnonzero(bad)
        if len(rows):
            r = int(rows[0])
            ln = int(step_line[r])
            more = f", {len(rows) - 1} more moves" if len(rows) > 1 else ""
            out.append(f"{name}:{ln + 1 + line_offset}: {_line_text(data, line_start, ln)[:60]}: "
                       f"feed {feed_mm_s[r]:.4g} mm/s{more}: {say}")
    return out


def _cut_last_line(data, line_start, step_line, kind, name, line_offset) -> str | None:
    """A warning when the file ends inside a move (no line ending after the line of its last
    step, a G0-G3 move): a file cut short (an interrupted copy or upload) ends mid-line, and its
    last move goes somewhere else than the slicer wrote. Another command or a comment without a
    line ending says nothing: a tool may end its file that way (FullControl: ``M84 ; disable
    steppers``)."""
    ln = len(line_start) - 2
    if not data or data.endswith(b"\n") or not len(step_line) or step_line[-1] != ln or kind[-1] > Kind.ARC:
        return None
    return (f"{name}:{ln + 1 + line_offset}: {_line_text(data, line_start, ln)[:60]}: the file ends "
            "inside this move (no line ending after it): was it cut short? Read as it is, as the "
            "firmware would run it")


#: M82/M83 written as a command (not in a comment): the file says how its E words are meant
_E_MODE_CMD = re.compile(rb"(?im)^[ \t]*(?:N\d+[ \t]*)?M8[23](?![0-9])")
_E_MOVE = re.compile(rb"(?im)^[ \t]*(?:N\d+[ \t]*)?G(0?[01]|92)(?![0-9])([^;\r\n]*)")
_WORD = re.compile(rb"([XYExye])[ \t]*([+-]?(?:\d+\.?\d*|\.\d+))")
#: E run backwards over E run forwards on the XY moves before any M82/M83, read as absolute
#: positions, above which a file that never says M82/M83 is read as relative. Measured on the
#: corpus and the fresh slices (whole files, the declaration ignored): 0.000 on every absolute
#: file (wipes aside, E only grows), 0.95-2.2 on every relative file (consecutive lengths differ
#: both ways), 22.6 on Kiri:Moto's undeclared one
UNDECLARED_RELATIVE_RATIO = 0.5
E_MODE_SAMPLE_MOVES = 4000


def undeclared_relative_e(data: bytes, name: str) -> str | None:
    """A warning if the file extrudes before any M82/M83 and its E words only make sense as
    relative lengths, else None; the caller then starts the scan in M83.

    Why: firmware starts in absolute E (Marlin, Klipper's gcode_move), but slicers that leave the
    mode to the printer's start macro (Kiri:Moto's ``print_start``) write relative E. Read as
    absolute, such a file's extrusions look like travels and retractions, and a re-ordered output
    drops half the print when the printer runs it as the slicer meant.
    """
    first_cmd = _E_MODE_CMD.search(data)
    region = data if first_cmd is None else data[:first_cmd.start()]
    prev_e, moves, forward_mm, backward_mm, first_line = 0.0, 0, 0.0, 0.0, None
    for m in _E_MOVE.finditer(region):
        words = {k.decode().upper(): float(v) for k, v in _WORD.findall(m.group(2))}
        if "E" not in words:
            continue
        if m.group(1) == b"92":
            prev_e = words["E"]
            continue
        e = words["E"]
        if "X" in words or "Y" in words:
            moves += 1
            forward_mm += max(e - prev_e, 0.0)
            backward_mm += max(prev_e - e, 0.0)
            if first_line is None:
                first_line = data.count(b"\n", 0, m.start()) + 1
            if moves >= E_MODE_SAMPLE_MOVES:
                break
        prev_e = e
    if moves < 20 or backward_mm <= UNDECLARED_RELATIVE_RATIO * forward_mm:
        return None
    return (f"{name}:{first_line}: extrudes before any M82/M83, and its E words read as absolute "
            f"positions would run the filament {backward_mm:.0f} mm backwards for {forward_mm:.0f} mm "
            f"forwards over the first {moves} moves: read as relative E (M83), as the printer's "
            "start macro must set it; the output keeps the file's own E words")


# ------------------------------------------------------------------------------------------------
def parse(path_or_text, *, source: str | None = None, time=None, flavor: str | None = None,
          state: np.ndarray | None = None, line_offset: int = 0, require_moves: bool = True) -> Program:
    """Parse G-code (a path, a ``.gz`` path, bytes or text) into a lossless ``Program``.

    ``time``: a ``gatesopt.energy.TimeAssumptions`` for durations the paper's T = L/F model
    cannot give (heat-up waits, homing); default: the paper profile's. ``flavor``: "klipper"
    to use Klipper's G90/G91 semantics; default: read from the file's header, else Marlin's.
    ``state`` and ``line_offset`` are for reading a file in pieces (``gatesopt.stream``): the modal
    state before the first line (updated in place to the state after the last), and the number of
    lines before this piece, so that error messages name the line in the whole file; a piece may
    have no moves (``require_moves=False``).
    Raises ``GcodeError`` (one line: ``file:line: text: reason``) for input that is not G-code.
    """
    from .energy import load_profile  # local: energy imports program, parse is imported by both

    data, name = read_input(path_or_text, source)
    warnings = _check_bytes(data, name)
    if time is None:
        time = load_profile("paper").time
    buf = np.frombuffer(data, dtype=np.uint8)
    line_start = _line_starts(buf)
    header = _read_header(data)
    fl = (flavor or header.get("flavor", "")).lower()
    klipper = "klipper" in fl
    state = _scan.initial_state(time.ambient_c, DEFAULT_FEED_MM_S) if state is None else state
    if line_offset == 0 and not state[_scan.STATE_RELATIVE_E]:
        # the file's start (a whole file, or a stream's first piece): its E mode, if unsaid
        relative = undeclared_relative_e(data, name)
        if relative:
            state[_scan.STATE_RELATIVE_E] = 1.0
            warnings.append(relative)
    err, err_line, err_letter, n, arrs, markers = _scan.scan(
        buf, line_start, klipper, time.hotend_heat_c_per_s, time.bed_heat_c_per_s,
        time.ambient_c, time.home_s, DEFAULT_FEED_MM_S, state, SCAN_TABLES)
    if err != _scan.OK:
        text = data[line_start[err_line]:line_start[err_line + 1]].decode("utf-8", "replace")
        letter = chr(err_letter + 65) if err_letter >= 0 else "?"
        reason = (_exponent_reason(text, refused=True) if err == _scan.ERR_EXPONENT else
                  _ERR_TEXT[err].format(L=letter, lim=_scan.ABSURD_E_MM if letter == "E" else _scan.ABSURD_MM))
        if err_line == len(line_start) - 2 and not data.endswith(b"\n"):
            reason += "; the file ends inside this line: was it cut short?"
        raise GcodeError(name, int(err_line) + 1 + line_offset, reason, text=text)
    (s_line, s_kind, s_pos, s_feed, s_len, s_dur, s_fan, s_hot, s_bed, s_arc, s_ccw,
     s_off, s_relxyz, s_rele, s_inch, s_en, l_letter, l_number, l_flags) = arrs
    warnings += per_command(np.flatnonzero(l_flags & 1), data, line_start, l_letter, l_number, name,
                            line_offset, lambda t: "unexpanded slicer placeholder ignored (as the "
                            "firmware ignores a word without a value)")
    warnings += _number_warnings(data, line_start, l_flags, l_letter, l_number, name, line_offset)
    s = slice(0, n)
    step_line, kind = s_line[s], s_kind[s]
    start, end = s_pos[:n], s_pos[1:n + 1]     # views of one buffer: start of step i = end of step i-1
    motion = kind <= Kind.ARC
    if require_moves and not motion.any():
        raise GcodeError(name, None, "no moves: no G0/G1/G2/G3 line with a coordinate")
    markers = _trailing_layer_markers(data, line_start, markers)
    layer, layer_z, layer_line, method = _find_layers(markers, step_line, kind, start, end)
    feature, feature_names = _find_features(data, markers, step_line)
    head = data[:65536]                 # the line ending is the file's convention: its head tells
    crlf = head.count(b"\r\n")
    line_ending = "\r\n" if crlf and crlf >= head.count(b"\n") // 2 else "\n"
    foreign = np.flatnonzero(l_flags & 2)
    if len(foreign):
        ln = int(foreign[0])
        text = data[line_start[ln]:line_start[ln + 1]].decode("utf-8", "replace").strip()
        warnings.append(f"{name}:{ln + 1 + line_offset}: {text[:60]}: {len(foreign)} moves carry an "
                        "axis gatesopt does not model (A B C U V W), ignored in the profile; "
                        "solve and order refuse to rewrite such a file")
    warnings += _feed_warnings(data, line_start, step_line, kind, s_feed[s], name, line_offset)
    cut = _cut_last_line(data, line_start, step_line, kind, name, line_offset)
    if cut:
        warnings.append(cut)
    if require_moves and not (end[:, 3] > start[:, 3]).any():
        warnings.append(f"{name}: no extrusion anywhere (E never increases)")
    m101 = re.search(rb"(?m)^[ \t]*M101\b", data) if b"M101" in data else None
    if m101:
        # BFB / early RepRap firmware switch the extruder on and off (M101 / M103, Cura's "BFB"
        # flavour) instead of moving E: every move reads as a travel here
        ln = data.count(b"\n", 0, m101.start())
        warnings.append(f"{name}:{ln + 1 + line_offset}: M101: the extruder is switched on and off "
                        "(M101/M103) instead of moved with E words: gatesopt models extrusion by E "
                        "only, so the moves it prints count as travel and no curve is re-ordered")
    prog = Program(
        source=name, data=data, line_start=line_start,
        line=step_line, kind=kind, start_mm=start, end_mm=end, feed_mm_s=s_feed[s],
        length_mm=s_len[s], duration_s=s_dur[s], layer=layer, feature=feature, fan=s_fan[s],
        hotend_c=s_hot[s], bed_c=s_bed[s], arc_center_mm=s_arc[s], arc_ccw=s_ccw[s],
        offset_mm=s_off[s], relative_xyz=s_relxyz[s], relative_e=s_rele[s], inch=s_inch[s],
        enabled=s_en[s], feature_names=feature_names, layer_z_mm=layer_z, layer_line=layer_line,
        layer_method=method, line_ending=line_ending, header=header, warnings=tuple(warnings),
        line_letter=l_letter, line_number=l_number, foreign_axis_lines=foreign,
        part_fan_lines=np.flatnonzero(l_flags & _scan.FLAG_PART_FAN),
    )
    for a in (prog.line, prog.kind, prog.start_mm, prog.end_mm, prog.duration_s, prog.enabled):
        a.flags.writeable = False
    return prog


def parse_text(text: str | bytes, *, source: str = "<text>", **kwargs) -> Program:
    """Parse G-code given as text (or bytes), never as a file name: ``parse_text("G1 X10 F600")``.
    The keyword arguments are ``parse``'s."""
    data = text if isinstance(text, bytes) else text.encode("utf-8", "surrogateescape")
    return parse(data, source=source, **kwargs)
