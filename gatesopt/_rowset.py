"""Exact lookups among rows of floats (numba): is a row present in a set, does a row repeat.

The verifier asks these of millions of move keys per file; most answers are exact hits (a split
move joined back has exactly the original's end points), so a hash table settles them in one pass
and only the rest need a k-d tree. Every hash hit is confirmed value by value: equal answers mean
equal rows (-0.0 equals 0.0, as in a distance).
"""
from __future__ import annotations

import numpy as np
from numba import njit

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_PRIME = np.uint64(0x100000001B3)
_S30, _S27, _S31 = np.uint64(30), np.uint64(27), np.uint64(31)


@njit(cache=True)
def _hashes(bits):
    """Row hashes of the (n, k) uint64 view of canonical floats: FNV over the words, then
    splitmix64's finalizer (coordinates are round decimals whose bits differ in few places)."""
    n, k = bits.shape
    out = np.empty(n, np.uint64)
    for i in range(n):
        h = np.uint64(0xCBF29CE484222325)
        for c in range(k):
            h = (h ^ bits[i, c]) * _PRIME
        h ^= h >> _S30
        h *= _M1
        h ^= h >> _S27
        h *= _M2
        h ^= h >> _S31
        out[i] = h
    return out


@njit(cache=True, inline="always")
def _equal(a, i, b, j):
    for c in range(a.shape[1]):
        if a[i, c] != b[j, c]:
            return False
    return True


@njit(cache=True)
def _build(rows, h):
    """Open-addressing table of row indices (-1 empty) and, per row, whether an earlier row equals it."""
    n = rows.shape[0]
    size = 16
    while size < 2 * n:
        size *= 2
    table = np.full(size, -1, np.int64)
    repeat = np.zeros(n, np.bool_)
    for i in range(n):
        s = np.int64(h[i] & np.uint64(size - 1))
        while table[s] >= 0:
            if _equal(rows, table[s], rows, i):
                repeat[i] = True
                repeat[table[s]] = True
                break
            s = (s + 1) & (size - 1)
        if table[s] < 0:
            table[s] = i
    return table, repeat


@njit(cache=True)
def _member(points, table, q, hq):
    size = table.shape[0]
    out = np.zeros(q.shape[0], np.bool_)
    for i in range(q.shape[0]):
        s = np.int64(hq[i] & np.uint64(size - 1))
        while table[s] >= 0:
            if _equal(points, table[s], q, i):
                out[i] = True
                break
            s = (s + 1) & (size - 1)
    return out


def _canonical(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows as contiguous floats with -0.0 made 0.0, their hashes)."""
    rows = np.ascontiguousarray(rows, dtype=float) + 0.0
    return rows, _hashes(rows.view(np.uint64))


class RowSet:
    """The rows of ``points`` hashed once, for several ``member`` questions."""

    def __init__(self, points: np.ndarray):
        self.points, hp = _canonical(points)
        self.table = _build(self.points, hp)[0] if len(self.points) else None

    def member(self, q: np.ndarray) -> np.ndarray:
        """(len(q),) bool: row q[i] equals a row of the set (value by value)."""
        if self.table is None or len(q) == 0:
            return np.zeros(len(q), bool)
        q, hq = _canonical(q)
        return _member(self.points, self.table, q, hq)


def member(points: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(len(q),) bool: row q[i] equals a row of ``points`` (value by value)."""
    if len(points) == 0 or len(q) == 0:
        return np.zeros(len(q), bool)
    return RowSet(points).member(q)


def repeated(rows: np.ndarray) -> np.ndarray:
    """(len(rows),) bool: the row equals another row (value by value)."""
    if len(rows) == 0:
        return np.zeros(0, bool)
    rows, h = _canonical(rows)
    return _build(rows, h)[1]
