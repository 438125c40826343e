"""The compiled core of the parser: one sequential pass over the bytes of a G-code file.

A per-line Python loop parses ~300 k lines/s; this numba kernel tokenizes every line and resolves
the modal state (G90/G91, M82/M83, G92, G20/G21, F, fan, temperatures, motor enables) in the
same pass, writing one row per timed step into preallocated arrays. It knows nothing about
files, layers or errors as text: it returns an error code and the line, and ``parse.py`` turns
that into a message.

Modal semantics follow Marlin 2.x (gcode.h ``set_relative_mode`` clears the E mode bits, so
G90/G91 switch E too), or Klipper's gcode_move.py when ``klipper`` is set (G90/G91 leave the
M82/M83 E mode alone).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

# error codes (parse.py maps them to messages)
OK = 0
ERR_BAD_NUMBER = 1      # a word's number does not parse (X1.2.3, X-, Xnan)
ERR_MISSING_NUMBER = 2  # an axis word without a number on a motion line
ERR_ABSURD = 3          # coordinate beyond ABSURD_MM
ERR_BAD_FEED = 4        # F <= 0
ERR_ARC = 5             # G2/G3 without I/J or R, or R too small for the chord
ERR_BAD_CHAR = 6        # a character that is no part of a G-code word inside a G command

ABSURD_MM = 100000.0    # 100 m: no printer has this; an X/Y/Z beyond it is corrupt input
ABSURD_E_MM = 1.0e8     # 100 km of filament: E is cumulative, and a 1 kg spool is ~330 m

# Kind values (kept equal to program.Kind)
K_TRAVEL, K_EXTRUDE, K_RETRACT, K_UNRETRACT, K_Z_ONLY, K_ARC, K_DWELL, K_WAIT, K_HOME, K_MOTOR = range(10)

# letters we care about, index = ord(c) - 65
_A = 65
LX, LY, LZ, LE, LF = 23, 24, 25, 4, 5
LI, LJ, LR, LP, LS = 8, 9, 17, 15, 18
LT = 19
# axes a move may carry that the model has not got: rotary A B C, secondary linear U V W (Mach3 and
# machinekit flavours write the extruder as A). Flagged per line (parse.py), never modelled
FOREIGN_AXES = (0, 1, 2, 20, 21, 22)

EXT = 64        # '@': line starts with an extended (Klipper-style) command word
POW10 = 10.0 ** np.arange(40)
SET_STEPPER_ENABLE = np.frombuffer(b"SET_STEPPER_ENABLE", dtype=np.uint8)
STEPPER_ = np.frombuffer(b"STEPPER=STEPPER_", dtype=np.uint8)
ENABLE_ = np.frombuffer(b"ENABLE=", dtype=np.uint8)

# Comment markers the slicers write (layers, Z, feature types). Found here, in the same pass, so the
# Python side never scans the text again. Marker code bits: 0-2 layer marker kind (see LAYER_KINDS,
# 1-based, in priority order), 8 = the line carries a Z, 16 = the line names a feature type.
LAYER_KINDS = ("prusaslicer", "bambu", "cura", "simplify3d", "slic3r", "kisslicer", "comment")
MK_Z = 8
MK_FEATURE = 16
P_LAYER_CHANGE = np.frombuffer(b";LAYER_CHANGE", dtype=np.uint8)      # PrusaSlicer, SuperSlicer, Orca
P_CHANGE_LAYER = np.frombuffer(b"; CHANGE_LAYER", dtype=np.uint8)     # Bambu Studio
P_LAYER_COLON = np.frombuffer(b";LAYER:", dtype=np.uint8)             # Cura, ideaMaker
P_S3D = np.frombuffer(b"; layer ", dtype=np.uint8)                    # Simplify3D: '; layer 3, Z = 0.6'
P_S3D_Z = np.frombuffer(b", Z = ", dtype=np.uint8)
P_SLIC3R = np.frombuffer(b"; move to next layer (", dtype=np.uint8)   # Slic3r 1.x verbose
P_KISS = np.frombuffer(b"; BEGIN_LAYER_OBJECT", dtype=np.uint8)       # KISSlicer: '... z=0.3'
P_KISS_Z = np.frombuffer(b" z=", dtype=np.uint8)
P_AYER = np.frombuffer(b"AYER", dtype=np.uint8)                        # ';layer 3' etc., any case
P_Z = np.frombuffer(b"Z:", dtype=np.uint8)                            # ';Z:0.2'
P_Z_HEIGHT = np.frombuffer(b"Z_HEIGHT:", dtype=np.uint8)              # '; Z_HEIGHT: 0.2'
P_TYPE = np.frombuffer(b"TYPE:", dtype=np.uint8)                      # ';TYPE:Perimeter'
P_FEATURE = np.frombuffer(b"FEATURE:", dtype=np.uint8)                # '; FEATURE: Outer wall'
P_FEATURE_LC = np.frombuffer(b"feature ", dtype=np.uint8)             # '; feature inner perimeter'


@njit(cache=True)
def _match(buf, i, end, pat):
    """buf[i:i+len(pat)] equals pat exactly."""
    n = pat.shape[0]
    if i + n > end:
        return False
    for k in range(n):
        if buf[i + k] != pat[k]:
            return False
    return True


@njit(cache=True)
def _find(buf, i, end, pat):
    """First position >= i of pat in buf[:end], or -1."""
    n = pat.shape[0]
    for j in range(i, end - n + 1):
        if _match(buf, j, end, pat):
            return j
    return -1


@njit(cache=True, inline="always")     # on the hot path: inlined, as the code it replaced was
def _scan_number(buf, j, end):
    """[+-]digits[.digits] at j: (value, digits read, position after it).

    The value is an integer mantissa divided once by a power of ten: for up to 15 significant
    digits that is the correctly rounded double, equal to float(text). Digits beyond 18 scale the
    value instead (such numbers are absurd anyway). NaN when there are no digits.
    """
    neg = False
    if j < end and (buf[j] == 45 or buf[j] == 43):
        neg = buf[j] == 45
        j += 1
    mant = 0
    nd = 0
    nfrac = 0
    while j < end and 48 <= buf[j] <= 57:
        if nd < 18:
            mant = mant * 10 + (buf[j] - 48)
            nd += 1
        else:
            nfrac -= 1
        j += 1
    if j < end and buf[j] == 46:
        j += 1
        while j < end and 48 <= buf[j] <= 57:
            if nd < 18:
                mant = mant * 10 + (buf[j] - 48)
                nd += 1
                nfrac += 1
            j += 1
    if nd == 0:
        return np.nan, 0, j
    v = mant / POW10[nfrac] if nfrac >= 0 else mant * POW10[-nfrac]
    return (-v if neg else v), nd, j


@njit(cache=True)
def _number_at(buf, i, end):
    """A decimal number starting at i (blanks skipped), NaN if none."""
    while i < end and (buf[i] == 32 or buf[i] == 9):
        i += 1
    return _scan_number(buf, i, end)[0]


@njit(cache=True)
def _comment_marker(buf, i, b):
    """Markers on a comment line starting at i (buf[i] == ';'). Returns (code, z, name_a, name_b)."""
    code = 0
    z = np.nan
    na = -1
    nb = -1
    if _match(buf, i, b, P_LAYER_CHANGE):
        code = 1
    elif _match(buf, i, b, P_CHANGE_LAYER):
        code = 2
    elif _match(buf, i, b, P_LAYER_COLON) and i + 7 < b and (buf[i + 7] == 45 or 48 <= buf[i + 7] <= 57):
        code = 3
    elif _match(buf, i, b, P_S3D) and i + 8 < b and 48 <= buf[i + 8] <= 57:
        code = 4
        j = _find(buf, i + 8, b, P_S3D_Z)
        if j >= 0:
            z = _number_at(buf, j + P_S3D_Z.shape[0], b)
    elif _match(buf, i, b, P_SLIC3R):
        code = 5
    elif _match(buf, i, b, P_KISS):
        code = 6
        j = _find(buf, i + P_KISS.shape[0], b, P_KISS_Z)
        if j >= 0:
            z = _number_at(buf, j + P_KISS_Z.shape[0], b)
    j = i + 1
    while j < b and (buf[j] == 32 or buf[j] == 9):
        j += 1
    if code == 0 and j + 5 < b and _upper(buf[j]) == 76 and _match_upper(buf, j + 1, b, P_AYER) \
            and (buf[j + 5] == 32 or buf[j + 5] == 95 or buf[j + 5] == 58):
        k = j + 6
        while k < b and buf[k] == 32:
            k += 1
        if k < b and 48 <= buf[k] <= 57:
            code = 7
    if _match(buf, j, b, P_Z):
        z = _number_at(buf, j + 2, b)
    elif _match(buf, j, b, P_Z_HEIGHT):
        z = _number_at(buf, j + P_Z_HEIGHT.shape[0], b)
    if not np.isnan(z):
        code |= MK_Z
    if _match(buf, j, b, P_TYPE):
        na = j + P_TYPE.shape[0]
    elif _match(buf, j, b, P_FEATURE):
        na = j + P_FEATURE.shape[0]
    elif _match(buf, j, b, P_FEATURE_LC):
        na = j + P_FEATURE_LC.shape[0]
    if na >= 0:
        while na < b and (buf[na] == 32 or buf[na] == 9):
            na += 1
        nb = b
        while nb > na and (buf[nb - 1] == 32 or buf[nb - 1] == 9):
            nb -= 1
        code |= MK_FEATURE
    return code, z, na, nb


@njit(cache=True, inline="always")
def _is_letter(c):
    return (65 <= c <= 90) or (97 <= c <= 122)


@njit(cache=True, inline="always")
def _upper(c):
    return c - 32 if 97 <= c <= 122 else c


@njit(cache=True)
def _match_upper(buf, i, end, pat):
    """buf[i:i+len(pat)] equals pat, case-insensitively."""
    n = pat.shape[0]
    if i + n > end:
        return False
    for k in range(n):
        if _upper(buf[i + k]) != pat[k]:
            return False
    return True


@njit(cache=True)
def _parse_words(buf, a, b, present, value, bad, placeholder, touched):
    """Tokenize buf[a:b] (one line, no line ending). Fills present/value/bad per letter.

    Returns (cmd_letter, cmd_number, first_word_pos, lenient_stop) where cmd_letter is the
    upper-case ASCII code of the first word's letter (0 if none, EXT for an extended command).
    ``bad[k]`` marks a letter whose number failed to parse.
    """
    placeholder[0] = False
    # reset only the letters the previous line set (touched[0] counts them, touched[1:] lists them):
    # resetting all 3 x 26 slots on every line cost more than the rest of the tokenizer
    for t in range(1, touched[0] + 1):
        k = touched[t]
        present[k] = False
        value[k] = np.nan
        bad[k] = False
    touched[0] = 0
    i = a
    # skip blanks
    while i < b and (buf[i] == 32 or buf[i] == 9):
        i += 1
    # line number N123
    if i < b and (buf[i] == 78 or buf[i] == 110) and i + 1 < b and 48 <= buf[i + 1] <= 57:
        i += 1
        while i < b and 48 <= buf[i] <= 57:
            i += 1
    cmd_letter = 0
    cmd_number = np.nan
    first = True
    first_pos = -1
    while i < b:
        c = buf[i]
        if c == 32 or c == 9 or c == 13:
            i += 1
            continue
        if c == 59:             # ';' comment to end of line
            break
        if c == 42:             # '*' checksum
            break
        if c == 40:             # '(' comment to ')'
            while i < b and buf[i] != 41:
                i += 1
            i += 1
            continue
        if c == 34:             # '"' quoted string: stop (string parameters, M486 A"..", M117)
            break
        if not _is_letter(c):
            # stray character: mark as trouble on the previous word if any, stop
            if first:
                cmd_letter = 0
            return cmd_letter, cmd_number, first_pos, True
        L = _upper(c)
        if first and i + 1 < b and (_is_letter(buf[i + 1]) or buf[i + 1] == 95):
            # extended command word (SET_VELOCITY_LIMIT, EXCLUDE_OBJECT_START, ...)
            return EXT, np.nan, i, True
        i += 1
        v, nd, j = _scan_number(buf, i, b)
        k = L - _A
        if touched[0] < 26:
            touched[0] += 1
            touched[touched[0]] = k
        if nd == 0 and j == i and j < b and buf[j] == 123 and not first:
            # '{placeholder}' a slicer left unexpanded: Marlin's seenval() ignores a word without
            # a valid value, so the word is dropped (parse.py warns)
            while j < b and buf[j] != 125:
                j += 1
            i = j + 1
            placeholder[0] = True
            continue
        if nd == 0 and j > i:   # a sign or dot without digits
            bad[k] = True
        # what follows a number must end the word
        if nd > 0 and j < b:
            cj = buf[j]
            if not (cj == 32 or cj == 9 or cj == 13 or cj == 59 or cj == 42 or cj == 40 or _is_letter(cj)):
                bad[k] = True
                # skip the rest of this malformed token
                while j < b and not (buf[j] == 32 or buf[j] == 9 or buf[j] == 59):
                    j += 1
        if first:
            cmd_letter = L
            cmd_number = v
            first_pos = i - 1
            first = False
        else:
            present[k] = True
            value[k] = v
        i = j
    return cmd_letter, cmd_number, first_pos, False


#: ``l_flags`` bit of a line that set the part-cooling fan (``Program.part_fan_lines``)
FLAG_PART_FAN = 4

STATE_SIZE = 21   # pos[4], G92 offset[4], enable[4], G91, M83, G20, feed, fan, hotend, bed, reached x2


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
def scan(buf, line_start, klipper, hot_rate, bed_rate, ambient_c, home_s, default_feed_mm_s, state):
    """One pass over all lines. Returns (error, error_line, error_letter, n_steps, arrays, markers).

    ``state`` (float64, STATE_SIZE) is the modal state before the first line (see ``initial_state``)
    and is updated in place to the state after the last line, so a file can be scanned chunk by
    chunk (``gatesopt.stream``) with the same result as in one piece.
    """
    n_lines = line_start.shape[0] - 1
    nmax = n_lines
    s_line = np.empty(nmax, np.int64)
    s_kind = np.empty(nmax, np.int8)
    # one position buffer: row 0 is the start position, row i+1 the end of step i, so that
    # start_mm = s_pos[:-1] and end_mm = s_pos[1:] are two views of the same memory
    s_pos = np.empty((nmax + 1, 4), np.float64)
    s_feed = np.empty(nmax, np.float64)
    s_len = np.empty(nmax, np.float64)
    s_dur = np.empty(nmax, np.float64)
    s_fan = np.empty(nmax, np.float32)
    s_hot = np.empty(nmax, np.float32)
    s_bed = np.empty(nmax, np.float32)
    s_arc = np.empty((nmax, 2), np.float64)
    s_ccw = np.zeros(nmax, np.bool_)
    s_off = np.empty((nmax, 4), np.float64)
    s_relxyz = np.empty(nmax, np.bool_)
    s_rele = np.empty(nmax, np.bool_)
    s_inch = np.empty(nmax, np.bool_)
    s_en = np.empty((nmax, 4), np.bool_)
    l_letter = np.zeros(n_lines, np.uint8)
    l_number = np.full(n_lines, np.nan, np.float32)
    l_flags = np.zeros(n_lines, np.uint8)      # bit 0: an unexpanded {placeholder} was dropped;
    # bit 1: a G0-G3 line carries an axis the model has not got (A B C U V W); bit 2: an M106 /
    # M107 set the part-cooling fan ``fan`` follows (FLAG_PART_FAN)
    # comment markers (grown by doubling): line, code bits, Z, feature-name byte span
    mk_cap = 1024
    mk_line = np.empty(mk_cap, np.int64)
    mk_code = np.empty(mk_cap, np.int8)
    mk_z = np.empty(mk_cap, np.float64)
    mk_span = np.empty((mk_cap, 2), np.int64)
    n_mk = 0
    no_markers = (np.empty(0, np.int64), np.empty(0, np.int8), np.empty(0, np.float64), np.empty((0, 2), np.int64))
    placeholder = np.zeros(1, np.bool_)
    touched = np.zeros(27, np.int64)

    # untrimmed: the caller slices the step arrays to [:n]
    arrs = (s_line, s_kind, s_pos, s_feed, s_len, s_dur, s_fan, s_hot, s_bed, s_arc, s_ccw,
            s_off, s_relxyz, s_rele, s_inch, s_en, l_letter, l_number, l_flags)
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
    axis_letter = np.array([LX, LY, LZ, LE])
    n = 0
    for ln in range(n_lines):
        a = line_start[ln]
        b = line_start[ln + 1]
        # strip the line ending
        while b > a and (buf[b - 1] == 10 or buf[b - 1] == 13):
            b -= 1
        c0 = a
        while c0 < b and (buf[c0] == 32 or buf[c0] == 9):
            c0 += 1
        if c0 < b and buf[c0] == 59:
            code, zc, na, nb = _comment_marker(buf, c0, b)
            if code != 0:
                if n_mk == mk_cap:
                    mk_cap *= 2
                    t1 = np.empty(mk_cap, np.int64)
                    t1[:n_mk] = mk_line[:n_mk]
                    mk_line = t1
                    t2 = np.empty(mk_cap, np.int8)
                    t2[:n_mk] = mk_code[:n_mk]
                    mk_code = t2
                    t3 = np.empty(mk_cap, np.float64)
                    t3[:n_mk] = mk_z[:n_mk]
                    mk_z = t3
                    t4 = np.empty((mk_cap, 2), np.int64)
                    t4[:n_mk] = mk_span[:n_mk]
                    mk_span = t4
                mk_line[n_mk] = ln
                mk_code[n_mk] = code
                mk_z[n_mk] = zc
                mk_span[n_mk, 0] = na
                mk_span[n_mk, 1] = nb
                n_mk += 1
            continue
        letter, number, fpos, lenient = _parse_words(buf, a, b, present, value, bad, placeholder, touched)
        if placeholder[0]:
            l_flags[ln] |= 1
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
            # Klipper extended commands: only SET_STEPPER_ENABLE matters to the model
            if _match_upper(buf, fpos, b, SET_STEPPER_ENABLE):
                i = fpos + SET_STEPPER_ENABLE.shape[0]
                axis = -1
                en_value = -1
                while i < b:
                    if _match_upper(buf, i, b, STEPPER_) and i + STEPPER_.shape[0] < b:
                        ch = _upper(buf[i + STEPPER_.shape[0]])
                        if ch == 88:
                            axis = 0
                        elif ch == 89:
                            axis = 1
                        elif ch == 90:
                            axis = 2
                        elif ch == 69:
                            axis = 3
                    if _match_upper(buf, i, b, ENABLE_) and i + ENABLE_.shape[0] < b:
                        en_value = buf[i + ENABLE_.shape[0]] - 48
                    i += 1
                if axis >= 0 and (en_value == 0 or en_value == 1):
                    en[axis] = en_value == 1
                    kind = K_MOTOR
            if kind < 0:
                continue
        elif letter == 71:  # G
            g = number
            if lenient:
                # the tokenizer stopped at a stray character: firmware would read on past it and
                # we would not; a G command we cannot read the way the firmware does is corrupt
                return ERR_BAD_CHAR, ln, -1, n, arrs, no_markers
            if g == 0.0 or g == 1.0 or g == 2.0 or g == 3.0:
                arc = g >= 2.0
                any_axis = False
                for q in range(4):
                    k = axis_letter[q]
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
                for k in FOREIGN_AXES:
                    if present[k]:
                        l_flags[ln] |= 2
                if not any_axis and not arc:
                    continue
                for q in range(4):
                    k = axis_letter[q]
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
                dx = tgt[0] - pos[0]
                dy = tgt[1] - pos[1]
                dz = tgt[2] - pos[2]
                de = tgt[3] - pos[3]
                if arc:
                    ccw = g == 3.0
                    for k in (LI, LJ, LR):
                        if bad[k]:
                            return ERR_BAD_NUMBER, ln, k, n, arrs, no_markers
                    if present[LI] or present[LJ]:
                        ii = value[LI] * scale if present[LI] and not np.isnan(value[LI]) else 0.0
                        jj = value[LJ] * scale if present[LJ] and not np.isnan(value[LJ]) else 0.0
                        cx = pos[0] + ii
                        cy = pos[1] + jj
                    elif present[LR] and not np.isnan(value[LR]):
                        r = value[LR] * scale
                        d = math.hypot(dx, dy)
                        if d == 0.0:
                            return ERR_ARC, ln, LR, n, arrs, no_markers
                        h2 = r * r - 0.25 * d * d
                        if h2 < -1e-6 * max(1.0, r * r):
                            return ERR_ARC, ln, LR, n, arrs, no_markers
                        h = math.sqrt(max(h2, 0.0))
                        # Marlin G2_G3.cpp: e = clockwise ^ (r < 0) ? -1 : 1
                        e = -1.0 if ((not ccw) != (r < 0)) else 1.0
                        sx = -dy / d
                        sy = dx / d
                        cx = 0.5 * (pos[0] + tgt[0]) + e * h * sx
                        cy = 0.5 * (pos[1] + tgt[1]) + e * h * sy
                    else:
                        return ERR_ARC, ln, LI, n, arrs, no_markers
                    rad = math.hypot(pos[0] - cx, pos[1] - cy)
                    a0 = math.atan2(pos[1] - cy, pos[0] - cx)
                    a1 = math.atan2(tgt[1] - cy, tgt[0] - cx)
                    sweep = (a1 - a0) if ccw else (a0 - a1)
                    # same end point = full circle (Marlin: angular_travel == 0 -> 2*pi)
                    if sweep <= 1e-9:
                        sweep += 2.0 * math.pi
                    length = math.hypot(rad * sweep, dz)
                    kind = K_ARC
                else:
                    length = math.sqrt(dx * dx + dy * dy + dz * dz)
                    moved_xy = dx != 0.0 or dy != 0.0
                    if de < 0.0:
                        kind = K_RETRACT
                    elif de > 0.0:
                        kind = K_EXTRUDE if (moved_xy or dz != 0.0) else K_UNRETRACT
                    else:
                        kind = K_TRAVEL if (moved_xy or dz == 0.0) else K_Z_ONLY
                if length == 0.0:
                    length = abs(de)
                dur = length / feed
            elif g == 4.0:
                if present[LP] and not np.isnan(value[LP]):
                    dur = max(value[LP], 0.0) / 1000.0
                elif present[LS] and not np.isnan(value[LS]):
                    dur = max(value[LS], 0.0)
                kind = K_DWELL
            elif g == 28.0:
                kind = K_HOME
                dur = home_s
                named = present[LX] or present[LY] or present[LZ]
                for q in range(4):
                    tgt[q] = pos[q]
                for q in range(3):
                    if (not named) or present[axis_letter[q]]:
                        tgt[q] = 0.0
                        off[q] = 0.0
                        en[q] = True
            elif g == 90.0:
                rel_xyz = False
                if not klipper:
                    rel_e = False
                continue
            elif g == 91.0:
                rel_xyz = True
                if not klipper:
                    rel_e = True
                continue
            elif g == 20.0:
                inch = True
                continue
            elif g == 21.0:
                inch = False
                continue
            elif g == 92.0:
                anyg = False
                for q in range(4):
                    k = axis_letter[q]
                    if bad[k]:
                        return ERR_BAD_NUMBER, ln, k, n, arrs, no_markers
                    if present[k]:
                        v = 0.0 if np.isnan(value[k]) else value[k] * scale
                        off[q] = pos[q] - v
                        anyg = True
                if not anyg:  # G92 alone: all axes to zero (Marlin)
                    for q in range(4):
                        off[q] = pos[q]
                continue
            else:
                continue
        elif letter == 77:  # M
            m = number
            if m == 82.0:
                rel_e = False
                continue
            elif m == 83.0:
                rel_e = True
                continue
            elif m == 104.0 or m == 109.0 or m == 140.0 or m == 190.0:
                bed_cmd = m == 140.0 or m == 190.0
                t = value[LS] if present[LS] else (value[LR] if present[LR] else np.nan)
                if not np.isnan(t):
                    if bed_cmd:
                        bed = t
                    else:
                        hot = t
                if m == 104.0 or m == 140.0:
                    continue
                # M109 / M190 wait: heat from the last temperature waited for (paper.toml [time])
                target = bed if bed_cmd else hot
                reached = bed_reached if bed_cmd else hot_reached
                if target > 0:
                    dur = abs(target - reached) / (bed_rate if bed_cmd else hot_rate)
                    if bed_cmd:
                        bed_reached = target
                    else:
                        hot_reached = target
                kind = K_WAIT
            elif m == 106.0:
                # only the part-cooling fan (no P, or P0) counts
                if present[LP] and not np.isnan(value[LP]) and value[LP] != 0.0:
                    continue
                s = value[LS] if present[LS] and not np.isnan(value[LS]) else 255.0
                fan = min(max(s / 255.0, 0.0), 1.0)
                l_flags[ln] |= FLAG_PART_FAN
                continue
            elif m == 107.0:
                if present[LP] and not np.isnan(value[LP]) and value[LP] != 0.0:
                    continue
                fan = 0.0
                l_flags[ln] |= FLAG_PART_FAN
                continue
            elif m == 17.0 or m == 18.0 or m == 84.0:
                named = False
                for q in range(4):
                    if present[axis_letter[q]]:
                        named = True
                if not named and (present[LS] or present[LT]):
                    continue  # M18 S<sec> / M84 S<sec>: idle timeout, not a disable
                for q in range(4):
                    if (not named) or present[axis_letter[q]]:
                        en[q] = m == 17.0
                kind = K_MOTOR
            else:
                continue
        elif letter == 83:  # S-series (3DGates Table 3): S1 X = on, S0 X = off
            if number == 0.0 or number == 1.0:
                named = False
                for q in range(4):
                    if present[axis_letter[q]]:
                        en[q] = number == 1.0
                        named = True
                if not named:
                    continue
                kind = K_MOTOR
            else:
                continue
        else:
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
    markers = (mk_line[:n_mk].copy(), mk_code[:n_mk].copy(), mk_z[:n_mk].copy(), mk_span[:n_mk].copy())
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
    return OK, -1, -1, n, arrs, markers
