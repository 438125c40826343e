"""The whole job: re-order curves, gate motors, rotate, emit, verify, in one library call.

    from gatesopt import parse
    from gatesopt.rewrite import run
    result = run(parse("part.gcode"))       # the defaults that fit the file's printer
    print(result.summary()["firmware_line"])
    if result.report.ok:
        open("part.gated.gcode", "w").write(result.text)

``run`` (``rewrite.pipeline``) is what ``gatesopt solve`` does; ``choose`` (``rewrite.printer``)
picks what ``solve`` picks for a file (its firmware's dialect, the stock-firmware time budget) and
says why; ``order_program``
(``rewrite.order``) is the curve ordering's own whole job, what ``gatesopt order`` does. This layer
sits above the two problem families (``gatesopt.gating``, ``gatesopt.ordering``) and the
verification (``gatesopt.verify``), which never import it.
"""
from .order import OrderResult, order_program, order_summary, reorder
from .pipeline import energy_time, run
from .result import RunResult
from .printer import FirmwareChoice, choose

__all__ = ["run", "RunResult", "energy_time", "choose", "FirmwareChoice", "order_program", "OrderResult",
           "order_summary", "reorder"]
