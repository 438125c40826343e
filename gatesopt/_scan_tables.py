"""The knowledge tables the scanner reads, packed into arrays, and the kernels that read them: the
layer, Z and feature markers slicers write on comment lines (``slicers``), and the extended
commands that switch motors (``firmware.EXTENDED_MOTOR_COMMANDS``, e.g. Klipper's
``SET_STEPPER_ENABLE``).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._scan_words import match_text, number_at

# The tables themselves are plain Python in the modules that own the knowledge
# (``slicers.LAYER_MARKERS`` / ``Z_MARKERS`` / ``FEATURE_MARKERS``, ``firmware.EXTENDED_MOTOR_COMMANDS``);
# ``parse`` packs them once and passes them to ``scan`` as arguments. Arguments, not globals: numba
# freezes a global array into the compiled kernel as a constant, so the kernel would depend on the
# tables' values, not only on the sources its cache directory is keyed on
# (``_jit.use_versioned_cache``), and this module would have to import the modules that own them.

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
def _find(buf, i, end, text, a, b):
    """First position >= i of text[a:b] in buf[:end], or -1."""
    for j in range(i, end - (b - a) + 1):
        if match_text(buf, j, end, text, a, b, False):
            return j
    return -1


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
def comment_marker(buf, i, b, rows, text):
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
            if layer_done or not match_text(buf, at, b, text, ta, tb, rows[r, M_FOLD] != 0):
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
                    z = number_at(buf, f + zb - za, b)
        elif role == ROLE_Z:
            if not z_done and match_text(buf, j, b, text, ta, tb, False):
                z = number_at(buf, j + tb - ta, b)
                z_done = True
        elif na < 0 and match_text(buf, j, b, text, ta, tb, False):
            na = j + tb - ta
    if na >= 0:
        while na < b and (buf[na] == 32 or buf[na] == 9):
            na += 1
        nb = b
        while nb > na and (buf[nb - 1] == 32 or buf[nb - 1] == 9):
            nb -= 1
    return kind, z, na, nb


@njit(cache=True)
def _token_end(buf, i, b):
    """End of the blank-separated word at i (a blank, ';' or '#' ends it)."""
    while i < b and buf[i] != 32 and buf[i] != 9 and buf[i] != 59 and buf[i] != 35:
        i += 1
    return i


@njit(cache=True)
def _is_text(buf, i, j, text, a, b):
    """buf[i:j], upper-cased, is text[a:b] (upper case)."""
    return j - i == b - a and match_text(buf, i, j, text, a, b, True)


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
def extended_motor(buf, fpos, b, en, commands, names, text):
    """An extended command line at fpos read through the packed table (``pack_motor_commands``,
    the rules of ``firmware.ExtendedMotorCommand``): if it switches a known motor, set ``en`` and
    return True; else False (the line is no step)."""
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
                return False           # a word without '=': Klipper's "Malformed command"
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
                    return False
            i = te
        if mask == 0 or en_value < 0:
            return False
        for q in range(4):
            if mask >> q & 1:
                en[q] = en_value == 1
        return True
    return False
