"""Line texts of a Program in bulk (numba): group equal lines, walk two files' lines side by side.

A gated file has millions of inserted instruction lines with a handful of distinct texts. Whatever
is decided from a line's text alone (is it a motor instruction, which one) is decided once per
distinct text: ``distinct_lines`` groups the lines by their exact bytes (a hash table whose every
hit is confirmed byte by byte, so equal ids mean equal texts), and the caller maps the answers back.
"""
from __future__ import annotations

import numpy as np
from numba import njit


def code_words(line):
    """The upper-case words of one line's code (``str`` or ``bytes``, as given): the comment after
    ``;`` and a line number ``N<n>`` dropped. The one reading of a line's instruction word for
    every module that decides from a line's text (firmware, planner, ordering)."""
    semi = b";" if isinstance(line, (bytes, bytearray)) else ";"
    words = line.split(semi, 1)[0].upper().split()
    if len(words) > 1 and words[0][:1] in (b"N", "N") and words[0][1:].isdigit():
        words = words[1:]
    if len(words) > 1 and len(words[0]) == 1 and words[1][:1].isdigit():
        # a command's number after blanks ("G 28 W"): one word, as the firmware reads it
        # (``_scan_words.parse_words``)
        words = [words[0] + words[1]] + words[2:]
    return words


_FNV_OFFSET = np.uint64(14695981039346656037)
_FNV_PRIME = np.uint64(1099511628211)


@njit(cache=True, inline="always")
def _same(buf_a, a0, a1, buf_b, b0, b1):
    if a1 - a0 != b1 - b0:
        return False
    for k in range(a1 - a0):
        if buf_a[a0 + k] != buf_b[b0 + k]:
            return False
    return True


@njit(cache=True)
def _first_equal(buf, line_start, lines):
    """first[k]: the smallest j with line ``lines[j]`` byte-equal to line ``lines[k]``."""
    m = lines.shape[0]
    size = 16
    while size < 2 * m:
        size *= 2
    table = np.full(size, -1, np.int64)
    first = np.empty(m, np.int64)
    for k in range(m):
        a, b = line_start[lines[k]], line_start[lines[k] + 1]
        h = _FNV_OFFSET
        for i in range(a, b):
            h = (h ^ np.uint64(buf[i])) * _FNV_PRIME
        s = np.int64(h & np.uint64(size - 1))
        while True:
            j = table[s]
            if j < 0:
                table[s] = k
                first[k] = k
                break
            if _same(buf, line_start[lines[j]], line_start[lines[j] + 1], buf, a, b):
                first[k] = j
                break
            s = (s + 1) & (size - 1)
    return first


def distinct_lines(program, lines) -> tuple[np.ndarray, list[str]]:
    """(inverse, texts): the distinct texts of ``program``'s lines ``lines`` (with their endings,
    in order of first appearance) and, per line, the index of its text."""
    lines = np.asarray(lines, np.int64)
    if not len(lines):
        return np.zeros(0, np.int64), []
    first = _first_equal(np.frombuffer(program.data, np.uint8), program.line_start, lines)
    is_rep = first == np.arange(len(lines))
    rank = np.cumsum(is_rep) - 1                # a line's text index, counted at its first line
    return rank[first], [program.line_text(int(k)) for k in lines[is_rep]]


@njit(cache=True)
def walk_kept(buf_a, ls_a, lines_a, buf_b, ls_b, lines_b, skippable, i, j):
    """Walk lines ``lines_a[i:]`` of one file and ``lines_b[j:]`` of another: equal texts advance
    both, a ``skippable[j]`` line of b that is not equal advances b alone. Returns (i, j) at the
    first pair that is neither, or where a side ends."""
    na, nb = lines_a.shape[0], lines_b.shape[0]
    while i < na and j < nb:
        la, lb = lines_a[i], lines_b[j]
        if _same(buf_a, ls_a[la], ls_a[la + 1], buf_b, ls_b[lb], ls_b[lb + 1]):
            i += 1
            j += 1
        elif skippable[j]:
            j += 1
        else:
            break
    return i, j
