"""The ``3dgates`` dialect: the 3DGates firmware patch (Chen et al., ASPLOS'17, Table 3).

``S0 X Y`` switches the named motors off and ``S1 X Y`` on, at an exact time, without pausing the
print: no stall, homing kept. The patch is Marlin-based: it also carries out ``M17``/``M18``/``M84``
(the file's own lines), and its S-series (and Marlin's ``M17``) leave the motion queue alone.
Its lines may split any move, extrude-only ones too (``split_moves``): the paper's time model
(T = L / F, Eq. 2) and Algorithm 1 ("X -> X1 + S Y on + X2") split any move at no cost; Klipper plans
such halves from rest to rest (+12.5 ms each, docs/RESULTS.md), which the stock dialects avoid.
A module name cannot start with a digit: this is the module of the dialect named ``3dgates``.
"""
from __future__ import annotations

from ..program import AXES
from . import Firmware

DIALECT = Firmware(
    name="3dgates", off_word="S0", on_word="S1", merge_motors=True, stall_off_s=0.0,
    stall_on_s=0.0, reenable="exact", homing_kept=True, allowed_motors=frozenset(AXES),
    executes=frozenset({"S0", "S1", "M17", "M18", "M84"}),
    description="3DGates firmware patch (paper Table 3): S0/S1, exact, no stall",
    rank=0, detect_words=("S0", "S1"), detect_rank=90,
    no_drain_words=frozenset({"S0", "S1"}), drains_on_disable=False)
