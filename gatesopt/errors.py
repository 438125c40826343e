"""Errors a user sees: one line, naming the file and the line."""
from __future__ import annotations


class GatesoptError(Exception):
    """Base class: everything gatesopt raises on purpose."""


class GcodeError(GatesoptError, ValueError):
    """Bad G-code input. ``str(err)`` is ``file:line: text: reason`` (line is 1-based)."""

    def __init__(self, source: str, line: int | None, reason: str, text: str | None = None):
        self.source, self.line, self.reason, self.text = source, line, reason, text
        where = f"{source}:{line}" if line is not None else source
        snippet = f" {text.strip()[:60]}:" if text else ""
        super().__init__(f"{where}:{snippet} {reason}")


class InfeasibleError(GatesoptError):
    """A problem has no feasible solution (e.g. the rotated print fits no bed)."""


class ProfileError(GatesoptError, ValueError):
    """A bad or unknown energy profile."""
