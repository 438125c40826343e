"""gatesopt: an optimization-centric solver library for 3D-printer G-code.

parse -> Program -> problem -> formulation -> solution -> emit -> verify. See README.md.
"""
from . import _jit  # noqa: F401  (counts compile time from the first kernel on; imported first)
from .errors import GatesoptError, GcodeError
from .parse import parse, parse_text
from .program import AXES, Kind, Program
from . import energy

__all__ = ["parse", "parse_text", "Program", "Kind", "AXES", "energy", "GatesoptError", "GcodeError"]
__version__ = "0.1.0"
