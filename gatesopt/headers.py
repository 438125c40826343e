"""The comment lines gatesopt writes at the top of a rewritten file, in one place.

Emitters write them (``gatesopt.gating.emit``: the rotation; ``gatesopt.ordering.emit``: the
re-ordering) and the verifier reads them (``gatesopt.verify``): both sides import these
constants, so a header cannot be written one way and read another.
"""
from __future__ import annotations

#: every gatesopt header line starts with this
PREFIX = "; gatesopt:"

#: the rotation a gating rewrite applied to the print, about a centre (``gating.emit.render``)
ROTATE_HEADER = "; gatesopt: rotate_deg={deg} center_x={cx} center_y={cy}"
#: how a reader finds a rotation line (``verify.read_rotation``)
ROTATE_PREFIX = "; gatesopt: rotate_deg="

#: the first line of a re-ordered file (``ordering.emit``): tells ``gatesopt verify ORIG OUT`` to
#: check it as a re-ordering, even where no curve visibly moved
ORDER_HEADER = "; gatesopt: order"
ORDER_PREFIX = ORDER_HEADER

#: headers are looked for in this many first lines of a file (each rewrite puts its own on top of
#: the text it read, which may hold an earlier one's)
HEADER_LINES = 50
