"""The file's end as the last group's end (formulations/ordering.md, "Cost model", "The file's
end"): the emitter copies the steps after the slicer's last curve verbatim, so their first XY
move starts wherever the last curve printed is left. A Cura file parks with ``G1 X0 Y210`` at
the retraction's feed (35 mm/s), KISSlicer lifts back over the last curve's end at 5 mm/s
(``G1 X Y Z E0 F300``): a last layer ordered to end elsewhere pays up to seconds that no link
priced, and the time guard put it back (cube__cura_mk3, plate__cura_ender3, real_kisslicer163,
real_kisslicer206: their last layers, proven groups in them). ``chain.end_of`` gives the file's
last group this end (``problem.FILE_END``); ``cost.TimePricer.group_costs`` prices it with
``FileEnd.ms``.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..program import Kind, Program
from .layout import Layout
from .move_times import MoveTimes, trapezoid_one_s

#: steps after the last curve searched for the first XY move (end G-code is a few dozen lines)
SCAN_STEPS = 400
_XY_WORD = re.compile(r"(?i)(?:^|[\s\d.])[XY]\s*[-+.\d]")
_MOTION = (Kind.TRAVEL, Kind.EXTRUDE, Kind.RETRACT, Kind.UNRETRACT, Kind.Z_ONLY)


@dataclass(frozen=True, eq=False)
class FileEnd:
    """The file's first XY move after its last curve: its absolute target ``xy``, its feed
    ``feed_mm_s`` and its own Z change ``dz_mm``, priced by ``move`` (the file's limits)."""

    xy: np.ndarray
    feed_mm_s: float
    dz_mm: float
    move_vec: np.ndarray

    @staticmethod
    def of(program: Program, lay: Layout, move: MoveTimes) -> "FileEnd | None":
        """The file's end move, or None where none follows the last curve, or a home, a
        relative move or an arc comes first (the head's position then does not carry over)."""
        if not len(lay.curve_s1):
            return None
        a = int(lay.curve_s1[-1])
        for k in range(a, min(len(program.kind), a + SCAN_STEPS)):
            kind = int(program.kind[k])
            if kind == Kind.HOME:
                return None
            if kind not in _MOTION and kind != Kind.ARC:
                continue
            code = program.line_text(int(program.line[k])).split(";", 1)[0]
            if not _XY_WORD.search(code[2:] if len(code) > 2 else ""):
                continue
            if kind == Kind.ARC or bool(program.relative_xyz[k]):
                return None
            return FileEnd(program.end_mm[k, :2].astype(float).copy(), float(program.feed_mm_s[k]),
                           float(program.end_mm[k, 2] - program.start_mm[k, 2]), move.vector())
        return None

    def ms(self, xy) -> np.ndarray:
        """Per point of ``xy`` ((m, 2)), the time (ms) of the end move from there: one move at its
        own feed, from and to the XY junction speed (the moves before it, an E-only retraction
        and a Z lift, are alike for every point), as a rebuilt travel's moves are priced alone
        (``link_cost.rebuilt_s``)."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        mt = self.move_vec
        v = min(self.feed_mm_s, mt[1]) if self.feed_mm_s > 0 else mt[1]
        dist = np.hypot(np.hypot(*(xy - self.xy).T), self.dz_mm)
        return np.array([trapezoid_one_s(d, v, mt[0], mt[2]) * 1000.0 for d in dist.tolist()])
