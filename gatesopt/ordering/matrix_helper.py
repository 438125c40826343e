"""A second process for the greedy chain (``layers.solve(..., "greedy", workers=2)``): it makes
link matrices, never paths.

Greedy's answer for a group depends on where the group starts (the previous group's end), so its
chain is solved in print order by one process, with one worker or two: the same file either
way (issue 36: ``--formulation greedy`` and an exact run's greedy pass must be one answer, and
the chain helper of ``helper.py``, solving from the back, starts groups elsewhere). What a second
process can do without changing the answer is the time objective's link matrices: a group's
matrix depends on its candidates only, not on its start or end (``cost.TimePricer.dense``), and
it is most of what a greedy group costs (docs/BENCHMARKS.md, "Link-cost build"). The helper
makes them from the back of the chain, as the chain helper walks it, and stops where it meets the
main process, which takes a matrix made there instead of making it (``take``) and makes the
others itself: the matrices are the same numbers bit for bit, so the paths are too.

The helper is a fresh interpreter (``child.Child``, as ``helper.py``'s), reading the problem from
a temporary file; each matrix comes back on its stdout as a frame (group, rows) followed by its float64 bytes, read by a thread straight into the array the
main process keeps (no pickle, one copy: the Cura bunny's matrices are ~190 MB in all). A shared
byte per group says what the helper does with it (``FREE``, ``BUILDING``, ``SENT``): the main
process waits for a group only while the helper is making or sending it.
"""
from __future__ import annotations

import dataclasses
import struct

import numpy as np

from .budget import MATRIX_S_PER_LINK
from .child import Child, child_open, views
from .problem import Anchor

#: fewer groups than this with a matrix to make: no helper (a fresh interpreter's start, ~1.5 s
#: with the imports and kernels, would not pay); ``helper.HELPER_MIN_GROUPS`` for the chain helper
MATRIX_HELPER_MIN_GROUPS = 16
#: nor where making every matrix is planned to take less than this (``budget.MATRIX_S_PER_LINK``,
#: ~2 candidates a curve): the main process would have made them all before the helper has
#: started, and starting it (the problem written to a file, a process spawned) is the main
#: process's time. real_ideamaker420, free: 53 matrices of 2 MB, the pass 0.28 s with one worker,
#: 0.75 s with a helper that never arrived
MATRIX_HELPER_MIN_S = 1.0
#: a group's state in the shared bytes: nobody has taken it / the helper makes it / sent it
FREE, BUILDING, SENT = 0, 1, 2
_HEAD = struct.Struct("<qq")        # group, rows (the matrix is rows x rows float64)


def matrix_groups(problem) -> list[int]:
    """Groups whose time-objective link matrix the greedy chain would make (not fixed, >= 2
    curves), in print order; none without a time pricer (the travel objective's matrices are one
    numpy expression: not worth a frame)."""
    if problem.pricer is None:
        return []
    return [g for g in range(problem.n_groups)
            if not problem.group_fixed[g] and len(problem.group_curves(g)) >= 2]


def planned_matrix_s(problem, todo) -> float:
    """What making the matrices of groups ``todo`` is planned to take (``budget.MATRIX_S_PER_LINK``
    per link, ~2 candidates a curve: what the budget plan charges)."""
    n = np.diff(problem.group_curve_start)[np.asarray(todo, np.int64)].astype(float)
    return float(MATRIX_S_PER_LINK * np.sum((2.0 * n) ** 2))


def with_arc(grp, arc):
    """``grp`` with the link matrix ``arc`` made elsewhere for the same group (the helper, or a
    greedy pass before an exact solve): it depends on the candidates only, so it is this
    instance's matrix whatever its start and end. ``grp`` unchanged where it has no time costs,
    already has a matrix, or ``arc`` is not its shape."""
    c = grp.costs
    if (arc is None or c is None or getattr(c, "euclidean", False) or c.arc is not None
            or arc.shape != (grp.n_cands, grp.n_cands)):
        return grp
    return dataclasses.replace(grp, costs=dataclasses.replace(c, arc=arc))


class MatrixHelper(Child):
    """The main process's end of the helper (``start``; ``take`` per group in print order,
    ``stop`` at the end)."""

    def __init__(self, proc, shm, n_groups, path):
        self.results: dict[int, np.ndarray] = {}
        super().__init__(proc, shm, n_groups, path)

    @property
    def state(self):
        """Per group ``FREE``, ``BUILDING`` or ``SENT`` (the shared bytes)."""
        return self.per_group

    @classmethod
    def start(cls, problem):
        """The helper for ``problem``, or None where it would not pay (``matrix_groups``)."""
        todo = matrix_groups(problem)
        if len(todo) < MATRIX_HELPER_MIN_GROUPS or planned_matrix_s(problem, todo) < MATRIX_HELPER_MIN_S:
            return None
        # (every group FREE: the shared bytes start at 0)
        return cls.spawn("matrix_helper", lambda name: (problem, todo, name), problem.n_groups,
                         "matrices")

    def _frames(self, out):
        while True:
            head = out.read(_HEAD.size)
            if len(head) < _HEAD.size:
                return
            g, m = _HEAD.unpack(head)
            arc = np.empty((m, m), np.float64)
            view = memoryview(arc).cast("B")
            got = 0
            while got < len(view):
                n = out.readinto(view[got:])
                if not n:
                    break
                got += n
            if got < len(view):
                return
            yield g, arc

    def _keep(self, item) -> None:
        g, arc = item
        self.results[g] = arc

    def take(self, g: int) -> np.ndarray | None:
        """Group g's link matrix if the helper made it, or is making or sending it (then wait
        for it); None: the main process makes it. Called for the groups in print order (the
        helper stops where the main process is)."""
        self.at[0] = g
        self._drain(block=False)
        while g not in self.results and not self.dead and self.state[g] != FREE:
            self._drain(block=True)
        return self.results.pop(g, None)


def main() -> None:
    """The helper process: each group's matrix from the back until the main process reaches it."""
    results, payload, shm = child_open()
    problem, todo, _ = payload
    state, at = views(shm.buf, problem.n_groups)
    origin = Anchor.of(problem.origin_xy)      # any start: the matrix does not depend on it
    try:
        for g in reversed(todo):
            at[1] = g
            state[g] = BUILDING
            if g <= at[0]:
                state[g] = FREE
                break
            arc = problem.group(g, origin).costs.matrix()
            if arc is None:                     # too many candidates for a matrix
                state[g] = FREE
                continue
            arc = np.ascontiguousarray(arc, np.float64)
            results.write(_HEAD.pack(g, len(arc)))
            results.write(memoryview(arc).cast("B"))
            results.flush()
            state[g] = SENT
    finally:
        at[1] = -1
        del state, at
        shm.close()
        results.close()
