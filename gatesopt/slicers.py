"""What the slicers write about their own output: feature names (and, later, layer markers).

One table, read by every module that needs to know what a slicer meant: the ordering's safe mode
(which features keep their order) and its travel rebuild (which curves are walls a travel must
not cross without retracting). Feature names come from the slicers' comments (``;TYPE:WALL-OUTER``
Cura, ``;TYPE:Perimeter`` PrusaSlicer, ``; FEATURE: Outer wall`` Orca/Bambu, ``; feature inner
perimeter`` KISSlicer/Kiri:Moto), matched case-insensitively anywhere in the name.
"""
from __future__ import annotations

import re

#: feature names whose curves keep the slicer's order in safe mode: walls (their order and seams
#: decide surface quality), ironing, skirt/brim, wipe/prime towers
FIXED_FEATURE_WORDS = ("perimeter", "wall", "ironing", "skirt", "brim", "wipe", "prime", "tower",
                       "shell", "inset", "outline")
#: feature names of walls a travel crosses only with a retraction (the slicers' combing rule)
WALL_FEATURE_WORDS = ("wall", "perimeter", "shell", "skirt", "brim")

FIXED_FEATURE = re.compile("|".join(FIXED_FEATURE_WORDS), re.I)
WALL_FEATURE = re.compile("|".join(WALL_FEATURE_WORDS), re.I)
