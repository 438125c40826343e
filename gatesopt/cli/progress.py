"""What a long command shows while it runs: a status line from its first second (what it does,
for how long, the compile note the moment a first run starts compiling), the progress bar over the
ordering's groups, and the number of worker processes the ordering may use."""
from __future__ import annotations

import contextlib
import os
import sys
import threading
import time


def default_workers() -> int:
    """Processes for the ordering (``layers.solve(workers=)``): 2 where the machine has 2 cores."""
    return 2 if (os.cpu_count() or 1) >= 2 else 1


@contextlib.contextmanager
def group_progress(enabled: bool, stream=None, mininterval: float = 0.25,
                   deadline_s: float | None = None, after: str = ""):
    """A progress bar over the ordering's groups on stderr (``progress`` for ``layers.solve``:
    groups done, proven so far), or None when not ``enabled`` (not a terminal). With a budget,
    ``deadline_s`` (a ``time.perf_counter()`` reading: when the budget ends) replaces tqdm's
    estimate, which extrapolates the rate of the groups so far: under a budget the groups left
    get what is left, whatever the rate. The command's status line (``command_status``) steps
    aside for the bar and comes back after it, saying ``after`` (what the command does next)."""
    if not enabled:
        yield None
        return
    from tqdm import tqdm
    pause_status()
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
        resume_status(after)


# ------------------------------------------------------------------------------------------------
# the status line: from the first second of a run, before any progress bar (issue 37: "the first
# run is silent for ~20 s before its progress bar")

#: the status line is first drawn this long after the command starts (a quick command shows none)
STATUS_FIRST_S = 0.5
#: and redrawn this often
STATUS_EVERY_S = 1.0
#: ``GATESOPT_PROGRESS=1`` draws the status line where standard error is no terminal (a test, a
#: log); ``0`` never draws it
PROGRESS_ENV = "GATESOPT_PROGRESS"

COMPILE_NOTE = ("compiling numba kernels: the first run after an install or an update does (up to a "
                "few minutes on 2 cores, not counted against a budget); later runs load them from "
                "the cache")


def wants_progress(stream=None) -> bool:
    """Progress is drawn on ``stream`` (standard error): a terminal, unless ``GATESOPT_PROGRESS``
    says otherwise."""
    env = os.environ.get(PROGRESS_ENV, "")
    if env in ("0", "1"):
        return env == "1"
    stream = stream or sys.stderr
    return bool(getattr(stream, "isatty", lambda: False)())


def wants_progress_on_terminal(stream) -> bool:
    """``stream`` is a terminal (the status line is drawn there by itself, not by request)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


class Status:
    """One line on standard error saying what the command does and for how long, redrawn in
    place every ``STATUS_EVERY_S`` from ``STATUS_FIRST_S`` on (a thread) until the command ends;
    the command's own output clears it first (``Status.wrap``), a progress bar takes its place
    while it runs (``pause`` / ``resume``)."""

    def __init__(self, what: str, stream, compiling=lambda: False):
        self.what = what
        self.stage = ""
        self._stream = stream
        self._compiling = compiling
        self._t0 = time.perf_counter()
        self._lock = threading.RLock()
        self._drawn = False
        self._paused = False
        self.line_open = False          # the command's output stopped inside a line
        # GATESOPT_PROGRESS=1 where nothing is a terminal: every stream counts as the screen
        self.test_stream = not wants_progress_on_terminal(stream)
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gatesopt-status", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        wait = STATUS_FIRST_S
        while not self._done.wait(wait):
            self.draw()
            wait = STATUS_EVERY_S

    def text(self) -> str:
        s = f"{self.what}: {time.perf_counter() - self._t0:.0f} s"
        if self._compiling():
            s += ", compiling numba kernels (first run only)"
        elif self.stage:
            s += f", {self.stage}"
        return s

    def draw(self) -> None:
        with self._lock:
            if self._done.is_set() or self._paused or self.line_open:
                return
            self._stream.write(f"\r{self.text()}\x1b[K")
            self._stream.flush()
            self._drawn = True

    def clear(self) -> None:
        with self._lock:
            if self._drawn:
                self._stream.write("\r\x1b[K")
                self._stream.flush()
                self._drawn = False

    def pause(self) -> None:
        """A progress bar draws from now on: clear the line, draw nothing."""
        with self._lock:
            self.clear()
            self._paused = True

    def resume(self, stage: str = "") -> None:
        """The bar is gone: draw the line again, saying ``stage``."""
        with self._lock:
            self.stage = stage
            self._paused = False
        self.draw()

    def note(self, line: str) -> None:
        """A line of its own (the compile note), the status line redrawn below it."""
        with self._lock:
            self.clear()
            self._stream.write(line + "\n")
            self._stream.flush()
        self.draw()

    def close(self) -> None:
        with self._lock:
            self._done.set()
            self.clear()

    def wrap(self, stream):
        """``stream`` (standard output or error) whose writes clear the status line first."""
        return _Ending(stream, self)


class _Ending:
    """A text stream that clears a ``Status`` line before each write (the command's own output),
    and otherwise is the stream it wraps."""

    def __init__(self, stream, status: Status):
        self._stream = stream
        self._status = status

    def _shares_the_screen(self) -> bool:
        """Output to a pipe or a file cannot collide with the status line on the terminal."""
        try:
            return self._stream.isatty()
        except (AttributeError, ValueError):
            return False

    @property
    def buffer(self):
        """The binary stream (G-code to ``-o -``): on the terminal, the status line ends first."""
        if self._shares_the_screen():
            with self._status._lock:
                self._status.clear()
                self._status.line_open = True
        return self._stream.buffer

    def write(self, text):
        if not text or (not self._shares_the_screen() and not self._status.test_stream):
            return self._stream.write(text)
        with self._status._lock:
            self._status.clear()        # redrawn below it at the next tick
            # not drawn inside a line (print writes its text and its end separately)
            self._status.line_open = not text.endswith(("\n", "\r"))
            return self._stream.write(text)

    def __getattr__(self, name):
        return getattr(self._stream, name)


class _Silent:
    """A status that draws nothing (standard error is no terminal): notes are plain lines."""

    def __init__(self, stream):
        self._stream = stream

    def note(self, line: str) -> None:
        self._stream.write(line + "\n")
        self._stream.flush()

    def pause(self) -> None:
        pass

    def resume(self, stage: str = "") -> None:
        pass

    def close(self) -> None:
        pass


#: the status of the running command (``command_status``), for the progress bars
_current: list = []


@contextlib.contextmanager
def command_status(what: str, compiling=lambda: False, on_long_compile=None):
    """The status line of a command from its first second on (``Status``; nothing drawn where
    ``wants_progress`` says no), with the compile note printed the moment a long compile starts
    (``on_long_compile``: ``_jit.on_long_compile``). Yields whether the note was printed (a list,
    filled in as it happens). Standard output and error are wrapped so that the command's output
    clears the line first."""
    stream = sys.stderr
    status = Status(what, stream, compiling) if wants_progress(stream) else _Silent(stream)
    noted: list = []

    def note() -> None:
        noted.append(True)
        status.note(f"gatesopt: note: {COMPILE_NOTE}")

    withdraw = on_long_compile(note) if on_long_compile is not None else None
    saved = sys.stdout, sys.stderr
    if isinstance(status, Status):
        sys.stdout, sys.stderr = status.wrap(sys.stdout), status.wrap(sys.stderr)
    _current.append(status)
    try:
        yield noted
    finally:
        if withdraw is not None:
            withdraw()
        _current.remove(status)
        status.close()
        if isinstance(status, Status):
            sys.stdout, sys.stderr = saved


def pause_status() -> None:
    """A progress bar starts: the command's status line steps aside."""
    for s in _current:
        s.pause()


def resume_status(stage: str = "") -> None:
    """The progress bar is gone: the status line again, saying ``stage``."""
    for s in _current:
        s.resume(stage)
