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

The helper is a fresh interpreter (``python -c``, as ``helper.py`` starts its own, for the same
reasons), reading the problem from a temporary file; each matrix comes back on its stdout as a
frame (group, rows) followed by its float64 bytes, read by a thread straight into the array the
main process keeps (no pickle, one copy: the Cura bunny's matrices are ~190 MB in all). A shared
byte per group says what the helper does with it (``FREE``, ``BUILDING``, ``SENT``): the main
process waits for a group only while the helper is making or sending it.
"""
from __future__ import annotations

import dataclasses
import os
import pickle
import queue
import struct
import subprocess
import sys
import tempfile
import threading

import numpy as np

from .budget import MATRIX_S_PER_LINK
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


def _views(buf, n_groups):
    """(state per group, [main_at, helper_at]) over a shared buffer."""
    state = np.ndarray((n_groups,), np.int8, buf, 16)
    at = np.ndarray((2,), np.int64, buf, 0)
    return state, at


class MatrixHelper:
    """The main process's end of the helper (``start``; ``take`` per group in print order,
    ``stop`` at the end)."""

    def __init__(self, proc, shm, n_groups, path):
        self.proc, self.shm, self.path = proc, shm, path
        self.state, self.at = _views(shm.buf, n_groups)
        self.results: dict[int, np.ndarray] = {}
        self.fresh: list[int] = []          # groups received since ``received`` was last called
        self.inbox: queue.Queue = queue.Queue()
        self.dead = False
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    @classmethod
    def start(cls, problem):
        """The helper for ``problem``, or None where it would not pay (``matrix_groups``)."""
        todo = matrix_groups(problem)
        if len(todo) < MATRIX_HELPER_MIN_GROUPS or planned_matrix_s(problem, todo) < MATRIX_HELPER_MIN_S:
            return None
        from multiprocessing import shared_memory
        shm = shared_memory.SharedMemory(create=True, size=16 + problem.n_groups)
        state, at = _views(shm.buf, problem.n_groups)
        state[:] = FREE
        at[:] = (-1, problem.n_groups)
        del state, at
        fd, path = tempfile.mkstemp(prefix="gatesopt-matrices-", suffix=".pickle")
        with os.fdopen(fd, "wb") as f:
            pickle.dump((problem, todo, shm.name), f, protocol=pickle.HIGHEST_PROTOCOL)
        proc = subprocess.Popen([sys.executable, "-c",
                                 "from gatesopt.ordering.matrix_helper import main; main()", path],
                                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE)
        return cls(proc, shm, problem.n_groups, path)

    def _read(self) -> None:
        out = self.proc.stdout
        try:
            while True:
                head = out.read(_HEAD.size)
                if len(head) < _HEAD.size:
                    break
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
                    break
                self.inbox.put((g, arc))
        finally:
            self.inbox.put(None)

    def _drain(self, block: bool) -> None:
        while not self.dead:
            try:
                item = self.inbox.get(block=block, timeout=0.5 if block else None)
            except queue.Empty:
                if block and self.proc.poll() is not None and self.inbox.empty():
                    self.dead = True
                return
            if item is None:
                self.dead = True
                return
            g, arc = item
            self.results[g] = arc
            self.fresh.append(g)
            if block:
                return

    def take(self, g: int) -> np.ndarray | None:
        """Group g's link matrix if the helper made it, or is making or sending it (then wait
        for it); None: the main process makes it. Called for the groups in print order (the
        helper stops where the main process is)."""
        self.at[0] = g
        self._drain(block=False)
        while g not in self.results and not self.dead and self.state[g] != FREE:
            self._drain(block=True)
        return self.results.pop(g, None)

    def received(self) -> list[int]:
        """Groups whose matrix arrived since the last call (the budget plan stops charging
        their matrix: ``budget.BudgetPlan.matrix_made``)."""
        self._drain(block=False)
        out, self.fresh = self.fresh, []
        return out

    def wait(self) -> None:
        """Until the helper has ended (every matrix it makes received): for tests, which then
        compare each matrix with the main process's own."""
        while not self.dead:
            self._drain(block=True)

    def stop(self) -> None:
        # a matrix the helper is still making is nobody's (the main process made its own)
        self.at[0] = 1 << 40
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        self.reader.join(timeout=1.0)
        self.proc.stdout.close()
        del self.state, self.at
        self.shm.close()
        self.shm.unlink()
        try:
            os.unlink(self.path)
        except OSError:
            pass


def main() -> None:
    """The helper process: each group's matrix from the back until the main process reaches it."""
    import signal
    from multiprocessing import resource_tracker, shared_memory
    # Ctrl-C reaches every process of the terminal's group: the main process stops the run
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    results = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)                               # stray prints go to stderr
    with open(sys.argv[1], "rb") as f:
        problem, todo, name = pickle.load(f)
    shm = shared_memory.SharedMemory(name=name)
    # the parent owns the segment: without this the tracker would unlink it when we exit
    resource_tracker.unregister(shm._name, "shared_memory")
    state, at = _views(shm.buf, problem.n_groups)
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
