"""gatesopt: an optimization-centric solver library for 3D-printer G-code.

parse -> Program -> problem -> formulation -> solution -> emit -> verify. See README.md.
"""
import time as _time

#: when this process first imported gatesopt (``cli.clock``: the process itself may have started
#: long before, where a shell ran other commands in it before it exec'd the interpreter)
_IMPORTED_S = _time.perf_counter()

from . import _jit  # noqa: E402,F401  (counts compile time from the first kernel on)
from .errors import GatesoptError, GcodeError
from .parse import parse, parse_text
from .program import AXES, Kind, Program
from . import energy

__all__ = ["parse", "parse_text", "Program", "Kind", "AXES", "energy", "GatesoptError", "GcodeError"]
__version__ = "0.1.0"
