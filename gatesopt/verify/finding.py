"""What a check reports: one ``Finding`` per failed check, with the line it is about."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Finding:
    """One failed check. ``line``: 1-based line in the output (``in_original``: in the original)."""

    check: str
    line: int | None
    message: str
    in_original: bool = False

    def __str__(self) -> str:
        where = "" if self.line is None else (f"original line {self.line}: " if self.in_original
                                              else f"line {self.line}: ")
        return f"[{self.check}] {where}{self.message}"
