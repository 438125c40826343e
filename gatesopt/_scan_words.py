"""The scanner's tokenizer: the words and numbers of one G-code line, for the numba kernel
``_scan.scan`` (and the text matching its table readers share, ``_scan_tables``).

``parse_words`` reads a line as firmware does: Marlin's parser.cpp (a word is a letter and the
number after it; the first word is the command; ``;`` and ``(..)`` are comments, ``*`` starts the
checksum) and Klipper's gcode.py (which upper-cases the line and splits it at letters); where the
two read a line differently (an exponent, a letter given twice, ``0x``), it says so in ``info``
and ``scan`` flags the line (``parse.py`` explains or refuses it). ``scan_number`` reads the
number of a word.

Numba's on-disk cache keys a kernel on its own file only; the cache directory carries a digest of
every source of the package (``_jit.use_versioned_cache``), so a change here recompiles ``scan``.
"""
from __future__ import annotations

import numpy as np
from numba import njit

# letters we care about, index = ord(c) - 65 (``parse_words`` fills per-letter arrays of 26)
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


@njit(cache=True)
def match_text(buf, i, end, text, a, b, fold):
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


@njit(cache=True, inline="always")     # on the hot path: inlined, as the code it replaced was
def scan_number(buf, j, end):
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
def number_at(buf, i, end):
    """A decimal number starting at i (blanks skipped), NaN if none."""
    while i < end and (buf[i] == 32 or buf[i] == 9):
        i += 1
    return scan_number(buf, i, end)[0]


@njit(cache=True)
def text_command(m):
    """An M command whose parameter is text (M23/M28/M30/M32/M33 file names, M117/M118 messages,
    M928 log name: Marlin's parser.cpp takes the rest of the line as a string)."""
    return m == 23.0 or m == 28.0 or m == 30.0 or m == 32.0 or m == 33.0 or m == 117.0 or m == 118.0 or m == 928.0


@njit(cache=True)
def _is_letter(c):
    return (65 <= c <= 90) or (97 <= c <= 122)


@njit(cache=True)
def _upper(c):
    return c - 32 if 97 <= c <= 122 else c


# parse_words' two helpers are inlined (numba IR): called, not inlined, they cost scan 10-12 % more
# CPU time (best of 10 on the four files of bench/scan_timing.py, in one run with the tree before
# the split: 48.2 / 39.6 / 29.0 / 20.1 ms against 43.7 / 36.1 / 26.2 / 18.0); inlined, 0.97-1.02x
@njit(cache=True, inline="always")
def _reset(present, value, bad, info, touched):
    """Clear ``info`` and the letters the previous line set (``touched[0]`` counts them,
    ``touched[1:]`` lists them): resetting all 3 x 26 slots on every line cost more than the rest
    of the tokenizer."""
    for q in range(info.shape[0]):
        info[q] = 0
    for t in range(1, touched[0] + 1):
        k = touched[t]
        present[k] = False
        value[k] = np.nan
        bad[k] = False
    touched[0] = 0


@njit(cache=True, inline="always")
def _glued_word(buf, a, i, b, L, after_command, info):
    """Count in ``info`` (``parse_words``) the word of letter ``L`` at i, written straight after a
    number (``after_command``: the command's own): compact G-code (G1X10Y5E.2), or an exponent
    that firmware reads as an E word (Marlin parser.h value_float stops at 'E'/'e', Klipper
    gcode.py splits the upper-cased line at letters: X1e400 is X1 E400 to both), or an X after a
    lone 0 (``0x10``)."""
    info[1] += 1
    if L == 88 and buf[i - 1] == 48 and i - 2 >= a and (
            _is_letter(buf[i - 2]) or buf[i - 2] == 43 or buf[i - 2] == 45):
        info[5] = 1
    if L == 69 and not after_command:
        j = i + 1
        if j < b and (buf[j] == 43 or buf[j] == 45):
            j += 1
        if j < b and 48 <= buf[j] <= 57:
            while j < b and 48 <= buf[j] <= 57:
                j += 1
            if j >= b or buf[j] != 46:
                info[2] += 1


@njit(cache=True)
def parse_words(buf, a, b, present, value, bad, info, touched):
    """Tokenize buf[a:b] (one line, no line ending). Fills present/value/bad per letter.

    Returns (cmd_letter, cmd_number, first_word_pos, lenient_stop) where cmd_letter is the
    upper-case ASCII code of the first word's letter (0 if none, EXT for an extended command).
    ``bad[k]`` marks a letter whose number failed to parse. ``info`` (int64 [6]) gets: [0] an
    unexpanded {placeholder} was dropped; [1] parameter words written straight after a number,
    no blank between (``G1X10Y5`` has two); [2] how many of them are E words shaped like a
    number's exponent (``X1e400``: e, a sign or not, digits, no '.'): when all of them are, the
    line's words are otherwise apart, and these are exponents; [3] a letter given twice; [4] a
    parameter letter straight after a letter (``X0xa``): Klipper reads the run as one parameter
    name ("XA"), Marlin each letter as a word without a value; [5] a number written like a
    hexadecimal one (``Y0x10``: an X word straight after a lone 0).
    """
    _reset(present, value, bad, info, touched)
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
            _glued_word(buf, a, i, b, L, i - 1 < cmd_end, info)
        at = i
        i += 1
        if first:
            # a command's number after blanks ("G 28 W", a Prusa start G-code): Marlin reads on
            # past them (GCodeParser::parse, "Skip spaces to get the numeric part"), as does
            # Klipper (gcode.py joins the command letter and its stripped number)
            j = i
            while j < b and (buf[j] == 32 or buf[j] == 9):
                j += 1
            if j > i and j < b and 48 <= buf[j] <= 57:
                i = j
        v, nd, j = scan_number(buf, i, b)
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
            first_pos = at
            first = False
            cmd_end = j
        else:
            present[k] = True
            value[k] = v
        i = j
    return cmd_letter, cmd_number, first_pos, False
