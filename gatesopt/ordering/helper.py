"""A second process for ``layers.solve(..., workers=2)``: the chain solved from both ends.

A group's start is where the previous group ended, so the main process solves groups in print
order. The helper walks the same chain from the back: each group it solves must end at the entry
of the path it chose for the group after it (or at the next fixed group's entry), and starts
where the group before it ends if that is known in advance (the first group; any group after a
fixed one: walls are fixed in safe mode). Otherwise the start is left free: the group is solved
as ``Group.backwards()`` (the same path walked from its end), which is exactly as good a chain
as the main process's, mirrored (the main process's groups leave their end free, the helper's
their start). Only the last group of the file, if its start is not known, is solved from a
guessed start (where the slicer came from); the main process re-scores it from the real one.

Both write where they are into shared memory; the main process takes the helper's answers when
it reaches those groups, ends its last own group at the entry of the helper's first if that is
known by then, and the helper stops where they meet. The budget plan's "done" marks are shared
too, so both plan over the same groups, and both spend the time left at once
(``runner.GroupRunner``).

The helper is a fresh interpreter (``child.Child``: started with ``subprocess``, its input over a
temporary file, answers back as pickled frames on its own stdout, read by a thread).
"""
from __future__ import annotations

import pickle
import struct
import time

from . import formulations
from .chain import end_of, path_options, solve_backwards
from .child import Child, child_open, views
from .problem import Anchor
from .runner import GroupRunner

#: fewer groups to solve than this: no helper (its start-up, ~1.5 s for a fresh interpreter with
#: the imports and kernels, would not pay)
HELPER_MIN_GROUPS = 16
_HEAD = struct.Struct("<q")


def groups_to_solve(problem) -> list[int]:
    """Groups a solver works on (not fixed, not empty), in print order."""
    return [g for g in range(problem.n_groups)
            if not problem.group_fixed[g] and len(problem.group_curves(g)) > 0]


def known_start(problem, g: int):
    """Where group g starts if no solution decides it (the first group, or the group after a
    fixed one: that group's last curve's end), else None."""
    if g == 0 or (problem.group_fixed[g - 1] and len(problem.group_curves(g - 1)) > 0):
        return _slicer_start(problem, g)
    return None


def _slicer_start(problem, g: int) -> Anchor:
    """Where the slicer's own order came from before group g's first curve (its curve as the
    slicer printed it)."""
    c = int(problem.group_curve_start[g]) - 1
    if c < 0:
        return Anchor.of(problem.origin_xy)
    return Anchor(problem.curve_end_xy[c].copy(), c, False)


class Helper(Child):
    """The main process's end of the chain helper (``start``; ``take`` per group in print
    order, ``stop`` at the end)."""

    def __init__(self, proc, shm, n_groups, path):
        self.results: dict[int, object] = {}
        super().__init__(proc, shm, n_groups, path)

    @property
    def shared(self):
        """Per group, done by either process: the budget plan's marks (``runner.GroupRunner``)."""
        return self.per_group

    @classmethod
    def start(cls, problem, formulation, time_limit_s, budget_s, t0, kwargs, greedy=None):
        """``greedy``: per group the greedy pass's answer (``runner.GreedyAnswer``) or None:
        the helper's warm starts and the answers of the groups it has no time for, as the main
        process's (``runner.GroupRunner.run``)."""
        todo = groups_to_solve(problem)
        if len(todo) < HELPER_MIN_GROUPS:
            return None
        # the budget's end as wall-clock time: the helper starts ~1.5 s later
        budget_end = None if budget_s is None else time.time() + budget_s - (time.perf_counter() - t0)
        return cls.spawn("helper", lambda name: (problem, formulation, time_limit_s, budget_end,
                                                 kwargs, todo, greedy, name),
                         problem.n_groups, "helper")

    def _frames(self, out):
        while True:
            head = out.read(_HEAD.size)
            if len(head) < _HEAD.size:
                return
            (size,) = _HEAD.unpack(head)
            body = out.read(size)
            if len(body) < size:
                return
            yield pickle.loads(body)

    def _keep(self, item) -> None:
        g, opts, entry, guess = item
        self.results[g] = (opts, entry, guess)

    def entry_of(self, g: int):
        """Where the helper's path for group g begins, if it has answered g (the main process
        then ends group g - 1 there), else None."""
        self._drain(block=False)
        got = self.results.get(g)
        return None if got is None else got[1]

    def take(self, g: int):
        """The helper's answer for group g, (options, guessed start or None), if it has one or is
        working on it (then wait for it): it has passed every group from its position on. None:
        the main process solves g itself."""
        self.at[0] = g
        self._drain(block=False)
        while g not in self.results and not self.dead and 0 <= self.at[1] <= g:
            self._drain(block=True)
        got = self.results.pop(g, None)
        return None if got is None else (got[0], got[2])


def main() -> None:
    """The helper process: solve the groups from the back until the main process reaches them."""
    results, payload, shm = child_open()
    problem, formulation, time_limit_s, budget_end, kwargs, todo, greedy, _ = payload
    done, at = views(shm.buf, problem.n_groups)
    t0 = time.perf_counter()
    entry = {}          # g -> where the path chosen for group g begins
    try:
        budget_s = None if budget_end is None else max(0.0, budget_end - time.time())
        record = formulations.lookup(formulation)
        runner = GroupRunner(problem, record.load().solve, time_limit_s, budget_s, t0, kwargs,
                             shared=done,
                             warm_up=(formulations.warm_up if "warm_up" in record.capabilities
                                      else None))
        for g in reversed(todo):
            at[1] = g
            if g <= at[0]:
                break
            end = end_of(problem, g)
            if end is None:
                end = entry.get(g + 1)
            start, guess = known_start(problem, g), None
            ans = greedy[g] if greedy is not None else None
            late = runner.out_of_time
            if start is None and end is not None:
                grp, opts = solve_backwards(runner, problem, g, end, ans)
            else:
                if start is None:       # the file's last group: no end, no known start
                    start = guess = _slicer_start(problem, g)
                grp = problem.group(g, start, end)
                gs = runner.run(g, grp, ans)
                grp.check_order(gs.order)
                opts = path_options(grp, gs)
            if runner.out_of_time > late:
                # no time for g: the main process answers it and those before it, where a group
                # the budget leaves unsearched keeps greedy's answer for the start greedy solved
                # it from (proven where greedy proved it); walked backwards from here, greedy's
                # proofs rarely close (its start costs unknown). An early helper out of time
                # answered every group so, in milliseconds: prusa25_bunny_triangles15_lh01
                # free, 864 of 1,069 groups, 945 proven by greedy's subset DP -> 189
                break
            runner.passed(g)
            entry[g] = problem.cand_anchor(g, grp, int(opts[0].order[0]))    # (not empty)
            body = pickle.dumps((g, opts, entry[g], guess))
            results.write(_HEAD.pack(len(body)) + body)
            results.flush()
    finally:
        at[1] = -1
        del done, at
        shm.close()
        results.close()
