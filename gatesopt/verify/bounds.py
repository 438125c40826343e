"""Check ``bounds``: the slicer's own statements of where the print lies on the bed
(``slicers.BOUNDS_FORMATS``: Cura's ``;MINX:`` ... ``;MAXY:``, ideaMaker's ``;Bounding Box:``,
Klipper's ``EXCLUDE_OBJECT_DEFINE`` outlines, PrusaSlicer's ``objects_info``) describe the rotated
print of a rotated output: the box of its extrusions, its objects' outlines turned with it. A
printer's screen, a host's cancel-object map and a bed-fit check read these lines; left as the
slicer wrote them they describe a print that is not there.

The expected lines are recomputed from the original and the rotation the output declares (the
one ``slicers.rotated_bounds`` rule the emitter follows), and compared number by number within
``BOUNDS_TOL_MM`` (the last digit the slicer wrote)."""
from __future__ import annotations

import re

import numpy as np

from .. import slicers
from ..program import Program
from .finding import Finding
from .rotation import rotate_xy

#: numbers of a bounds line may differ by this much (mm) from the recomputed ones (rounding)
BOUNDS_TOL_MM = 2e-3
_NUMBER = re.compile(r"[-+]?\d+(?:\.\d*)?")


def bounds_line_numbers(program: Program) -> list[int]:
    """0-based lines of ``program`` that state the print's bounds."""
    return [line for line, *_ in slicers.bounds_lines(program.data, program.line_start)]


def _same(a: str, b: str) -> bool:
    if a == b:
        return True
    na, nb = _NUMBER.findall(a), _NUMBER.findall(b)
    if len(na) != len(nb) or _NUMBER.sub("#", a) != _NUMBER.sub("#", b):
        return False
    return all(abs(float(x) - float(y)) <= BOUNDS_TOL_MM for x, y in zip(na, nb))


def check_bounds(original: Program, output: Program, deg: float, center, *,
                 max_findings: int = 5) -> list[Finding]:
    """Findings where a bounds line of ``output`` is not the original's rotated by ``deg`` about
    ``center`` (in order, one for one)."""
    ext = np.flatnonzero(original.extruding & (original.layer >= 0))
    pts = np.concatenate((original.start_mm[ext, :2], original.end_mm[ext, :2]))
    expected = slicers.rotated_bounds(original.data, original.line_start,
                                      lambda p: rotate_xy(np.asarray(p, float), deg, center), pts)
    want = bounds_line_numbers(original)
    got = bounds_line_numbers(output)
    out = []
    if len(want) != len(got):
        at = got[0] + 1 if got else None
        return [Finding("bounds", at, f"{len(got)} lines state the print's bounds, the original has {len(want)}")]
    for a, b in zip(want, got):
        exp = expected.get(a, original.line_text(a)).rstrip("\r\n")
        txt = output.line_text(b).rstrip("\r\n")
        if not _same(exp, txt):
            out.append(Finding("bounds", b + 1, f"{txt.strip()[:50]!r} where the rotated print's bounds are "
                                               f"{exp.strip()[:50]!r}"))
            if len(out) >= max_findings:
                break
    return out
