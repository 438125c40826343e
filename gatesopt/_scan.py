"""The compiled core of the parser: one sequential pass over the bytes of a G-code file.

A per-line Python loop parses ~300 k lines/s; this numba kernel tokenizes every line and resolves
the modal state (G90/G91, M82/M83, G92, G20/G21, F, fan, temperatures, motor enables) in the
same pass, writing one row per timed step into preallocated arrays. It knows nothing about
files, layers or errors as text: it returns an error code and the line, and ``parse.py`` turns
that into a message.

Modal semantics follow Marlin 2.x (gcode.h ``set_relative_mode`` clears the E mode bits, so
G90/G91 switch E too), or Klipper's gcode_move.py when ``klipper`` is set (G90/G91 leave the
M82/M83 E mode alone).

The line's words and numbers are read by ``_scan_words.parse_words``; what the slicers and
firmware write (layer markers, Z and feature comments, extended motor commands) comes as packed
tables from the modules that own it and is read by ``_scan_tables``. Numba's on-disk cache keys a
kernel on its own file only (numba's "Notes on Caching": changes in other files are not seen);
the cache directory carries a digest of every source of the package instead
(``_jit.use_versioned_cache``), so the kernel's helpers can live in those modules.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._scan_tables import comment_marker, extended_motor
from ._scan_words import (AXIS_LETTERS, EXT, FOREIGN_AXES, LE, LF, LI, LJ, LP, LR, LS, LT, LX, LY, LZ,
                          parse_words, text_command)

# error codes (parse.py maps them to messages)
OK = 0
ERR_BAD_NUMBER = 1      # a word's number does not parse (X1.2.3, X-, Xnan)
ERR_MISSING_NUMBER = 2  # an axis word without a number on a motion line
ERR_ABSURD = 3          # coordinate beyond ABSURD_MM
ERR_BAD_FEED = 4        # F <= 0
ERR_ARC = 5             # G2/G3 without I/J or R, or R too small for the chord
ERR_BAD_CHAR = 6        # a character that is no part of a G-code word inside a G command
ERR_EXPONENT = 7        # a number written with an exponent on a move or G92 line (FLAG_EXPONENT)
ERR_LETTER_RUN = 8      # a move or G92 line with a letter straight after a letter (``X0xa``)
ERR_HEX = 9             # a move or G92 line with a hexadecimal-looking number (FLAG_HEX)

ABSURD_MM = 100000.0    # 100 m: no printer has this; an X/Y/Z beyond it is corrupt input
ABSURD_E_MM = 1.0e8     # 100 km of filament: E is cumulative, and a 1 kg spool is ~330 m

# Kind values (kept equal to program.Kind)
K_TRAVEL, K_EXTRUDE, K_RETRACT, K_UNRETRACT, K_Z_ONLY, K_ARC, K_DWELL, K_WAIT, K_HOME, K_MOTOR = range(10)

#: ``l_flags`` bit of a line that set the part-cooling fan (``Program.part_fan_lines``)
FLAG_PART_FAN = 4
#: ``l_flags`` bit of a line with a number written with an exponent (``X1e400``), which firmware
#: reads as an E word: on a line whose words are otherwise apart, E words straight after a
#: number, shaped like an exponent (``parse_words`` ``info[2]``); refused on moves and G92
FLAG_EXPONENT = 8
#: ``l_flags`` bit of a line that gives a letter twice (``G1 X0x10``: X0, then X10)
FLAG_REPEATED = 16
#: ``l_flags`` bit of a line with a number written like a hexadecimal one (``Y0x10``): Klipper
#: reads Y0 X10; Marlin's ``value_float`` hands "0x10" to strtod, which reads 16 where the C
#: library reads hexadecimal (32-bit boards) and 0 where it does not (avr-libc); refused on moves
FLAG_HEX = 32

STATE_SIZE = 21   # pos[4], G92 offset[4], enable[4], G91, M83, G20, feed, fan, hotend, bed, reached x2
STATE_RELATIVE_E = 13   # the M83 slot of the state above


def initial_state(ambient_c: float, default_feed_mm_s: float) -> np.ndarray:
    """The printer at power-on: at the origin, absolute mm, motors on, heaters at ambient."""
    st = np.zeros(STATE_SIZE)
    st[8:12] = 1.0
    st[15] = default_feed_mm_s
    st[19] = st[20] = ambient_c
    return st


@njit(cache=True)
def line_starts(buf):
    """Byte offset of each line's start, plus len(buf) at the end (no file-sized temporaries)."""
    n = 0
    for c in buf:
        if c == 10:
            n += 1
    last_open = buf.shape[0] > 0 and buf[buf.shape[0] - 1] != 10
    out = np.empty(n + 1 + (1 if last_open else 0), np.int64)
    out[0] = 0
    k = 1
    for i in range(buf.shape[0]):
        if buf[i] == 10:
            out[k] = i + 1
            k += 1
    if last_open:
        out[k] = buf.shape[0]
    return out


@njit(cache=True)
def _step_arrays(n_lines):
    """The kernel's output arrays, untrimmed (one step row at most per line; the caller slices the
    step arrays to the steps written): step rows, then per line letter, number, flags."""
    # one position buffer: row 0 is the start position, row i+1 the end of step i, so that
    # start_mm = s_pos[:-1] and end_mm = s_pos[1:] are two views of the same memory
    return (np.empty(n_lines, np.int64), np.empty(n_lines, np.int8), np.empty((n_lines + 1, 4), np.float64),
            np.empty(n_lines, np.float64), np.empty(n_lines, np.float64), np.empty(n_lines, np.float64),
            np.empty(n_lines, np.float32), np.empty(n_lines, np.float32), np.empty(n_lines, np.float32),
            np.empty((n_lines, 2), np.float64), np.zeros(n_lines, np.bool_), np.empty((n_lines, 4), np.float64),
            np.empty(n_lines, np.bool_), np.empty(n_lines, np.bool_), np.empty(n_lines, np.bool_),
            np.empty((n_lines, 4), np.bool_),
            # per line: the first word's letter and number, and flags: bit 0 an unexpanded
            # {placeholder} was dropped; bit 1 a G0-G3 line carries an axis the model has not got
            # (A B C U V W); bit 2 an M106 / M107 set the part-cooling fan (FLAG_PART_FAN); bit 3
            # a number with an exponent (FLAG_EXPONENT); bit 4 a letter given twice (FLAG_REPEATED)
            np.zeros(n_lines, np.uint8), np.full(n_lines, np.nan, np.float32), np.zeros(n_lines, np.uint8))


@njit(cache=True)
def _grow_markers(mk_line, mk_kind, mk_z, mk_span, n_mk):
    """The comment-marker arrays (line, layer kind, Z, feature-name span) at twice the size."""
    cap = 2 * n_mk
    t1 = np.empty(cap, np.int64)
    t1[:n_mk] = mk_line
    t2 = np.empty(cap, np.int16)
    t2[:n_mk] = mk_kind
    t3 = np.empty(cap, np.float64)
    t3[:n_mk] = mk_z
    t4 = np.empty((cap, 2), np.int64)
    t4[:n_mk] = mk_span
    return t1, t2, t3, t4


@njit(cache=True)
def _arc(present, value, bad, pos, tgt, scale, ccw):
    """(error, letter, centre x, centre y, length) of a G2/G3 arc from ``pos`` to ``tgt``: the
    centre from I/J, else from R (Marlin G2_G3.cpp), the length along the helix."""
    for k in (LI, LJ, LR):
        if bad[k]:
            return ERR_BAD_NUMBER, k, np.nan, np.nan, 0.0
    dx = tgt[0] - pos[0]
    dy = tgt[1] - pos[1]
    if present[LI] or present[LJ]:
        ii = value[LI] * scale if present[LI] and not np.isnan(value[LI]) else 0.0
        jj = value[LJ] * scale if present[LJ] and not np.isnan(value[LJ]) else 0.0
        cx = pos[0] + ii
        cy = pos[1] + jj
    elif present[LR] and not np.isnan(value[LR]):
        r = value[LR] * scale
        d = math.hypot(dx, dy)
        if d == 0.0:
            return ERR_ARC, LR, np.nan, np.nan, 0.0
        h2 = r * r - 0.25 * d * d
        if h2 < -1e-6 * max(1.0, r * r):
            return ERR_ARC, LR, np.nan, np.nan, 0.0
        h = math.sqrt(max(h2, 0.0))
        # Marlin G2_G3.cpp: e = clockwise ^ (r < 0) ? -1 : 1
        e = -1.0 if ((not ccw) != (r < 0)) else 1.0
        sx = -dy / d
        sy = dx / d
        cx = 0.5 * (pos[0] + tgt[0]) + e * h * sx
        cy = 0.5 * (pos[1] + tgt[1]) + e * h * sy
    else:
        return ERR_ARC, LI, np.nan, np.nan, 0.0
    rad = math.hypot(pos[0] - cx, pos[1] - cy)
    a0 = math.atan2(pos[1] - cy, pos[0] - cx)
    a1 = math.atan2(tgt[1] - cy, tgt[0] - cx)
    sweep = (a1 - a0) if ccw else (a0 - a1)
    # same end point = full circle (Marlin: angular_travel == 0 -> 2*pi)
    if sweep <= 1e-9:
        sweep += 2.0 * math.pi
    return OK, -1, cx, cy, math.hypot(rad * sweep, tgt[2] - pos[2])


@njit(cache=True)
def _dwell_s(present, value):
    """G4's duration: P in ms, else S in s."""
    if present[LP] and not np.isnan(value[LP]):
        return max(value[LP], 0.0) / 1000.0
    if present[LS] and not np.isnan(value[LS]):
        return max(value[LS], 0.0)
    return 0.0


@njit(cache=True)
def _home(present, pos, tgt, off, en):
    """G28: the named axes (all of X Y Z without a name) to 0, their G92 offsets cleared, their
    motors on; ``tgt`` is the end point."""
    named = present[LX] or present[LY] or present[LZ]
    for q in range(4):
        tgt[q] = pos[q]
    for q in range(3):
        if (not named) or present[AXIS_LETTERS[q]]:
            tgt[q] = 0.0
            off[q] = 0.0
            en[q] = True


@njit(cache=True)
def _set_offsets(present, value, bad, pos, off, scale):
    """G92: the named axes' positions set (all to zero without a name, as Marlin); (error, letter)."""
    anyg = False
    for q in range(4):
        k = AXIS_LETTERS[q]
        if bad[k]:
            return ERR_BAD_NUMBER, k
        if present[k]:
            v = 0.0 if np.isnan(value[k]) else value[k] * scale
            off[q] = pos[q] - v
            anyg = True
    if not anyg:
        for q in range(4):
            off[q] = pos[q]
    return OK, -1


@njit(cache=True)
def _heat(m, present, value, hot, bed, hot_reached, bed_reached, hot_rate, bed_rate):
    """M104/M109/M140/M190: (hotend, bed, hotend reached, bed reached, kind or -1, duration). A
    wait (M109, M190) heats from the last temperature waited for (paper.toml [time])."""
    bed_cmd = m == 140.0 or m == 190.0
    t = value[LS] if present[LS] else (value[LR] if present[LR] else np.nan)
    if not np.isnan(t):
        if bed_cmd:
            bed = t
        else:
            hot = t
    if m == 104.0 or m == 140.0:
        return hot, bed, hot_reached, bed_reached, -1, 0.0
    target = bed if bed_cmd else hot
    reached = bed_reached if bed_cmd else hot_reached
    dur = 0.0
    if target > 0:
        dur = abs(target - reached) / (bed_rate if bed_cmd else hot_rate)
        if bed_cmd:
            bed_reached = target
        else:
            hot_reached = target
    return hot, bed, hot_reached, bed_reached, K_WAIT, dur


@njit(cache=True)
def _part_fan(m, present, value, fan):
    """M106/M107: (fan 0-1, the line set the part-cooling fan). Only the part-cooling fan (no P,
    or P0) counts."""
    if present[LP] and not np.isnan(value[LP]) and value[LP] != 0.0:
        return fan, False
    if m == 107.0:
        return 0.0, True
    s = value[LS] if present[LS] and not np.isnan(value[LS]) else 255.0
    return min(max(s / 255.0, 0.0), 1.0), True


@njit(cache=True)
def _motor_m(m, present, en):
    """M17/M18/M84: the named motors (all without a name) on (M17) or off; K_MOTOR, or -1 for
    ``M18 S<sec>`` / ``M84 S<sec>`` (an idle timeout, not a disable)."""
    named = False
    for q in range(4):
        if present[AXIS_LETTERS[q]]:
            named = True
    if not named and (present[LS] or present[LT]):
        return -1
    for q in range(4):
        if (not named) or present[AXIS_LETTERS[q]]:
            en[q] = m == 17.0
    return K_MOTOR


@njit(cache=True)
def _motor_s(number, present, en):
    """The S-series (3DGates Table 3): ``S1 X`` on, ``S0 X`` off; K_MOTOR, or -1 without a motor."""
    if not (number == 0.0 or number == 1.0):
        return -1
    named = False
    for q in range(4):
        if present[AXIS_LETTERS[q]]:
            en[q] = number == 1.0
            named = True
    return K_MOTOR if named else -1


@njit(cache=True)
def scan(buf, line_start, klipper, hot_rate, bed_rate, ambient_c, home_s, default_feed_mm_s, state,
         tables):
    """One pass over all lines. Returns (error, error_line, error_letter, n_steps, arrays, markers).

    ``state`` (float64, STATE_SIZE) is the modal state before the first line (see ``initial_state``)
    and is updated in place to the state after the last line, so a file can be scanned chunk by
    chunk (``gatesopt.stream``) with the same result as in one piece. ``tables``: (marker rows,
    marker text, motor commands, motor names, motor text), from ``pack_comment_markers`` and
    ``pack_motor_commands``. ``markers``: per comment line with a marker its line, layer kind
    (1-based, 0: none), Z (NaN: none) and feature-name span (-1: none).

    A numba kernel, long on purpose: the modal state lives in local variables across the line
    loop, and the hot path (G0/G1 lines, nearly every line of a print) is written out here with
    every step row; what the other commands do is in the helpers above (and the tokenizer in
    ``_scan_words``). Measured (CPU time of the
    240 k G-code lines of prusa25_bunny_triangles15_lh01): the G0-G3 path written out 24.5 ms, as
    four njit helpers 25.8 ms, the same with ``inline="always"`` 31 ms; on prusa25_xend_honey25_acp
    one ``_move`` helper returning eight values took 34.6 ms against 26.2 ms before the split.
    """
    mk_rows, mk_text, motor_cmds, motor_names, motor_text = tables
    n_lines = line_start.shape[0] - 1
    arrs = _step_arrays(n_lines)
    (s_line, s_kind, s_pos, s_feed, s_len, s_dur, s_fan, s_hot, s_bed, s_arc, s_ccw,
     s_off, s_relxyz, s_rele, s_inch, s_en, l_letter, l_number, l_flags) = arrs
    mk_line = np.empty(1024, np.int64)
    mk_kind = np.empty(1024, np.int16)
    mk_z = np.empty(1024, np.float64)
    mk_span = np.empty((1024, 2), np.int64)
    n_mk = 0
    no_markers = (np.empty(0, np.int64), np.empty(0, np.int16), np.empty(0, np.float64), np.empty((0, 2), np.int64))
    info = np.zeros(6, np.int64)
    touched = np.zeros(27, np.int64)
    present = np.zeros(26, np.bool_)
    value = np.full(26, np.nan)
    bad = np.zeros(26, np.bool_)
    pos = state[0:4].copy()
    off = state[4:8].copy()
    tgt = np.zeros(4)
    en = state[8:12] != 0.0
    rel_xyz = state[12] != 0.0
    rel_e = state[13] != 0.0
    inch = state[14] != 0.0
    feed = state[15]
    fan = state[16]
    hot = state[17]
    bed = state[18]
    hot_reached = state[19]
    bed_reached = state[20]
    s_pos[0, :] = pos
    n = 0
    for ln in range(n_lines):
        a = line_start[ln]
        b = line_start[ln + 1]
        while b > a and (buf[b - 1] == 10 or buf[b - 1] == 13):      # strip the line ending
            b -= 1
        c0 = a
        while c0 < b and (buf[c0] == 32 or buf[c0] == 9):
            c0 += 1
        if c0 < b and buf[c0] == 59:
            kind, zc, na, nb = comment_marker(buf, c0, b, mk_rows, mk_text)
            if kind != 0 or not np.isnan(zc) or na >= 0:
                if n_mk == mk_line.shape[0]:
                    mk_line, mk_kind, mk_z, mk_span = _grow_markers(mk_line, mk_kind, mk_z, mk_span, n_mk)
                mk_line[n_mk] = ln
                mk_kind[n_mk] = kind
                mk_z[n_mk] = zc
                mk_span[n_mk, 0] = na
                mk_span[n_mk, 1] = nb
                n_mk += 1
            continue
        letter, number, fpos, lenient = parse_words(buf, a, b, present, value, bad, info, touched)
        if info[0] != 0:
            l_flags[ln] |= 1
        if (info[2] != 0 or info[3] != 0 or info[5] != 0) and (
                letter == 71 or (letter == 77 and not text_command(number))):
            if info[2] != 0 and info[2] == info[1]:
                l_flags[ln] |= FLAG_EXPONENT
            if info[3] != 0:
                l_flags[ln] |= FLAG_REPEATED
            if info[5] != 0:
                l_flags[ln] |= FLAG_HEX
        l_letter[ln] = letter
        l_number[ln] = number
        if letter == 0:
            continue
        scale = 25.4 if inch else 1.0
        kind = -1
        dur = 0.0
        length = 0.0
        cx = np.nan
        cy = np.nan
        ccw = False
        if letter == EXT:
            if extended_motor(buf, fpos, b, en, motor_cmds, motor_names, motor_text):
                kind = K_MOTOR
        elif letter == 71:  # G
            g = number
            if lenient:
                # the tokenizer stopped at a stray character: firmware would read on past it and
                # we would not; a G command we cannot read the way the firmware does is corrupt
                return ERR_BAD_CHAR, ln, -1, n, arrs, no_markers
            if (l_flags[ln] & FLAG_EXPONENT) != 0 and (g == 0.0 or g == 1.0 or g == 2.0 or g == 3.0
                                                       or g == 92.0):
                # firmware moves by an E word the writer did not mean (X1e400: 400 mm of filament)
                return ERR_EXPONENT, ln, LE, n, arrs, no_markers
            if (l_flags[ln] & FLAG_HEX) != 0 and (g == 0.0 or g == 1.0 or g == 2.0 or g == 3.0
                                                  or g == 92.0):
                return ERR_HEX, ln, -1, n, arrs, no_markers
            if g == 0.0 or g == 1.0 or g == 2.0 or g == 3.0:
                any_axis = False
                for q in range(4):
                    k = AXIS_LETTERS[q]
                    if bad[k]:
                        return ERR_BAD_NUMBER, ln, k, n, arrs, no_markers
                    if present[k]:
                        if np.isnan(value[k]):
                            return ERR_MISSING_NUMBER, ln, k, n, arrs, no_markers
                        any_axis = True
                if bad[LF]:
                    return ERR_BAD_NUMBER, ln, LF, n, arrs, no_markers
                if present[LF]:
                    if np.isnan(value[LF]):
                        return ERR_MISSING_NUMBER, ln, LF, n, arrs, no_markers
                    if value[LF] <= 0.0:
                        return ERR_BAD_FEED, ln, LF, n, arrs, no_markers
                    feed = value[LF] * scale / 60.0
                if info[4] != 0:
                    return ERR_LETTER_RUN, ln, -1, n, arrs, no_markers
                for k in FOREIGN_AXES:
                    if present[k]:
                        l_flags[ln] |= 2
                arc = g >= 2.0
                if not any_axis and not arc:
                    continue
                for q in range(4):
                    k = AXIS_LETTERS[q]
                    limit = ABSURD_E_MM if q == 3 else ABSURD_MM
                    if present[k]:
                        v = value[k] * scale
                        if abs(v) > limit:
                            return ERR_ABSURD, ln, k, n, arrs, no_markers
                        rel = rel_e if q == 3 else rel_xyz
                        tgt[q] = pos[q] + v if rel else v + off[q]
                    else:
                        tgt[q] = pos[q]
                    if abs(tgt[q]) > limit:
                        return ERR_ABSURD, ln, k, n, arrs, no_markers
                if arc:
                    ccw = g == 3.0
                    err, err_k, cx, cy, length = _arc(present, value, bad, pos, tgt, scale, ccw)
                    if err != OK:
                        return err, ln, err_k, n, arrs, no_markers
                    kind = K_ARC
                else:
                    dx = tgt[0] - pos[0]
                    dy = tgt[1] - pos[1]
                    dz = tgt[2] - pos[2]
                    de = tgt[3] - pos[3]
                    length = math.sqrt(dx * dx + dy * dy + dz * dz)
                    moved_xy = dx != 0.0 or dy != 0.0
                    if de < 0.0:
                        kind = K_RETRACT
                    elif de > 0.0:
                        kind = K_EXTRUDE if (moved_xy or dz != 0.0) else K_UNRETRACT
                    else:
                        kind = K_TRAVEL if (moved_xy or dz == 0.0) else K_Z_ONLY
                if length == 0.0:
                    length = abs(tgt[3] - pos[3])
                dur = length / feed
            elif g == 4.0:
                dur = _dwell_s(present, value)
                kind = K_DWELL
            elif g == 28.0:
                _home(present, pos, tgt, off, en)
                dur = home_s
                kind = K_HOME
            elif g == 90.0 or g == 91.0:
                rel_xyz = g == 91.0
                if not klipper:     # Marlin: G90/G91 switch E too; Klipper leaves M82/M83 alone
                    rel_e = rel_xyz
            elif g == 20.0 or g == 21.0:
                inch = g == 20.0
            elif g == 92.0:
                err, err_k = _set_offsets(present, value, bad, pos, off, scale)
                if err != OK:
                    return err, ln, err_k, n, arrs, no_markers
                if info[4] != 0:
                    return ERR_LETTER_RUN, ln, -1, n, arrs, no_markers
        elif letter == 77:  # M
            m = number
            if m == 82.0 or m == 83.0:
                rel_e = m == 83.0
            elif m == 104.0 or m == 109.0 or m == 140.0 or m == 190.0:
                hot, bed, hot_reached, bed_reached, kind, dur = _heat(
                    m, present, value, hot, bed, hot_reached, bed_reached, hot_rate, bed_rate)
            elif m == 106.0 or m == 107.0:
                fan, part = _part_fan(m, present, value, fan)
                if part:
                    l_flags[ln] |= FLAG_PART_FAN
            elif m == 17.0 or m == 18.0 or m == 84.0:
                kind = _motor_m(m, present, en)
        elif letter == 83:  # S-series
            kind = _motor_s(number, present, en)
        if kind < 0:        # no step: a mode, an offset, a fan, a line the model ignores
            continue
        if kind == K_DWELL or kind == K_WAIT or kind == K_MOTOR:
            for q in range(4):          # rows that take time without moving
                tgt[q] = pos[q]
        # ---- write the step row
        s_line[n] = ln
        s_kind[n] = kind
        for q in range(4):
            s_pos[n + 1, q] = tgt[q]
            s_off[n, q] = off[q]
        s_feed[n] = feed
        s_len[n] = length
        s_dur[n] = dur
        s_fan[n] = fan
        s_hot[n] = hot
        s_bed[n] = bed
        s_arc[n, 0] = cx
        s_arc[n, 1] = cy
        s_ccw[n] = ccw
        s_relxyz[n] = rel_xyz
        s_rele[n] = rel_e
        s_inch[n] = inch
        # a motor that steps is on (every firmware enables an axis to move it), and stays on
        if kind <= K_ARC:
            for q in range(4):
                if tgt[q] != pos[q] or (kind == K_ARC and q < 2):
                    en[q] = True
        for q in range(4):
            s_en[n, q] = en[q]
            pos[q] = tgt[q]
        n += 1
    _save_state(state, pos, off, en, rel_xyz, rel_e, inch, feed, fan, hot, bed, hot_reached, bed_reached)
    markers = (mk_line[:n_mk].copy(), mk_kind[:n_mk].copy(), mk_z[:n_mk].copy(), mk_span[:n_mk].copy())
    return OK, -1, -1, n, arrs, markers


@njit(cache=True)
def _save_state(state, pos, off, en, rel_xyz, rel_e, inch, feed, fan, hot, bed, hot_reached, bed_reached):
    """The modal state after the last line, into ``state`` (the layout of ``initial_state``)."""
    state[0:4] = pos
    state[4:8] = off
    for q in range(4):
        state[8 + q] = 1.0 if en[q] else 0.0
    state[12] = 1.0 if rel_xyz else 0.0
    state[13] = 1.0 if rel_e else 0.0
    state[14] = 1.0 if inch else 0.0
    state[15] = feed
    state[16] = fan
    state[17] = hot
    state[18] = bed
    state[19] = hot_reached
    state[20] = bed_reached
