"""What a long command shows while it runs: the progress bar over the ordering's groups, and the
number of worker processes the ordering may use."""
from __future__ import annotations

import contextlib
import os
import sys
import time


def default_workers() -> int:
    """Processes for the ordering (``layers.solve(workers=)``): 2 where the machine has 2 cores."""
    return 2 if (os.cpu_count() or 1) >= 2 else 1


@contextlib.contextmanager
def group_progress(enabled: bool, stream=None, mininterval: float = 0.25,
                   deadline_s: float | None = None):
    """A progress bar over the ordering's groups on stderr (``progress`` for ``layers.solve``:
    groups done, proven so far), or None when not ``enabled`` (not a terminal). With a budget,
    ``deadline_s`` (a ``time.perf_counter()`` reading: when the budget ends) replaces tqdm's
    estimate, which extrapolates the rate of the groups so far: under a budget the groups left
    get what is left, whatever the rate."""
    if not enabled:
        yield None
        return
    from tqdm import tqdm
    bar_format = (None if deadline_s is None
                  else "{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} [{elapsed}{postfix}]")
    bar = tqdm(total=1, unit="group", desc="ordering", leave=False, dynamic_ncols=True,
               file=stream or sys.stderr, mininterval=mininterval, bar_format=bar_format)

    def update(done: int, total: int, proven: int) -> None:
        if bar.total != total:
            bar.total = total
        post = f"proven {proven:,}"
        if deadline_s is not None:
            post += f", budget ends in {max(0.0, deadline_s - time.perf_counter()):.0f} s"
        bar.set_postfix_str(post, refresh=False)
        bar.update(done - bar.n)

    try:
        yield update
    finally:
        bar.close()
