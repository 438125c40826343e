"""A second process for ``layers.solve(..., workers=2)``: the groups whose start is known before
the chain reaches them.

A group's start is where the previous group ended, so groups are solved in print order. But the
first group, and every group after a fixed one, start at a point no solution changes (the fixed
group's exit; its end is the next fixed group's entry): in safe mode most groups (walls are
fixed; the Cura bunny: 538 of its 951 groups of > 12 curves). The helper solves those from the
back while the main process walks the chain from the front; each writes where it is into shared
memory, the main process takes the helper's answers when it reaches those groups, and the helper
stops where they meet. The budget plan's "done" marks are shared too, so both plan over the same
groups, and both spend the time left at once (``layers._GroupRunner``).

The helper is a fresh interpreter started with ``subprocess`` (``python -c``), not
``multiprocessing``: "fork" after HiGHS has started its threads can deadlock, and "spawn"
re-imports the caller's main module (a script without ``if __name__ == "__main__"`` would run
again in the child, and its parent hung writing the problem to it). The problem goes over a
temporary file, answers come back as pickled frames on the child's own stdout (its fd 1 points to
stderr for anything else printed), read by a thread.
"""
from __future__ import annotations

import os
import pickle
import queue
import struct
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

#: fewer groups with a known start than this: no helper (its start-up, ~1.5 s for a fresh
#: interpreter with the imports and kernels, would not pay)
HELPER_MIN_GROUPS = 16
_HEAD = struct.Struct("<q")


def anchored(problem) -> list[int]:
    """Groups to solve whose start does not depend on another group's solution."""
    out = []
    for g in range(problem.n_groups):
        if problem.group_fixed[g] or len(problem.group_curves(g)) <= 1:
            continue
        if g == 0 or (problem.group_fixed[g - 1] and len(problem.group_curves(g - 1)) > 0):
            out.append(g)
    return out


def _views(buf, n_groups):
    """(done mask per group, [main_at, helper_at]) over a shared buffer."""
    done = np.ndarray((n_groups,), np.int8, buf, 16)
    at = np.ndarray((2,), np.int64, buf, 0)
    return done, at


class Helper:
    def __init__(self, proc, shm, n_groups, path):
        self.proc, self.shm, self.path = proc, shm, path
        self.shared, self.at = _views(shm.buf, n_groups)
        self.results: dict[int, object] = {}
        self.inbox: queue.Queue = queue.Queue()
        self.dead = False
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    @classmethod
    def start(cls, problem, formulation, time_limit_s, budget_s, t0, kwargs):
        todo = anchored(problem)
        if len(todo) < HELPER_MIN_GROUPS:
            return None
        from multiprocessing import shared_memory
        shm = shared_memory.SharedMemory(create=True, size=16 + problem.n_groups)
        done, at = _views(shm.buf, problem.n_groups)
        done[:] = 0
        at[:] = (-1, problem.n_groups)
        # the budget's end as wall-clock time: the helper starts ~1.5 s later
        budget_end = None if budget_s is None else time.time() + budget_s - (time.perf_counter() - t0)
        fd, path = tempfile.mkstemp(prefix="gatesopt-helper-", suffix=".pickle")
        with os.fdopen(fd, "wb") as f:
            pickle.dump((problem, formulation, time_limit_s, budget_end, kwargs, todo, shm.name), f)
        proc = subprocess.Popen([sys.executable, "-c", "from gatesopt.ordering.helper import main; main()",
                                 path], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE)
        return cls(proc, shm, problem.n_groups, path)

    def _read(self) -> None:
        out = self.proc.stdout
        try:
            while True:
                head = out.read(_HEAD.size)
                if len(head) < _HEAD.size:
                    break
                (size,) = _HEAD.unpack(head)
                body = out.read(size)
                if len(body) < size:
                    break
                self.inbox.put(pickle.loads(body))
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
            g, gs = item
            self.results[g] = gs
            if block:
                return

    def take(self, g: int):
        """The helper's answer for group g if it has one or is working on it (then wait for it);
        None: the main process solves g itself."""
        self.at[0] = g
        self._drain(block=False)
        while g not in self.results and not self.dead and self.at[1] == g:
            self._drain(block=True)
        return self.results.pop(g, None)

    def stop(self) -> None:
        self.at[0] = 1 << 40                    # the helper stops after its current group
        try:
            self.proc.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self.reader.join(timeout=1.0)
        self.proc.stdout.close()
        del self.shared, self.at
        self.shm.close()
        self.shm.unlink()
        try:
            os.unlink(self.path)
        except OSError:
            pass


def main() -> None:
    """The helper process: solve the anchored groups from the back until the main process
    reaches them."""
    from multiprocessing import resource_tracker, shared_memory

    from .layers import FORMULATIONS, _end_of, _GroupRunner
    results = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)                               # stray prints (HiGHS, numba) go to stderr
    with open(sys.argv[1], "rb") as f:
        problem, formulation, time_limit_s, budget_end, kwargs, todo, name = pickle.load(f)
    shm = shared_memory.SharedMemory(name=name)
    # the parent owns the segment: without this the tracker would unlink it when we exit
    resource_tracker.unregister(shm._name, "shared_memory")
    done, at = _views(shm.buf, problem.n_groups)
    t0 = time.perf_counter()
    try:
        budget_s = None if budget_end is None else max(0.0, budget_end - time.time())
        runner = _GroupRunner(problem, FORMULATIONS[formulation], time_limit_s, budget_s, t0,
                              kwargs, shared=done)
        for g in reversed(todo):
            at[1] = g
            if g <= at[0]:
                break
            pos = (np.asarray(problem.origin_xy, float) if g == 0
                   else problem.curve_end_xy[problem.group_curves(g - 1)[-1]])
            gs = runner.run(g, problem.group(g, pos, _end_of(problem, g)))
            runner.passed(g)
            body = pickle.dumps((g, gs))
            results.write(_HEAD.pack(len(body)) + body)
            results.flush()
    finally:
        at[1] = -1
        del done, at
        shm.close()
        results.close()
