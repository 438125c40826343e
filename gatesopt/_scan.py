"""The compiled core of the parser: one sequential pass over the bytes of a G-code file.

A per-line Python loop parses ~300 k lines/s; this numba kernel tokenizes every line and resolves
the modal state (G90/G91, M82/M83, G92, G20/G21, F, fan, temperatures, motor enables) in the
same pass, writing one row per timed step into preallocated arrays. It knows nothing about
files, layers or errors as text: it returns an error code and the line, and ``parse.py`` turns
that into a message.

Modal semantics follow Marlin 2.x (gcode.h ``set_relative_mode`` clears the E mode bits, so
G90/G91 switch E too), or Klipper's gcode_move.py when ``klipper`` is set (G90/G91 leave the
M82/M83 E mode alone).

What the slicers and firmware write (layer markers, Z and feature comments, extended motor
commands) is not in here: it comes as packed tables (``pack_comment_markers``,
``pack_motor_commands``) from the modules that own it. The kernel and its helpers stay in this
one file, past the house's ~600 lines: numba's on-disk cache of ``scan`` is keyed on this file's
source alone and is not invalidated when a jitted helper in another file changes (numba's "Notes
on Caching": cache invalidation does not see changes in other files).
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
ERR_EXPONENT = 7        # a number written with an exponent on a move or G92 line (FLAG_EXPONENT)
ERR_LETTER_RUN = 8      # a move or G92 line with a letter straight after a letter (``X0xa``)
ERR_HEX = 9             # a move or G92 line with a hexadecimal-looking number (FLAG_HEX)

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
AXIS_LETTERS = (LX, LY, LZ, LE)     # the model's axes X Y Z E, in the order of ``program.AXES``

EXT = 64        # '@': line starts with an extended (Klipper-style) command word
POW10 = 10.0 ** np.arange(40)


# ------------------------------------------------------------------------------------------------
# the knowledge tables the kernel reads, packed into arrays
#
# The tables themselves are plain Python in the modules that own the knowledge
# (``slicers.LAYER_MARKERS`` / ``Z_MARKERS`` / ``FEATURE_MARKERS``, ``firmware.EXTENDED_MOTOR_COMMANDS``);
# ``parse`` packs them once and passes them to ``scan`` as arguments. Arguments, not globals: numba
# freezes a global array into the compiled kernel and its on-disk cache is keyed on this file
# only, so a row added to ``slicers.py`` would not reach a cached kernel.

#: columns of a packed comment-marker row (``pack_comment_markers``); text spans index ``text``
(M_ROLE, M_KIND, M_AT_SEMICOLON, M_FOLD, M_FOLLOW, M_TEXT_A, M_TEXT_B, M_SEP_A, M_SEP_B,
 M_ZAFTER_A, M_ZAFTER_B) = range(11)
ROLE_LAYER, ROLE_Z, ROLE_FEATURE = 0, 1, 2
FOLLOW_CODES = {"": 0, "digit": 1, "signed": 2}


def _append_text(blob: bytearray, text: bytes) -> tuple[int, int]:
    """Append ``text`` to ``blob``; its (start, end) in it."""
    a = len(blob)
    blob += text
    return a, len(blob)


def pack_comment_markers(layer_markers, layer_kinds, z_markers, feature_markers):
    """(rows int64 [n, 11], text uint8) for ``scan``: the layer markers written on comment lines
    (``slicers.LayerMarker``s, each with its 1-based kind: its slicer's place in ``layer_kinds``),
    then the Z markers, then the feature markers (``slicers``). The scanner takes the first
    matching row of each role on a line."""
    blob = bytearray()
    rows = []
    for m in layer_markers:
        text = m.text.upper() if m.fold_case else m.text
        at_semicolon = text.startswith(b";")
        ta, tb = _append_text(blob, text)
        sa, sb = _append_text(blob, m.sep)
        za, zb = _append_text(blob, m.z_after)
        rows.append((ROLE_LAYER, layer_kinds.index(m.slicer) + 1, at_semicolon, m.fold_case,
                     FOLLOW_CODES[m.follow], ta, tb, sa, sb, za, zb))
    for role, texts in ((ROLE_Z, z_markers), (ROLE_FEATURE, feature_markers)):
        for t in texts:
            ta, tb = _append_text(blob, t)
            rows.append((role, 0, False, False, 0, ta, tb, tb, tb, tb, tb))
    return np.array(rows, np.int64).reshape(-1, 11), np.frombuffer(bytes(blob) or b"\0", np.uint8).copy()


#: columns of a packed extended motor command (``pack_motor_commands``) and of one of its names
(C_WORD_A, C_WORD_B, C_MOTOR_A, C_MOTOR_B, C_ENABLE_A, C_ENABLE_B, C_DEFAULT, C_LISTS) = range(8)
N_COMMAND, N_NAME_A, N_NAME_B, N_AXIS = range(4)


def pack_motor_commands(commands, axes):
    """(commands int64 [n, 8], names int64 [m, 4], text uint8) for ``scan``: each
    ``firmware.ExtendedMotorCommand``'s word and parameter names in upper case, its default enable
    and list flag, each motor name (upper case) with its command's index and its motor's index in
    ``axes``."""
    blob = bytearray()
    cmds, names = [], []
    for c, cmd in enumerate(commands):
        cmds.append(_append_text(blob, cmd.word.upper().encode())
                    + _append_text(blob, cmd.motor_param.upper().encode())
                    + _append_text(blob, cmd.enable_param.upper().encode())
                    + (int(cmd.default_enable), int(bool(cmd.lists))))
        for name, motor in cmd.motors:
            names.append((c,) + _append_text(blob, name.upper().encode()) + (axes.index(motor),))
    return (np.array(cmds, np.int64).reshape(-1, 8), np.array(names, np.int64).reshape(-1, 4),
            np.frombuffer(bytes(blob) or b"\0", np.uint8).copy())


@njit(cache=True)
def _match(buf, i, end, text, a, b, fold):
    """buf[i:end] starts with text[a:b] (``fold``: buf upper-cased first; text is upper case)."""
    n = b - a
    if i + n > end:
        return False
    for k in range(n):
        c = buf[i + k]
        if fold:
            c = _upper(c)
        if c != text[a + k]:
            return False
    return True


@njit(cache=True)
def _find(buf, i, end, text, a, b):
    """First position >= i of text[a:b] in buf[:end], or -1."""
    for j in range(i, end - (b - a) + 1):
        if _match(buf, j, end, text, a, b, False):
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
def _follows(buf, k, b, text, sa, sb, follow):
    """What a layer marker needs after its text at k: one byte of text[sa:sb] (then spaces), then
    ``follow`` (0 nothing, 1 a digit, 2 a digit or '-')."""
    if sb > sa:
        if k >= b:
            return False
        hit = False
        for t in range(sa, sb):
            if buf[k] == text[t]:
                hit = True
        if not hit:
            return False
        k += 1
        while k < b and buf[k] == 32:
            k += 1
    if follow == 0:
        return True
    if k >= b:
        return False
    return (48 <= buf[k] <= 57) or (follow == 2 and buf[k] == 45)


@njit(cache=True)
def _comment_marker(buf, i, b, rows, text):
    """Markers on a comment line starting at i (buf[i] == ';'), from the packed table ``rows`` /
    ``text`` (``pack_comment_markers``). Returns (layer kind or 0, z, name_a, name_b): the first
    matching row of each role counts; the name span is the feature name, blanks trimmed."""
    kind = 0
    z = np.nan
    na = -1
    nb = -1
    j = i + 1
    while j < b and (buf[j] == 32 or buf[j] == 9):
        j += 1
    layer_done = False
    z_done = False
    for r in range(rows.shape[0]):
        role = rows[r, M_ROLE]
        ta = rows[r, M_TEXT_A]
        tb = rows[r, M_TEXT_B]
        if role == ROLE_LAYER:
            at = i if rows[r, M_AT_SEMICOLON] else j
            if layer_done or not _match(buf, at, b, text, ta, tb, rows[r, M_FOLD] != 0):
                continue
            if not _follows(buf, at + tb - ta, b, text, rows[r, M_SEP_A], rows[r, M_SEP_B], rows[r, M_FOLLOW]):
                continue
            kind = rows[r, M_KIND]
            layer_done = True
            za = rows[r, M_ZAFTER_A]
            zb = rows[r, M_ZAFTER_B]
            if zb > za:
                f = _find(buf, at + tb - ta, b, text, za, zb)
                if f >= 0:
                    z = _number_at(buf, f + zb - za, b)
        elif role == ROLE_Z:
            if not z_done and _match(buf, j, b, text, ta, tb, False):
                z = _number_at(buf, j + tb - ta, b)
                z_done = True
        elif na < 0 and _match(buf, j, b, text, ta, tb, False):
            na = j + tb - ta
    if na >= 0:
        while na < b and (buf[na] == 32 or buf[na] == 9):
            na += 1
        nb = b
        while nb > na and (buf[nb - 1] == 32 or buf[nb - 1] == 9):
            nb -= 1
    return kind, z, na, nb


@njit(cache=True)
def _text_command(m):
    """An M command whose parameter is text (M23/M28/M30/M32/M33 file names, M117/M118 messages,
    M928 log name: Marlin's parser.cpp takes the rest of the line as a string)."""
    return m == 23.0 or m == 28.0 or m == 30.0 or m == 32.0 or m == 33.0 or m == 117.0 or m == 118.0 or m == 928.0


@njit(cache=True)
def _is_letter(c):
    return (65 <= c <= 90) or (97 <= c <= 122)


@njit(cache=True)
def _upper(c):
    return c - 32 if 97 <= c <= 122 else c


@njit(cache=True)
def _parse_words(buf, a, b, present, value, bad, info, touched):
    """Tokenize buf[a:b] (one line, no line ending). Fills present/value/bad per letter.

    Returns (cmd_letter, cmd_number, first_word_pos, lenient_stop) where cmd_letter is the
    upper-case ASCII code of the first word's letter (0 if none, EXT for an extended command).
    ``bad[k]`` marks a letter whose number failed to parse. ``info`` (int64 [4]) gets: [0] an
    unexpanded {placeholder} was dropped; [1] parameter words written straight after a number,
    no blank between (``G1X10Y5`` has two); [2] how many of them are E words shaped like a
    number's exponent (``X1e400``: e, a sign or not, digits, no '.'): when all of them are, the
    line's words are otherwise apart, and these are exponents; [3] a letter given twice; [4] a
    parameter letter straight after a letter (``X0xa``): Klipper reads the run as one parameter
    name ("XA"), Marlin each letter as a word without a value; [5] a number written like a
    hexadecimal one (``Y0x10``: an X word straight after a lone 0).
    """
    info[0] = 0
    info[1] = 0
    info[2] = 0
    info[3] = 0
    info[4] = 0
    info[5] = 0
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
    cmd_end = a                 # where the command word's number ends
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
        if not first and i > a and (48 <= buf[i - 1] <= 57 or buf[i - 1] == 46):
            nglued_cmd = i - 1 < cmd_end       # straight after the command's number: compact
            # written straight after a number: compact G-code (G1X10Y5E.2), or an exponent that
            # firmware reads as an E word (Marlin parser.h value_float stops at 'E'/'e', Klipper
            # gcode.py splits the upper-cased line at letters: X1e400 is X1 E400 to both)
            info[1] += 1
            if L == 88 and buf[i - 1] == 48 and i - 2 >= a and (
                    _is_letter(buf[i - 2]) or buf[i - 2] == 43 or buf[i - 2] == 45):
                info[5] = 1
            if L == 69 and not nglued_cmd:
                j = i + 1
                if j < b and (buf[j] == 43 or buf[j] == 45):
                    j += 1
                if j < b and 48 <= buf[j] <= 57:
                    while j < b and 48 <= buf[j] <= 57:
                        j += 1
                    if j >= b or buf[j] != 46:
                        info[2] += 1
        i += 1
        v, nd, j = _scan_number(buf, i, b)
        k = L - _A
        if not first and present[k]:
            info[3] = 1         # firmware takes the last (Marlin's FASTER_GCODE_PARSER, Klipper)
        if touched[0] < 26 and not present[k]:
            touched[0] += 1
            touched[touched[0]] = k
        if nd == 0 and j == i and j < b and buf[j] == 123 and not first:
            # '{placeholder}' a slicer left unexpanded: Marlin's seenval() ignores a word without
            # a valid value, so the word is dropped (parse.py warns)
            while j < b and buf[j] != 125:
                j += 1
            i = j + 1
            info[0] = 1
            continue
        if nd == 0 and j > i:   # a sign or dot without digits
            bad[k] = True
        if nd == 0 and j == i and j < b and _is_letter(buf[j]) and not first:
            info[4] = 1
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
            cmd_end = j
        else:
            present[k] = True
            value[k] = v
        i = j
    return cmd_letter, cmd_number, first_pos, False


#: ``l_flags`` bit of a line that set the part-cooling fan (``Program.part_fan_lines``)
FLAG_PART_FAN = 4
#: ``l_flags`` bit of a line with a number written with an exponent (``X1e400``), which firmware
#: reads as an E word: on a line whose words are otherwise apart, E words straight after a
#: number, shaped like an exponent (``_parse_words`` ``info[2]``); refused on moves and G92
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
def _token_end(buf, i, b):
    """End of the blank-separated word at i (a blank, ';' or '#' ends it)."""
    while i < b and buf[i] != 32 and buf[i] != 9 and buf[i] != 59 and buf[i] != 35:
        i += 1
    return i


@njit(cache=True)
def _is_text(buf, i, j, text, a, b):
    """buf[i:j], upper-cased, is text[a:b] (upper case)."""
    return j - i == b - a and _match(buf, i, j, text, a, b, True)


@njit(cache=True)
def _int_value(buf, i, j):
    """The integer buf[i:j] (an optional sign, digits) as 0 / 1 (0 off, anything else on), or -1
    when it is no integer (Klipper's ``get_int`` fails: the line is an error)."""
    if i < j and (buf[i] == 43 or buf[i] == 45):
        i += 1
    if i >= j:
        return -1
    nonzero = False
    for k in range(i, j):
        if not (48 <= buf[k] <= 57):
            return -1
        if buf[k] != 48:
            nonzero = True
    return 1 if nonzero else 0


@njit(cache=True)
def _extended_motor(buf, fpos, b, en, commands, names, text):
    """An extended command line at fpos read through the packed table (``pack_motor_commands``,
    the rules of ``firmware.ExtendedMotorCommand``): if it switches a known motor, set ``en`` and
    return K_MOTOR; else -1 (the line is no step)."""
    we = _token_end(buf, fpos, b)
    for c in range(commands.shape[0]):
        if not _is_text(buf, fpos, we, text, commands[c, C_WORD_A], commands[c, C_WORD_B]):
            continue
        mask = 0
        en_value = commands[c, C_DEFAULT]
        lists = commands[c, C_LISTS] != 0
        i = we
        while True:
            while i < b and (buf[i] == 32 or buf[i] == 9):
                i += 1
            if i >= b or buf[i] == 59 or buf[i] == 35:
                break
            te = _token_end(buf, i, b)
            eq = -1
            for k in range(i, te):
                if buf[k] == 61:
                    eq = k
                    break
            if eq < 0:
                return -1           # a word without '=': Klipper's "Malformed command"
            if _is_text(buf, i, eq, text, commands[c, C_MOTOR_A], commands[c, C_MOTOR_B]):
                mask = 0            # the last of a parameter counts
                s = eq + 1
                while s <= te:
                    e = te
                    if lists:
                        e = s
                        while e < te and buf[e] != 44:
                            e += 1
                    for r in range(names.shape[0]):
                        if names[r, N_COMMAND] == c and _is_text(buf, s, e, text, names[r, N_NAME_A],
                                                                 names[r, N_NAME_B]):
                            mask |= 1 << names[r, N_AXIS]
                    s = e + 1
            elif (commands[c, C_ENABLE_B] > commands[c, C_ENABLE_A]
                  and _is_text(buf, i, eq, text, commands[c, C_ENABLE_A], commands[c, C_ENABLE_B])):
                en_value = _int_value(buf, eq + 1, te)
                if en_value < 0:
                    return -1
            i = te
        if mask == 0 or en_value < 0:
            return -1
        for q in range(4):
            if mask >> q & 1:
                en[q] = en_value == 1
        return K_MOTOR
    return -1


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
    every step row; what the other commands do is in the helpers above. Measured (CPU time of the
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
            kind, zc, na, nb = _comment_marker(buf, c0, b, mk_rows, mk_text)
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
        letter, number, fpos, lenient = _parse_words(buf, a, b, present, value, bad, info, touched)
        if info[0] != 0:
            l_flags[ln] |= 1
        if (info[2] != 0 or info[3] != 0 or info[5] != 0) and (
                letter == 71 or (letter == 77 and not _text_command(number))):
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
            kind = _extended_motor(buf, fpos, b, en, motor_cmds, motor_names, motor_text)
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
