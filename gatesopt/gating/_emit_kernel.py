"""The compiled core of gating emission without rotation: one pass over the lines of a file.

``emit_plain.render_plain`` decides *what* goes where (instruction lines before a line, moves split at a
fraction of their time) with numpy; this kernel writes the bytes. Lines that are not rewritten are
copied as they are; instruction lines are copied from a small table of texts; a split move is
written here when its line is in the plain form slicers write (``G1 X.. Y.. E.. F..``: upper-case
letters, one space between words, ASCII) and every number it needs can be rounded here exactly as
Python's ``format`` rounds. Any other split move (arcs, unusual spelling, a number within a few
ulps of a rounding tie) is left to ``emit_line.LineRewriter.rewrite``, the reference implementation: the
kernel records where its text goes and the caller splices it in. The two must write the same bytes
(tests/test_gating_emit.py compares them line by line).

Number texts follow ``emit_line.fmt_number`` and ``emit_line._dec_text``: rounded to a fixed number of decimals,
trailing zeros and a trailing '.' dropped, "-0" written "0". Relative values (G91, M83) are summed
as integers in units of the last decimal, which is what the reference's ``Decimal`` arithmetic is.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

POW10 = 10.0 ** np.arange(19)
IPOW10 = 10 ** np.arange(19, dtype=np.int64)
_TIE_REL = 4.5e-16      # 4 x the relative error of one rounded product: x * 10**d is within it
_MAX_SCALED = 1.0e15    # |x| * 10**d below 2**50: its integer and fractional parts are exact
_MERGE_FRACTION = 1e-12  # cuts this close to a group's first cut share one split (as emit.render)

# decimals of split points per axis X Y Z E (emit_line.DECIMALS_SPLIT_MM; inches: two more)
DECIMALS_SPLIT = np.array([5, 5, 5, 6], np.int64)

_SP, _DOT, _MINUS, _PLUS, _SEMI = 32, 46, 45, 43, 59
_AXIS_OF_LETTER = np.full(26, -1, np.int64)
_AXIS_OF_LETTER[ord("X") - 65] = 0
_AXIS_OF_LETTER[ord("Y") - 65] = 1
_AXIS_OF_LETTER[ord("Z") - 65] = 2
_AXIS_OF_LETTER[ord("E") - 65] = 3
_LETTER_OF_AXIS = np.array([ord("X"), ord("Y"), ord("Z"), ord("E")], np.uint8)


@njit(cache=True)
def _round_scaled(x, d):
    """(round(x * 10**d), ok): rounded as ``f"{x:.{d}f}"`` rounds x's exact binary value. ``ok`` is
    False out of range (NaN included) or within a few ulps of a tie, where the product computed in
    floating point cannot tell which way the exact value rounds."""
    y = abs(x) * POW10[d]
    if not (y < _MAX_SCALED):
        return 0, False
    n0 = math.floor(y)
    frac = y - n0
    if abs(frac - 0.5) <= _TIE_REL * y:
        return 0, False
    n = np.int64(n0) + (1 if frac > 0.5 else 0)
    return (-n if x < 0 else n), True


@njit(cache=True)
def _put_scaled(out, p, v, d):
    """Write the integer v in units of 10**-d as the shortest decimal text (no trailing zeros, no
    '-0'); return the position after it."""
    if v == 0:
        out[p] = 48
        return p + 1
    if v < 0:
        out[p] = _MINUS
        p += 1
        v = -v
    ip = v // IPOW10[d]
    fp = v % IPOW10[d]
    nd = 1
    while nd < 19 and ip >= IPOW10[nd]:
        nd += 1
    for k in range(nd - 1, -1, -1):
        out[p + k] = 48 + ip % 10
        ip //= 10
    p += nd
    if fp != 0:
        while fp % 10 == 0:
            fp //= 10
            d -= 1
        out[p] = _DOT
        p += 1
        for k in range(d - 1, -1, -1):
            out[p + k] = 48 + fp % 10
            fp //= 10
        p += d
    return p


@njit(cache=True)
def _value_end(buf, j, end):
    """End of a number ``[-+]?(digits[.digits] | .digits)`` starting at j (the reference's word
    regex), or -1 if there is none."""
    if j < end and (buf[j] == _MINUS or buf[j] == _PLUS):
        j += 1
    nd = 0
    while j < end and 48 <= buf[j] <= 57:
        j += 1
        nd += 1
    if j < end and buf[j] == _DOT:
        j += 1
        while j < end and 48 <= buf[j] <= 57:
            j += 1
            nd += 1
    return j if nd > 0 else -1


@njit(cache=True)
def _scan_decimal(buf, a, b):
    """The number text buf[a:b] as (mantissa, decimals), exact; (0, -1) beyond 17 digits or
    beyond the 18 decimals ``IPOW10`` holds (``E0.00000000000000000001``: one digit, 20 decimals;
    read past the table, the power was garbage and the division by it a SIGFPE)."""
    neg = buf[a] == _MINUS
    if buf[a] == _MINUS or buf[a] == _PLUS:
        a += 1
    mant = np.int64(0)
    nd = 0
    dec = 0
    seen_dot = False
    for j in range(a, b):
        c = buf[j]
        if c == _DOT:
            seen_dot = True
            continue
        if nd == 0 and c == 48:
            if seen_dot:
                dec += 1
            continue        # leading zeros carry no digit
        mant = mant * 10 + (c - 48)
        nd += 1
        if seen_dot:
            dec += 1
        if nd > 17:
            return np.int64(0), -1
    if dec > len(IPOW10) - 1:
        return np.int64(0), -1
    return (-mant if neg else mant), dec


@njit(cache=True)
def _n_digits(v):
    v = abs(v)
    nd = 1
    while nd < 19 and v >= IPOW10[nd]:
        nd += 1
    return nd


@njit(cache=True)
def _put_bytes(out, p, src, a, b):
    for k in range(b - a):
        out[p + k] = src[a + k]
    return p + (b - a)


@njit(cache=True)
def _put_code(out, p, code, code_ptr, txt_id, txt_buf, txt_ptr, nl):
    """The instruction lines of ``code``, each with the file's line ending."""
    for t in range(code_ptr[code], code_ptr[code + 1]):
        k = txt_id[t]
        p = _put_bytes(out, p, txt_buf, txt_ptr[k], txt_ptr[k + 1])
        p = _put_bytes(out, p, nl, 0, nl.shape[0])
    return p


@njit(cache=True)
def _plain_words(buf, a, b, tok_a, tok_b, tok_axis):
    """Line buf[a:b] read in the plain form the kernels rewrite themselves: ``G<digits>[.<digits>]``
    then `` <LETTER><number>`` words, each letter once, then a comment if any. Returns (body,
    code, g_end, n_tok, axis_tok): where the line ends without its line ending, where its G-code
    ends (up to the first ';', right-stripped), where its G word ends; the words' spans in
    ``tok_a`` / ``tok_b`` [:n_tok] and their axes in ``tok_axis`` (-1: not X Y Z E); each axis's
    word (``axis_tok``, -1: none). ``n_tok`` is -1 when the line is not in the plain form."""
    axis_tok = np.full(4, -1, np.int64)
    body = b
    while body > a and (buf[body - 1] == 10 or buf[body - 1] == 13):
        body -= 1
    code = a
    while code < body and buf[code] != _SEMI:
        code += 1
    while code > a and (buf[code - 1] == _SP or buf[code - 1] == 9):
        code -= 1
    if code - a < 2 or buf[a] != 71:
        return body, code, a, -1, axis_tok
    j = _value_end(buf, a + 1, code)
    if j < 0 or buf[a + 1] == _MINUS or buf[a + 1] == _PLUS or buf[a + 1] == _DOT or buf[j - 1] == _DOT:
        return body, code, a, -1, axis_tok
    g_end = j
    n_tok = 0
    seen = 0
    while j < code:
        if buf[j] != _SP or j + 1 >= code or n_tok >= tok_a.shape[0]:
            return body, code, g_end, -1, axis_tok
        L = buf[j + 1]
        if not (65 <= L <= 90) or (seen >> (L - 65)) & 1:
            return body, code, g_end, -1, axis_tok
        seen |= 1 << (L - 65)
        v = _value_end(buf, j + 2, code)
        if v < 0 or (v < code and buf[v] != _SP):
            return body, code, g_end, -1, axis_tok
        tok_a[n_tok] = j + 1
        tok_b[n_tok] = v
        ax = _AXIS_OF_LETTER[L - 65]
        tok_axis[n_tok] = ax
        if ax >= 0:
            axis_tok[ax] = n_tok
        n_tok += 1
        j = v
    return body, code, g_end, n_tok, axis_tok


@njit(cache=True)
def _split_row(out, p, buf, a, b, r, e0, e1, cut_frac, cut_code, code_ptr, txt_id, txt_buf, txt_ptr, nl,
               start_mm, end_mm, offset_mm, rel_xyz, rel_e, inch, tok_a, tok_b, tok_axis):
    """Write line buf[a:b] (step r) split at the cuts e0..e1 (sorted by fraction) with their lines
    between the pieces, as ``emit_line.LineRewriter.rewrite`` does without rotation. Returns
    (position after it, lines added), or (-1, 0) when the line is left to the reference
    implementation."""
    body, code, g_end, n_tok, axis_tok = _plain_words(buf, a, b, tok_a, tok_b, tok_axis)
    if n_tok < 0:
        return -1, 0
    scale = 25.4 if inch[r] else 1.0
    extra = 2 if inch[r] else 0
    sums = np.zeros(4, np.int64)
    vals = np.zeros(4, np.int64)        # this piece's numbers, in units of 10**-digits
    digits = np.zeros(4, np.int64)
    added = 0
    e = e0
    k = 0
    while True:
        last = e >= e1
        f = 1.0 if last else cut_frac[e]
        g_last = e
        if not last:
            while g_last + 1 < e1 and cut_frac[g_last + 1] - f <= _MERGE_FRACTION:
                g_last += 1
        # the numbers of this piece
        for ax in range(4):
            t = axis_tok[ax]
            if t < 0:
                continue
            rel = rel_e[r] if ax == 3 else rel_xyz[r]
            d = DECIMALS_SPLIT[ax] + extra
            if last and not rel:
                continue                          # the original text
            if last:
                # the original text minus the pieces written, exactly (Decimal in the reference)
                mant, dec = _scan_decimal(buf, tok_a[t] + 1, tok_b[t])
                if dec < 0:
                    return -1, 0
                D = max(dec, d)
                if _n_digits(mant) + D - dec > 17 or _n_digits(sums[ax]) + D - d > 17:
                    return -1, 0
                vals[ax] = mant * IPOW10[D - dec] - sums[ax] * IPOW10[D - d]
                digits[ax] = D
                continue
            a0 = start_mm[r, ax]
            q = a0 + f * (end_mm[r, ax] - a0)
            if rel:
                x = (q - a0) / scale - sums[ax] / POW10[d]
            else:
                x = (q - offset_mm[r, ax]) / scale
            n, ok = _round_scaled(x, d)
            if not ok:
                return -1, 0
            vals[ax] = n
            digits[ax] = d
            if rel:
                sums[ax] += n
        # the text of this piece
        p = _put_bytes(out, p, buf, a, g_end)
        if k == 0:
            for t in range(n_tok):
                out[p] = _SP
                out[p + 1] = buf[tok_a[t]]
                p += 2
                ax = tok_axis[t]
                if ax >= 0:
                    p = _put_scaled(out, p, vals[ax], digits[ax])
                else:
                    p = _put_bytes(out, p, buf, tok_a[t] + 1, tok_b[t])
            p = _put_bytes(out, p, buf, code, body)           # the comment, as written
        else:
            for ax in range(4):
                t = axis_tok[ax]
                if t < 0:
                    continue
                out[p] = _SP
                out[p + 1] = _LETTER_OF_AXIS[ax]
                p += 2
                rel = rel_e[r] if ax == 3 else rel_xyz[r]
                if last and not rel:
                    p = _put_bytes(out, p, buf, tok_a[t] + 1, tok_b[t])
                else:
                    p = _put_scaled(out, p, vals[ax], digits[ax])
        if last:
            p = _put_bytes(out, p, buf, body, b)              # the line's own ending
            return p, added
        p = _put_bytes(out, p, nl, 0, nl.shape[0])
        added += 1
        for c in range(e, g_last + 1):
            p = _put_code(out, p, cut_code[c], code_ptr, txt_id, txt_buf, txt_ptr, nl)
            added += code_ptr[cut_code[c] + 1] - code_ptr[cut_code[c]]
        e = g_last + 1
        k += 1


@njit(cache=True)
def render_plain(buf, line_start, ins_slot, ins_code, split_rows, split_line, cut_ptr, cut_frac, cut_code,
                 code_ptr, txt_id, txt_buf, txt_ptr, nl, kind_arc, start_mm, end_mm, offset_mm, rel_xyz,
                 rel_e, inch, split_here, out, left_at):
    """Write the output into ``out``: before line i the instruction lines of the ``ins_code``
    entries with ``ins_slot == i`` (sorted by slot), then line i -- copied, or, for line
    ``split_line[k]`` (sorted), step ``split_rows[k]`` split at its cuts
    ``cut_ptr[k]:cut_ptr[k+1]``. A split move the kernel leaves to the reference gets
    ``left_at[k]`` = where its text belongs (else -1); ``split_here`` False leaves them all (the
    tests compare the two). Returns (bytes written, lines added by the splits written here)."""
    n_lines = line_start.shape[0] - 1
    n_ins = ins_slot.shape[0]
    n_split = split_rows.shape[0]
    tok_a = np.empty(64, np.int64)
    tok_b = np.empty(64, np.int64)
    tok_axis = np.empty(64, np.int64)
    p = 0
    ki = 0
    ks = 0
    added = 0
    li = 0
    while True:
        while ki < n_ins and ins_slot[ki] == li:
            p = _put_code(out, p, ins_code[ki], code_ptr, txt_id, txt_buf, txt_ptr, nl)
            ki += 1
        if li >= n_lines:
            break
        sl = split_line[ks] if ks < n_split else n_lines
        if sl == li:
            r = split_rows[ks]
            q = -1
            if split_here and not kind_arc[r]:
                q, n_add = _split_row(out, p, buf, line_start[li], line_start[li + 1], r, cut_ptr[ks],
                                      cut_ptr[ks + 1], cut_frac, cut_code, code_ptr, txt_id, txt_buf,
                                      txt_ptr, nl, start_mm, end_mm, offset_mm, rel_xyz, rel_e, inch,
                                      tok_a, tok_b, tok_axis)
            if q < 0:
                left_at[ks] = p
            else:
                left_at[ks] = -1
                p = q
                added += n_add
            ks += 1
            li += 1
            continue
        nxt = sl
        if ki < n_ins and ins_slot[ki] < nxt:
            nxt = ins_slot[ki]
        p = _put_bytes(out, p, buf, line_start[li], line_start[nxt])
        li = nxt
    return p, added


# ------------------------------------------------------------------------------------------------
# Rotation without instructions (``emit_rotated``): the rotated text of a whole file
_SNAP_MM = 1e-3                 # emit_line.SNAP_MM
_MAX_EXACT = 9007199254740992   # 2**53: a mantissa below it is a float exactly
_ROT_DECIMALS = 4               # emit_line.DECIMALS_MM["X"] / ["Y"]


@njit(cache=True)
def _text_value(txt, n):
    """float(text) of the number text txt[:n] (as Python's ``float``: the exact decimal value,
    rounded once); (0.0, False) where that is not exactly what a division gives."""
    mant, dec = _scan_decimal(txt, 0, n)
    if dec < 0 or abs(mant) >= _MAX_EXACT or dec > 22:
        return 0.0, False
    return mant / POW10[dec], True


@njit(cache=True)
def _rotated_row(out, p, buf, a, b, r, pstart, pend, offset_mm, rel_e, snap, has_snap,
                 em_val, em_txt, em_len, em_off, stats, tok_a, tok_b, tok_axis, val_txt, val_len):
    """Write line buf[a:b] (step r: an absolute, unsplit, non-arc G0/G1 in the rotated run) as
    ``emit_line.LineRewriter.rewrite(r, [])`` writes it under a rotation, and update the
    rewriter's state (``em_*``: the last X/Y text written, its offset, the head's XY) as it does.
    Returns the position after it, or -1 to leave the line to the reference (not the plain form:
    ``G<n>`` then `` <LETTER><number>`` words, each letter once; a number that needs more care)."""
    body, code, g_end, n_tok, axis_tok = _plain_words(buf, a, b, tok_a, tok_b, tok_axis)
    if n_tok < 0:
        return -1
    if axis_tok[0] < 0 and axis_tok[1] < 0:
        return -1           # X and Y added where the line names neither: the reference
    # X and Y: the previous text where the move is single-axis after rotating (the snap), else
    # the rotated end point, 4 decimals (``_snapped``, ``_piece_values``)
    for k in range(2):
        val_len[k] = -1
        if has_snap and snap[r, k]:
            ref = em_val[k] if not math.isnan(em_val[k]) else pstart[r, k]
            dev = abs(ref - pend[r, k])
            if dev > _SNAP_MM:
                stats[1] += 1                       # refused: earlier snaps drifted
            elif em_len[k] >= 0 and em_off[k] == offset_mm[r, k]:
                for q in range(em_len[k]):
                    val_txt[k, q] = em_txt[k, q]
                val_len[k] = em_len[k]
                stats[0] = max(stats[0], dev)
            else:
                stats[2] += 1                       # missed: no previous absolute text
        if val_len[k] < 0:
            n, ok = _round_scaled(pend[r, k] - offset_mm[r, k], _ROT_DECIMALS)
            if not ok:
                return -1
            val_len[k] = _put_scaled(val_txt[k], 0, n, _ROT_DECIMALS)
    # the head's XY after the line: the written text's value (``_written_xy``)
    new_val = np.empty(2)
    for k in range(2):
        x, ok = _text_value(val_txt[k], val_len[k])
        if not ok:
            return -1
        new_val[k] = x * 1.0 + offset_mm[r, k]
    p0 = p
    p = _put_bytes(out, p, buf, a, g_end)
    xy_done = False
    for t in range(n_tok):
        ax = tok_axis[t]
        if ax == 0 or ax == 1:
            if xy_done:
                continue
            xy_done = True
            for k in range(2):
                out[p] = _SP
                out[p + 1] = _LETTER_OF_AXIS[k]
                p = _put_bytes(out, p + 2, val_txt[k], 0, val_len[k])
            continue
        out[p] = _SP
        out[p + 1] = buf[tok_a[t]]
        p += 2
        if ax == 3 and rel_e[r]:
            # a relative E keeps its value, written as Decimal writes it (``_dec_text``)
            mant, dec = _scan_decimal(buf, tok_a[t] + 1, tok_b[t])
            if dec < 0:
                return -1
            p = _put_scaled(out, p, mant, dec)
        else:
            p = _put_bytes(out, p, buf, tok_a[t] + 1, tok_b[t])
    p = _put_bytes(out, p, buf, code, b)        # the comment and the line's own ending
    for k in range(2):
        em_val[k] = new_val[k]
        for q in range(val_len[k]):
            em_txt[k, q] = val_txt[k, q]
        em_len[k] = val_len[k]
        em_off[k] = offset_mm[r, k]
    return p


@njit(cache=True)
def render_rotated(buf, line_start, li, row_of_line, rewrite, splittable, arc, rel_xyz, rel_e, inch,
                   xy_moved, pstart, pend, end_mm, offset_mm, snap, has_snap, em_val, em_txt, em_len,
                   em_off, stats, out, p):
    """From line ``li`` on, write the rotated file into ``out`` at ``p`` as ``emit._write_lines``
    does with ``emit_line.LineRewriter`` and no instruction: lines copied, the rows in
    ``rewrite`` rewritten (``_rotated_row``), the rewriter's state (``em_*``, ``stats``: largest
    snap, snaps refused, snaps missed) kept as its ``note_kept`` keeps it. Stops at the first line
    it leaves to the reference (a relative, arc or inch move to rewrite, one not in the plain
    form, an XY move kept as written). Returns (position, that line; ``n_lines`` when done)."""
    n_lines = line_start.shape[0] - 1
    tok_a = np.empty(64, np.int64)
    tok_b = np.empty(64, np.int64)
    tok_axis = np.empty(64, np.int64)
    val_txt = np.empty((2, 64), np.uint8)
    val_len = np.empty(2, np.int64)
    while li < n_lines:
        a, b = line_start[li], line_start[li + 1]
        r = row_of_line[li]
        if r >= 0 and rewrite[r]:
            if arc[r] or rel_xyz[r] or inch[r]:
                return p, li
            q = _rotated_row(out, p, buf, a, b, r, pstart, pend, offset_mm, rel_e, snap, has_snap,
                             em_val, em_txt, em_len, em_off, stats, tok_a, tok_b, tok_axis, val_txt, val_len)
            if q < 0:
                return p, li
            p = q
            li += 1
            continue
        if r >= 0:
            # ``LineRewriter.note_kept``
            if not splittable[r]:
                if xy_moved[r]:                     # homing moved XY: no text to snap to
                    em_len[0] = -1
                    em_len[1] = -1
                    em_val[0] = end_mm[r, 0]
                    em_val[1] = end_mm[r, 1]
            elif not xy_moved[r]:
                if math.isnan(em_val[0]) or math.isnan(em_val[1]):
                    em_val[0] = pend[r, 0]
                    em_val[1] = pend[r, 1]
            else:
                return p, li                        # an XY move kept as written: its texts
        p = _put_bytes(out, p, buf, a, b)
        li += 1
    return p, n_lines
