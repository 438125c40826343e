"""The second process of a two-worker solve, both ends of it: what ``helper.py`` (the chain
solved from the back) and ``matrix_helper.py`` (greedy's link matrices) share.

The child is a fresh interpreter started with ``subprocess`` (``python -c``), not
``multiprocessing``: "fork" after HiGHS has started its threads can deadlock, and "spawn"
re-imports the caller's main module (a script without ``if __name__ == "__main__"`` would run
again in the child, and its parent hung writing the problem to it). Its input goes over a
temporary file; its answers come back as frames on the child's own stdout (its fd 1 points to
stderr for anything else printed), read by a thread of the parent (``Child._read``). Both share
16 + n_groups bytes (``views``): where each process is, [main_at, helper_at], and one byte per
group whose meaning is the helper's own.
"""
from __future__ import annotations

import os
import pickle
import queue
import subprocess
import sys
import tempfile
import threading

import numpy as np


def views(buf, n_groups: int):
    """(one int8 per group, [main_at, helper_at] int64) over a shared buffer."""
    per_group = np.ndarray((n_groups,), np.int8, buf, 16)
    at = np.ndarray((2,), np.int64, buf, 0)
    return per_group, at


class Child:
    """The parent's end: ``spawn`` starts the child; a subclass reads its frames (``_frames``)
    and keeps what they say (``_keep``); ``_drain`` moves them from the reader thread's inbox;
    ``stop`` ends the child and frees what it used."""

    def __init__(self, proc, shm, n_groups: int, path: str):
        self.proc, self.shm, self.path = proc, shm, path
        self.per_group, self.at = views(shm.buf, n_groups)
        self.inbox: queue.Queue = queue.Queue()
        self.dead = False
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    @classmethod
    def spawn(cls, module: str, payload, n_groups: int, prefix: str):
        """The parent's end of a child started now: the shared bytes zeroed with [main_at,
        helper_at] = (-1, n_groups), ``payload(shm_name)`` pickled to a temporary file, and
        ``gatesopt.ordering.<module>.main()`` started on it."""
        from multiprocessing import shared_memory
        shm = shared_memory.SharedMemory(create=True, size=16 + n_groups)
        per_group, at = views(shm.buf, n_groups)
        per_group[:] = 0
        at[:] = (-1, n_groups)
        del per_group, at
        fd, path = tempfile.mkstemp(prefix=f"gatesopt-{prefix}-", suffix=".pickle")
        with os.fdopen(fd, "wb") as f:
            pickle.dump(payload(shm.name), f, protocol=pickle.HIGHEST_PROTOCOL)
        proc = subprocess.Popen([sys.executable, "-c",
                                 f"from gatesopt.ordering.{module} import main; main()", path],
                                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE)
        return cls(proc, shm, n_groups, path)

    def _frames(self, out):
        """Yield each item the child wrote on ``out``; end at its end or a cut frame."""
        raise NotImplementedError

    def _keep(self, item) -> None:
        """Keep one item the child sent."""
        raise NotImplementedError

    def _read(self) -> None:
        try:
            for item in self._frames(self.proc.stdout):
                self.inbox.put(item)
        finally:
            self.inbox.put(None)

    def _drain(self, block: bool) -> None:
        """Keep what has arrived; with ``block``, wait for one item (or the child's end)."""
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
            self._keep(item)
            if block:
                return

    def wait(self) -> None:
        """Until the child has ended (everything it sent received): for tests."""
        while not self.dead:
            self._drain(block=True)

    def stop(self) -> None:
        # what the child is still working on is nobody's (the main process did it itself)
        self.at[0] = 1 << 40
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        self.reader.join(timeout=1.0)
        self.proc.stdout.close()
        del self.per_group, self.at
        self.shm.close()
        self.shm.unlink()
        try:
            os.unlink(self.path)
        except OSError:
            pass


def child_open():
    """The child's start: (answer stream, the parent's payload, the shared memory). Ctrl-C
    reaches every process of the terminal's group: the parent stops the run (and this process,
    ``Child.stop``); here it would only print a traceback."""
    import signal
    from multiprocessing import resource_tracker, shared_memory
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    results = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)                               # stray prints (HiGHS, numba) go to stderr
    with open(sys.argv[1], "rb") as f:
        payload = pickle.load(f)
    shm = shared_memory.SharedMemory(name=payload[-1])
    # the parent owns the segment: without this the tracker would unlink it when we exit
    resource_tracker.unregister(shm._name, "shared_memory")
    return results, payload, shm
