"""What the slicers write about their own output: layer markers, Z comments and feature names.

One table per kind of knowledge, read by every module that needs to know what a slicer meant:

- ``LAYER_MARKERS``, ``Z_MARKERS``, ``FEATURE_MARKERS``: the comments the parser's scanner looks
  for (``gatesopt._scan`` reads them as arrays, packed by ``_scan.pack_comment_markers``; the
  layer markers written after G-code on the same line are found by ``parse``). Adding a slicer's
  layer marker is one ``LayerMarker`` row here, with an example line (``tests/test_slicers.py``
  parses every row's example and checks the layers it finds).
- ``FIXED_FEATURE_WORDS``, ``WALL_FEATURE_WORDS``: feature names the ordering's safe mode keeps in
  place and its travel rebuild treats as walls. Feature names come from the slicers' comments
  (``;TYPE:WALL-OUTER`` Cura, ``;TYPE:Perimeter`` PrusaSlicer, ``; FEATURE: Outer wall``
  Orca/Bambu, ``; feature inner perimeter`` KISSlicer/Kiri:Moto), matched case-insensitively
  anywhere in the name.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

#: where a ``LayerMarker`` is written: a comment line of its own, or a comment after the G-code
#: of a line (Slic3r's ``G1 Z0.350 F7800.000 ; move to next layer (0)``)
COMMENT_LINE = "comment line"
TRAILING = "trailing"
#: what must follow a layer marker's text: nothing, a digit, or a digit or a minus sign
FOLLOW = ("", "digit", "signed")


@dataclass(frozen=True)
class LayerMarker:
    """A comment a slicer writes where a new layer starts.

    ``text`` starting with ``;`` is matched at the comment's ``;`` exactly; any other text after
    the ``;`` and the blanks behind it (so ``LAYER`` finds ``;LAYER 3`` and ``; layer 3``).
    ``sep``: one of these bytes must follow the text, then spaces are skipped. ``follow``: what
    must come next (``FOLLOW``). ``z_after``: the layer's Z is the number after this text, further
    on the same line. ``fold_case``: the text matches in any case (give it in upper case).
    ``where``: ``COMMENT_LINE`` (read by the scanner) or ``TRAILING`` (a comment after G-code on
    the line: the text is found anywhere after the line's first non-blank byte, by ``parse``).
    ``example``: a line the slicer writes, for the table's test.
    """

    slicer: str                 # the layer method's name: ``Program.layer_method == "marker:<slicer>"``
    text: bytes
    example: str
    follow: str = ""
    sep: bytes = b""
    z_after: bytes = b""
    fold_case: bool = False
    where: str = COMMENT_LINE

    def __post_init__(self):
        if self.follow not in FOLLOW:
            raise ValueError(f"LayerMarker {self.text!r}: follow must be one of {FOLLOW}, not {self.follow!r}")
        if self.where not in (COMMENT_LINE, TRAILING):
            raise ValueError(f"LayerMarker {self.text!r}: where must be {COMMENT_LINE!r} or {TRAILING!r}")
        if self.fold_case and self.text != self.text.upper():
            raise ValueError(f"LayerMarker {self.text!r}: a fold_case text is given in upper case")
        if self.where == TRAILING and (self.follow or self.sep or self.z_after or self.fold_case):
            raise ValueError(f"LayerMarker {self.text!r}: a trailing marker is its text alone")


#: Layer markers in priority order. On one line the first row that matches is the line's marker;
#: in a file, layers come from the first slicer (in this order) that wrote any of its markers
#: (PrusaSlicer's ``;LAYER_CHANGE`` wins over the generic ``; layer 3`` its custom G-code may
#: carry). A file with none gets layers from its Z changes (``parse``).
LAYER_MARKERS = (
    LayerMarker("prusaslicer", b";LAYER_CHANGE", ";LAYER_CHANGE"),    # PrusaSlicer, SuperSlicer, Orca
    LayerMarker("bambu", b"; CHANGE_LAYER", "; CHANGE_LAYER"),        # Bambu Studio
    LayerMarker("cura", b";LAYER:", ";LAYER:3", follow="signed"),     # Cura, ideaMaker (';LAYER:-2': raft)
    LayerMarker("simplify3d", b"; layer ", "; layer 3, Z = 0.6", follow="digit", z_after=b", Z = "),
    LayerMarker("slic3r", b"; move to next layer (", "; move to next layer (3)"),   # Slic3r 1.x verbose
    # the same on the layer change move itself; without it Slic3r's start G-code purge line became
    # "layer 0" of the print
    LayerMarker("slic3r", b"; move to next layer (", "G1 Z0.350 F7800.000 ; move to next layer (0)",
                where=TRAILING),
    LayerMarker("kisslicer", b"; BEGIN_LAYER_OBJECT", "; BEGIN_LAYER_OBJECT z=0.3", z_after=b" z="),
    # any other ';layer 3', '; LAYER_3', ';Layer: 3' (Kiri:Moto, IceSL, hand-written files)
    LayerMarker("comment", b"LAYER", "; Layer: 3", follow="digit", sep=b" _:", fold_case=True),
)
#: the slicers' names in priority order (``parse`` tries them in this order)
LAYER_KINDS = tuple(dict.fromkeys(m.slicer for m in LAYER_MARKERS))

#: comments that give the Z of the layer they are in (``;Z:0.2`` PrusaSlicer, ``; Z_HEIGHT: 0.2``
#: Bambu/Orca), matched after the ``;`` and its blanks, the number after them; the first Z comment
#: after a layer marker is its layer's Z
Z_MARKERS = (b"Z:", b"Z_HEIGHT:")
#: comments that name the feature printed from there on (``;TYPE:Perimeter``, ``; FEATURE: Outer
#: wall``, ``; feature inner perimeter``), matched after the ``;`` and its blanks; the name is the
#: rest of the line, blanks trimmed
FEATURE_MARKERS = (b"TYPE:", b"FEATURE:", b"feature ")

#: feature names whose curves keep the slicer's order in safe mode: walls (their order and seams
#: decide surface quality), ironing, skirt/brim, wipe/prime towers
FIXED_FEATURE_WORDS = ("perimeter", "wall", "ironing", "skirt", "brim", "wipe", "prime", "tower",
                       "shell", "inset", "outline")
#: feature names of walls a travel crosses only with a retraction (the slicers' combing rule)
WALL_FEATURE_WORDS = ("wall", "perimeter", "shell", "skirt", "brim")

FIXED_FEATURE = re.compile("|".join(FIXED_FEATURE_WORDS), re.I)
WALL_FEATURE = re.compile("|".join(WALL_FEATURE_WORDS), re.I)
