"""What the slicers write about their own output: layer markers, Z comments and feature names.

One table per kind of knowledge, read by every module that needs to know what a slicer meant:

- ``LAYER_MARKERS``, ``Z_MARKERS``, ``FEATURE_MARKERS``: the comments the parser's scanner looks
  for (``gatesopt._scan`` reads them as arrays, packed by ``_scan_tables.pack_comment_markers``; the
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
import weakref
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

#: feature names of passes over what their layer printed before them (ironing smooths the top
#: surface already printed): they keep their place in either order mode, free mode included
PASS_OVER_FEATURE_WORDS = ("ironing", "iron")

FIXED_FEATURE = re.compile("|".join(FIXED_FEATURE_WORDS), re.I)
PASS_OVER_FEATURE = re.compile("|".join(PASS_OVER_FEATURE_WORDS), re.I)
WALL_FEATURE = re.compile("|".join(WALL_FEATURE_WORDS), re.I)



# ------------------------------------------------------------------------------------------------
# Object labels: the lines that say which object the moves after them belong to, so that a
# firmware can cancel one object of a plate (Marlin/Prusa ``M486``, Klipper ``EXCLUDE_OBJECT``)
# or a post-processor can (PrusaSlicer's comments, Cura's ``;MESH:``, which cancel-object
# preprocessors turn into M486). The ordering's safe mode moves a labelled object's moves of a
# layer as one block with its labels (``ordering/blocks.py``); verify checks that every extruded
# move stays inside its own object's labels (``verify/ordering.check_objects``).

#: what a label line does: opens an object's region, closes it, opens the moves that belong to
#: no object (Cura's ``;MESH:NONMESH``), or anything else about objects (the definitions
#: ``M486 T4``, ``EXCLUDE_OBJECT_DEFINE``, cancels ``M486 P2``): those stay barriers
LABEL_OPEN, LABEL_CLOSE, LABEL_OUTSIDE, LABEL_OTHER = "open", "close", "outside", "other"


@dataclass(frozen=True)
class ObjectLabel:
    """A kind of object label line: ``pattern`` matched (case-insensitively) against the line's
    text stripped of blanks; group ``name``, where present, names the object. ``family``: labels
    of one family open and close one object at a time (a file may carry two families, PrusaSlicer
    writing its comments and M486). ``word``: lower-case bytes every such line contains (found by
    ``bytes.find``: a case-insensitive regex over a 6 MB file took 0.27 s, this 0.02 s).
    ``example``: a line the slicer writes (``tests/test_slicers.py`` reads every row's)."""

    family: str
    kind: str
    word: bytes
    pattern: str
    example: str


#: object labels, the first matching row decides (the close rows before the open rows that their
#: text contains: ``; stop printing object`` holds ``printing object``)
OBJECT_LABELS = (
    # SuperSlicer 2.3 writes each label twice: '; INIT ...' before the retraction and lift, the
    # plain one after them, before the travel (a family of its own: both nest)
    ObjectLabel("comment-init", LABEL_CLOSE, b"printing object",
                r";\s*INIT stop printing object\s*(?P<name>.*)", "; INIT stop printing object cube_1 id:0 copy 0"),
    ObjectLabel("comment-init", LABEL_OPEN, b"printing object",
                r";\s*INIT printing object\s*(?P<name>.*)", "; INIT printing object cube_1 id:0 copy 0"),
    # PrusaSlicer, SuperSlicer, OrcaSlicer: around each object's moves of a layer
    ObjectLabel("comment", LABEL_CLOSE, b"printing object", r";\s*stop printing object\s*(?P<name>.*)",
                "; stop printing object cube_1 id:0 copy 0"),
    ObjectLabel("comment", LABEL_OPEN, b"printing object", r";\s*printing object\s*(?P<name>.*)",
                "; printing object cube_1 id:0 copy 0"),
    # Marlin / Prusa firmware M486 (PrusaSlicer with "label objects", post-processors): S<id>
    # starts object id, S-1 ends it; T (count), P/U (cancel, uncancel), C (cancel current) and a
    # bare A (name) are something else
    ObjectLabel("m486", LABEL_CLOSE, b"m486", r"M486\s+S\s*-1(\s*;.*)?", "M486 S-1"),
    ObjectLabel("m486", LABEL_OPEN, b"m486", r"M486\s+S\s*(?P<name>\d+)(\s+A\s*\S.*?)?(\s*;.*)?",
                "M486 S2"),
    ObjectLabel("m486", LABEL_OTHER, b"m486", r"M486\b.*", "M486 T4"),
    # Klipper's exclude_object (OrcaSlicer, SuperSlicer, PrusaSlicer >= 2.6 for Klipper)
    ObjectLabel("klipper", LABEL_OPEN, b"exclude_object", r"EXCLUDE_OBJECT_START\s+NAME\s*=\s*(?P<name>\S+).*",
                "EXCLUDE_OBJECT_START NAME=cube_1_id_0_copy_0"),
    ObjectLabel("klipper", LABEL_CLOSE, b"exclude_object", r"EXCLUDE_OBJECT_END\b.*",
                "EXCLUDE_OBJECT_END NAME=cube_1_id_0_copy_0"),
    ObjectLabel("klipper", LABEL_OTHER, b"exclude_object", r".*EXCLUDE_OBJECT.*",
                "EXCLUDE_OBJECT_DEFINE NAME=cube_1_id_0_copy_0 CENTER=125,105"),
    # CuraEngine: ';MESH:<name>' where a mesh's moves begin, ';MESH:NONMESH' where moves of no
    # mesh begin (the travel to the next layer, skirt, support); no end marker: a region ends
    # at the next ';MESH:'
    ObjectLabel("mesh", LABEL_OUTSIDE, b";mesh:", r";MESH:NONMESH\s*", ";MESH:NONMESH"),
    ObjectLabel("mesh", LABEL_OPEN, b";mesh:", r";MESH:(?P<name>.+)", ";MESH:cube_1.stl"),
)
#: every word some label line contains (``OBJECT_LABELS``)
OBJECT_LABEL_WORDS = tuple(dict.fromkeys(row.word for row in OBJECT_LABELS))
_LABEL_RX = tuple(re.compile(row.pattern, re.I) for row in OBJECT_LABELS)


def object_label(text: str) -> tuple[ObjectLabel, str] | None:
    """(row, object name) of the label line ``text`` (``OBJECT_LABELS``; name "" where the row
    names none), or None if it is no label line of the table."""
    t = text.strip()
    low = t.lower().encode("utf-8", "replace")
    for row, rx in zip(OBJECT_LABELS, _LABEL_RX):
        if row.word in low:
            m = rx.fullmatch(t)
            if m:
                name = m.groupdict().get("name") or ""
                return row, name.strip()
    return None

# ------------------------------------------------------------------------------------------------
# The printer a file was sliced for: the firmware it runs and its bed.
#
# ``read_printer(data)`` reads them from the file's own text with the line each came from, so
# that what gatesopt chose for a file can be said in one line ("marlin: read ';FLAVOR:Marlin' at
# line 1"). Three kinds of evidence, strongest first:
#
# 1. a Klipper command on a line of its own (``KLIPPER_COMMAND``): the firmware must run it, and
#    only Klipper has extended commands of that form (``START_PRINT``, ``EXCLUDE_OBJECT_DEFINE``,
#    ``SET_VELOCITY_LIMIT``, a Voron profile's ``print_start``); Marlin and RepRapFirmware answer
#    "unknown command" to them;
# 2. a printer model that ships with one firmware (``PRINTER_MODELS``: a Voron, a Creality K1 run
#    Klipper);
# 3. the slicer's firmware setting (``FLAVOR_SETTINGS``). Klipper's own docs (docs/Slicers.md,
#    "Set the G-Code flavor to Marlin") tell users to slice for Marlin, so a Marlin flavour does
#    not rule Klipper out: evidence 1 and 2 win over it.

#: firmware families a file can name; "other" is a firmware gatesopt has no dialect for
#: (Repetier, Smoothieware, Makerbot/Sailfish, Mach3, Ultimaker's Griffin), "" says nothing
FAMILIES = ("marlin", "klipper", "reprapfirmware", "bambu", "other")


@dataclass(frozen=True)
class FlavorSetting:
    """A slicer setting that names the firmware its G-code is written for: ``pattern`` (a regex
    over the file's bytes, group 1 the value) and ``values``: (regex matched against the whole
    value, case-insensitively, family, why) rows, the first that matches decides. ``example``: a
    line the slicer writes (``tests/test_slicers.py`` reads every row's example)."""

    slicer: str
    pattern: bytes
    values: tuple
    example: str


FLAVOR_SETTINGS = (
    # CuraEngine writes its machine_gcode_flavor as ';FLAVOR:<name>' on the first line:
    # "RepRap (Marlin/Sprinter)" -> Marlin, "RepRap (Volumetric)" -> Marlin(Volumetric),
    # "RepRap (RepRap)" -> RepRap (the Duet/RepRapFirmware choice), UltiGCode, Griffin, ...
    FlavorSetting("cura", rb"(?m)^;FLAVOR:[ \t]*([^\r\n]*)", (
        (r"marlin.*", "marlin", "Cura's Marlin flavour"),
        (r"reprap", "reprapfirmware", "Cura's RepRap (RepRap) flavour, RepRapFirmware's"),
        (r".*", "other", "a flavour without a gatesopt dialect")), ";FLAVOR:Marlin"),
    # PrusaSlicer, SuperSlicer, Slic3r, OrcaSlicer, Bambu Studio: '; gcode_flavor = marlin2'.
    # 'reprap' is Slic3r's "RepRap (Marlin/Sprinter)" (PrusaSlicer: "RepRap/Sprinter"), the
    # Marlin-compatible default; RepRapFirmware is 'reprapfirmware'
    FlavorSetting("prusaslicer", rb"(?m)^;[ \t]*gcode_flavor[ \t]*=[ \t]*([^\r\n]*)", (
        (r"marlin2?", "marlin", "Marlin"),
        (r"klipper", "klipper", "Klipper"),
        (r"reprapfirmware", "reprapfirmware", "RepRapFirmware"),
        (r"reprap", "marlin", "RepRap/Sprinter, the Marlin-compatible flavour"),
        (r".*", "other", "a flavour without a gatesopt dialect")), "; gcode_flavor = marlin2"),
    # ideaMaker's printer setting: ';Firmware: RepRapFirmware'
    FlavorSetting("ideamaker", rb"(?m)^;Firmware:[ \t]*([^\r\n]*)", (
        (r".*reprap.*|.*duet.*", "reprapfirmware", "RepRapFirmware"),
        (r".*klipper.*", "klipper", "Klipper"),
        (r".*marlin.*", "marlin", "Marlin"),
        (r".*", "other", "a firmware without a gatesopt dialect")), ";Firmware: RepRapFirmware"),
    # Simplify3D's process settings block: ';   firmwareTypeOverride,RepRap (Marlin/Repetier/Sprinter)'
    FlavorSetting("simplify3d", rb"(?m)^;[ \t]*firmwareTypeOverride,([^\r\n]*)", (
        (r".*(reprapfirmware|duet).*", "reprapfirmware", "RepRapFirmware"),
        (r".*klipper.*", "klipper", "Klipper"),
        (r".*marlin.*", "marlin", "Marlin-compatible"),
        (r".*", "other", "a firmware without a gatesopt dialect")),
        ";   firmwareTypeOverride,RepRap (Marlin/Repetier/Sprinter)"),
    # KISSlicer's firmware_type is the extrusion style (BFB, 5D relative E, 5D absolute E, ...):
    # it names no firmware
    FlavorSetting("kisslicer", rb"(?m)^;[ \t]*firmware_type[ \t]*=[ \t]*([^\r\n]*)", (
        (r".*", "", "KISSlicer's extrusion style, not a firmware"),), "; firmware_type = 1"),
)


@dataclass(frozen=True)
class PrinterModel:
    """Printers that ship with one firmware: ``pattern`` matched (case-insensitively, anywhere)
    in the printer model a slicer names (``PRINTER_MODEL_SETTINGS``)."""

    pattern: str
    family: str
    why: str


#: where slicers name the printer: PrusaSlicer/Orca ``; printer_model = ``, Cura 5
#: ``;TARGET_MACHINE.NAME:``, Kiri:Moto ``; Target: ``, ideaMaker ``;Printer Type: ``
PRINTER_MODEL_SETTINGS = (rb"(?m)^;[ \t]*printer_model[ \t]*=[ \t]*([^\r\n]*)",
                          rb"(?m)^;TARGET_MACHINE\.NAME:[ \t]*([^\r\n]*)",
                          rb"(?m)^;[ \t]*Target:[ \t]*([^\r\n]*)",
                          rb"(?m)^;Printer Type:[ \t]*([^\r\n]*)")
PRINTER_MODELS = (
    PrinterModel(r"voron", "klipper", "Voron printers run Klipper"),
    PrinterModel(r"\bk1\b|k1 ?max|\bk1c\b|cr-k1|\bk2 ?(plus|pro)\b", "klipper",
                 "Creality K1/K2 printers run Klipper"),
    PrinterModel(r"rat ?rig|v-core", "klipper", "RatRig printers run Klipper (RatOS)"),
    PrinterModel(r"sovol sv0?[78]\b", "klipper", "Sovol SV07/SV08 printers run Klipper"),
    PrinterModel(r"neptune ?4", "klipper", "Elegoo Neptune 4 printers run Klipper"),
    PrinterModel(r"qidi|x-(plus|max|smart) ?3|\bq1 ?pro\b", "klipper", "QIDI printers run Klipper"),
    PrinterModel(r"bambu", "bambu", "Bambu Lab firmware"),
)

#: a Klipper extended command on a line of its own: a name with an underscore, any case
#: (klippy/gcode.py reads extended commands case-insensitively), e.g. ``START_PRINT``,
#: ``EXCLUDE_OBJECT_DEFINE NAME=..``, ``print_start`` (Voron profiles). A command word of Marlin,
#: RepRapFirmware or the S-series is a letter and a number (``G1``, ``M486``, ``S0``); their
#: meta commands (``if``, ``var``, ``M98 P"..."``) carry no underscore in the first word.
KLIPPER_COMMAND = re.compile(rb"(?im)^[ \t]*(?:N\d+[ \t]+)?([a-z][a-z0-9]*_[a-z0-9_]*)(?=[ \t;\r\n]|$)")


@dataclass(frozen=True)
class Evidence:
    """One thing the file says about its printer's firmware."""

    family: str         # one of FAMILIES, or "" when the setting names no firmware
    kind: str           # "Klipper command" | "printer model" | "flavor setting"
    line: int           # 1-based line of the file
    text: str           # the line as written (stripped, at most 80 characters)
    why: str            # what it means, e.g. "Cura's Marlin flavour"
    value: str = ""     # the setting's value (a flavor setting: "marlin2", "Marlin", ...)

    def where(self) -> str:
        return f"'{self.text}' (line {self.line})"


@dataclass(frozen=True)
class Bed:
    """The printable area of the bed: a convex polygon in machine XY (mm), and where it was read."""

    polygon_mm: tuple           # ((x, y), ...)
    source: str                 # "bed_shape", "printable_area", "--bed", ...
    line: int = 0               # 1-based line of the file (0: not read from the file)
    text: str = ""

    @property
    def size_mm(self) -> tuple[float, float]:
        xs = [p[0] for p in self.polygon_mm]
        ys = [p[1] for p in self.polygon_mm]
        return max(xs) - min(xs), max(ys) - min(ys)

    def describe(self) -> str:
        """e.g. "250 x 210 mm bed (bed_shape, line 24627)"."""
        w, d = self.size_mm
        where = f"{self.source}, line {self.line}" if self.line else self.source
        shape = "" if len(self.polygon_mm) == 4 else f"{len(self.polygon_mm)}-gon "
        return f"{w:g} x {d:g} mm {shape}bed ({where})"


def rectangle_bed(x0: float, y0: float, x1: float, y1: float, source: str, line: int = 0,
                  text: str = "") -> Bed:
    return Bed(((x0, y0), (x1, y0), (x1, y1), (x0, y1)), source, line, text)


@dataclass(frozen=True)
class PrinterFacts:
    """What the file says about its printer (``read_printer``)."""

    firmware: Evidence | None       # the deciding evidence (None: the file names no firmware)
    evidence: tuple                 # every Evidence found, strongest first
    flavor: str                     # the flavor setting's value as written ("" if none)
    bed: Bed | None


HEAD_BYTES = 100_000    # slicers write their settings in the first and last ~100 kB


def _ends(data: bytes) -> list[tuple[int, bytes]]:
    """(offset, bytes) of the part of ``data`` the settings are in: its head and tail."""
    if len(data) <= 2 * HEAD_BYTES:
        return [(0, data)]
    return [(0, data[:HEAD_BYTES]), (len(data) - HEAD_BYTES, data[-HEAD_BYTES:])]


def _search(pattern, data: bytes):
    """(1-based line, whole line text, group 1) of the first match of ``pattern`` in the head or
    tail of ``data``, or None."""
    pat = re.compile(pattern) if isinstance(pattern, bytes) else pattern
    for off, part in _ends(data):
        m = pat.search(part)
        if m:
            start = off + m.start()
            line_start = data.rfind(b"\n", 0, start) + 1
            line_end = data.find(b"\n", start)
            text = data[line_start:line_end if line_end >= 0 else len(data)]
            return (data.count(b"\n", 0, start) + 1, text.decode("utf-8", "replace").strip()[:80],
                    m.group(1).decode("utf-8", "replace").strip())
    return None


def flavor_evidence(data: bytes) -> Evidence | None:
    """The first slicer firmware setting in ``data`` (``FLAVOR_SETTINGS``), as Evidence."""
    for row in FLAVOR_SETTINGS:
        hit = _search(row.pattern, data)
        if hit is None:
            continue
        line, text, value = hit
        for rx, family, why in row.values:
            if re.fullmatch(rx, value, re.I):
                return Evidence(family, "flavor setting", line, text, why, value)
    return None


def printer_models(data: bytes):
    """(line, text, value) of each printer model the slicer names (``PRINTER_MODEL_SETTINGS``,
    in that order; an empty value skipped)."""
    for pattern in PRINTER_MODEL_SETTINGS:
        hit = _search(pattern, data)
        if hit is not None and hit[2]:
            yield hit


def model_evidence(data: bytes) -> Evidence | None:
    """The printer model the slicer names, where ``PRINTER_MODELS`` knows its firmware."""
    for line, text, value in printer_models(data):
        for row in PRINTER_MODELS:
            if re.search(row.pattern, value, re.I):
                return Evidence(row.family, "printer model", line, text, row.why, value)
    return None


def klipper_evidence(data: bytes) -> Evidence | None:
    """The first Klipper extended command of the file (``KLIPPER_COMMAND``), anywhere in it."""
    m = KLIPPER_COMMAND.search(data)
    if m is None:
        return None
    start = m.start(1)
    line_end = data.find(b"\n", start)
    text = data[start:line_end if line_end >= 0 else len(data)].decode("utf-8", "replace").strip()[:80]
    return Evidence("klipper", "Klipper command", data.count(b"\n", 0, start) + 1, text,
                    "a Klipper command")


def read_printer(data: bytes) -> PrinterFacts:
    """The firmware and bed ``data`` (a G-code file's bytes) was sliced for, with the lines they
    were read from. The firmware: a Klipper command in the file, else a printer model known to
    run one firmware, else the slicer's flavor setting (see the top of this section)."""
    flavor = flavor_evidence(data)
    found = [e for e in (klipper_evidence(data), model_evidence(data), flavor) if e is not None]
    deciding = next((e for e in found if e.family), None)
    return PrinterFacts(deciding, tuple(found), flavor.value if flavor else "", read_bed(data))


_FACTS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def same_printer(copy, program) -> None:
    """``copy``, parsed from a re-ordered copy of ``program``'s text (every line naming the printer
    kept), has ``program``'s printer facts, not read again (~0.1 s a read on 200,000 lines)."""
    _FACTS[copy] = program_printer(program)


def program_printer(program) -> PrinterFacts:
    """``read_printer`` of a parsed ``Program``'s bytes, read once per program (a Program is never
    mutated; the Klipper-command search reads the whole file, ~0.13 s on a 1.4 MB file, and every
    planner call asks: ``limits.default_family``, ``rewrite.printer.choose``; a copy: its original's)."""
    facts = _FACTS.get(program)
    if facts is None:
        facts = _FACTS[program] = read_printer(bytes(program.data))
    return facts


# -- the bed ---------------------------------------------------------------------------------------
def _polygon_bed(data: bytes) -> Bed | None:
    # PrusaSlicer/SuperSlicer/Slic3r '; bed_shape = 0x0,250x0,250x210,0x210'; Orca/Bambu
    # '; printable_area = 0x0,300x0,300x300,0x300' (the same points, a circle as many)
    for name in (b"bed_shape", b"printable_area"):
        hit = _search(rb"(?m)^;[ \t]*" + name + rb"[ \t]*=[ \t]*([-\d.eE]+x[-\d.eE]+(?:,[-\d.eE]+x[-\d.eE]+)+)", data)
        if hit:
            try:
                pts = tuple(tuple(float(v) for v in p.split("x")) for p in hit[2].split(","))
            except ValueError:
                continue
            if len(pts) >= 3:
                return Bed(pts, name.decode(), hit[0], hit[1])
    return None


def _number(data: bytes, pattern: bytes):
    hit = _search(pattern, data)
    if hit is None:
        return None
    try:
        return float(hit[2].split()[0]), hit
    except (ValueError, IndexError):
        return None


def _sized_bed(data: bytes) -> Bed | None:
    # KISSlicer '; bed_size_x_mm = 100' with '; bed_offset_x_mm = 50' (the bed centre's
    # coordinate); IceSL '; bed_size_x_mm : 120' (from 0)
    w = _number(data, rb"(?m)^;[ \t]*bed_size_x_mm[ \t]*[=:][ \t]*([-\d.]+)")
    d = _number(data, rb"(?m)^;[ \t]*bed_size_y_mm[ \t]*[=:][ \t]*([-\d.]+)")
    if not (w and d) or min(w[0], d[0]) <= 0:
        return None
    ox = _number(data, rb"(?m)^;[ \t]*bed_offset_x_mm[ \t]*=[ \t]*([-\d.]+)")
    oy = _number(data, rb"(?m)^;[ \t]*bed_offset_y_mm[ \t]*=[ \t]*([-\d.]+)")
    cx = ox[0] if ox else w[0] / 2
    cy = oy[0] if oy else d[0] / 2
    return rectangle_bed(cx - w[0] / 2, cy - d[0] / 2, cx + w[0] / 2, cy + d[0] / 2, "bed_size_x_mm",
                         w[1][0], w[1][1])


def _ideamaker_bed(data: bytes) -> Bed | None:
    # ideaMaker ';Dimension: 300.000 300.000 300.000 0.400 0.400' (W D H), ';Origin Center: 0',
    # ';Plate Shape: 0' (0: rectangle; else round: the inscribed 64-gon, inside the circle)
    hit = _search(rb"(?m)^;Dimension:[ \t]*([^\r\n]*)", data)
    if hit is None:
        return None
    try:
        w, d = (float(v) for v in hit[2].split()[:2])
    except ValueError:
        return None
    centred = _number(data, rb"(?m)^;Origin Center:[ \t]*(\d+)")
    shape = _number(data, rb"(?m)^;Plate Shape:[ \t]*(\d+)")
    cx, cy = (0.0, 0.0) if centred and centred[0] else (w / 2, d / 2)
    if shape and shape[0]:
        import math
        pts = tuple((cx + w / 2 * math.cos(2 * math.pi * k / 64), cy + d / 2 * math.sin(2 * math.pi * k / 64))
                    for k in range(64))
        return Bed(pts, "Dimension", hit[0], hit[1])
    return rectangle_bed(cx - w / 2, cy - d / 2, cx + w / 2, cy + d / 2, "Dimension", hit[0], hit[1])


def _kirimoto_bed(data: bytes) -> Bed | None:
    # Kiri:Moto '; Bed left:0 right:300 top:300 bottom:0'
    hit = _search(rb"(?m)^;[ \t]*Bed (left:[-\d.]+ right:[-\d.]+ top:[-\d.]+ bottom:[-\d.]+)", data)
    if hit is None:
        return None
    kv = dict(w.split(":") for w in hit[2].split())
    try:
        x0, x1, y1, y0 = (float(kv[k]) for k in ("left", "right", "top", "bottom"))
    except (KeyError, ValueError):
        return None
    if x1 <= x0 or y1 <= y0:
        return None
    return rectangle_bed(x0, y0, x1, y1, "Bed", hit[0], hit[1])


def _simplify3d_bed(data: bytes) -> Bed | None:
    # Simplify3D ';   strokeXoverride,200' (the axis travel) and ';   originOffsetXoverride,0'
    # (where the G-code's 0 lies on it)
    w = _number(data, rb"(?m)^;[ \t]*strokeXoverride,([-\d.]+)")
    d = _number(data, rb"(?m)^;[ \t]*strokeYoverride,([-\d.]+)")
    if not (w and d) or min(w[0], d[0]) <= 0:
        return None
    ox = _number(data, rb"(?m)^;[ \t]*originOffsetXoverride,([-\d.]+)")
    oy = _number(data, rb"(?m)^;[ \t]*originOffsetYoverride,([-\d.]+)")
    x0, y0 = -(ox[0] if ox else 0.0), -(oy[0] if oy else 0.0)
    return rectangle_bed(x0, y0, x0 + w[0], y0 + d[0], "strokeXoverride", w[1][0], w[1][1])


#: readers of the bed each slicer writes, tried in order (Cura writes no bed: ``--bed WxD``)
BED_READERS = (_polygon_bed, _sized_bed, _ideamaker_bed, _kirimoto_bed, _simplify3d_bed)
#: an example of each reader's lines, for ``tests/test_slicers.py``
BED_EXAMPLES = (
    ("; bed_shape = 5x0,215x0,215x220,5x220", (5, 0, 215, 220)),
    ("; printable_area = 0x0,300x0,300x300,0x300", (0, 0, 300, 300)),
    ("; bed_size_x_mm = 180\n; bed_size_y_mm = 190\n; bed_offset_x_mm = 90\n; bed_offset_y_mm = 95",
     (0, 0, 180, 190)),
    ("; bed_size_x_mm : \t120\n; bed_size_y_mm : \t120", (0, 0, 120, 120)),
    (";Dimension: 205.000 205.000 205.000 0.400\n;Plate Shape: 0\n;Origin Center: 0", (0, 0, 205, 205)),
    ("; Bed left:0 right:300 top:300 bottom:0", (0, 0, 300, 300)),
    (";   strokeXoverride,230\n;   strokeYoverride,220\n;   originOffsetXoverride,0", (0, 0, 230, 220)),
)


def read_bed(data: bytes) -> Bed | None:
    """The bed the file names (``BED_READERS``), or None (Cura files name none)."""
    for reader in BED_READERS:
        bed = reader(data)
        if bed is not None:
            return bed
    return None


# -- the print's bounds the slicer wrote, rewritten when the print is rotated ------------------------
_NUM = rb"[-+]?\d+(?:\.\d*)?"


@dataclass(frozen=True)
class BoundsFormat:
    """A line in which a slicer states where the print lies on the bed. ``kind`` "box": named
    groups ``minx maxx miny maxy`` (any of them) hold the XY box of the print; "outline": every
    ``[x,y]`` pair and ``CENTER=x,y`` on the line is a point of an object's outline."""

    slicer: str
    pattern: bytes
    kind: str
    example: str
    #: a literal each such line holds: a file without it has none (its scan is skipped: an
    #: outline is looked for in the whole file, ~0.3 s a pattern on 28 MB)
    needle: bytes = b""


BOUNDS_FORMATS = (
    # Cura ';MINX:96.5', Creality Print '; MINX = 38.69', Cura Griffin ';PRINT.SIZE.MIN.X:9'
    *(BoundsFormat("cura", rb"(?m)^;(?:[ \t]*" + k.upper() + rb"[ \t]*[:=]|PRINT\.SIZE\." + k[:3].upper()
                   + rb"\." + k[3:].upper() + rb":)[ \t]*(?P<" + k + rb">" + _NUM + rb")", "box",
                   f";{k.upper().decode()}:96.5") for k in (b"minx", b"miny", b"maxx", b"maxy")),
    # ideaMaker ';Bounding Box: minx maxx miny maxy minz maxz'
    BoundsFormat("ideamaker", rb"(?m)^;Bounding Box:[ \t]*(?P<minx>" + _NUM + rb")[ \t]+(?P<maxx>" + _NUM
                 + rb")[ \t]+(?P<miny>" + _NUM + rb")[ \t]+(?P<maxy>" + _NUM + rb")", "box",
                 ";Bounding Box: 76.501 123.499 94.994 110.006 0.000 9.320"),
    # Klipper's exclude_object outline (Orca, SuperSlicer, Cura plug-ins): drawn by the web UIs
    BoundsFormat("klipper", rb"(?m)^[ \t]*EXCLUDE_OBJECT_DEFINE\b[^\r\n]*", "outline",
                 "EXCLUDE_OBJECT_DEFINE NAME=cube_id_0_copy_0 CENTER=125,105 POLYGON=[[115,95],[135,95],[135,115],[115,115]]",
                 b"EXCLUDE_OBJECT_DEFINE"),
    # PrusaSlicer's object outlines for cancelling objects (octoprint, Prusa firmware)
    BoundsFormat("prusaslicer", rb"(?m)^;[ \t]*objects_info[ \t]*=[^\r\n]*", "outline",
                 '; objects_info = {"objects":[{"name":"cube_id_0_copy_0","polygon":[[115.0,95.0],[135.0,95.0],[135.0,115.0],[115.0,115.0]]}]}',
                 b"objects_info"),
)

_PAIR = re.compile(rb"(\[[ \t]*|CENTER=)(" + _NUM + rb")([ \t]*,[ \t]*)(" + _NUM + rb")")
BOX_TOL_MM = 0.05        # a point this far outside the stated box still counts as inside it


def bounds_lines(data: bytes, line_start) -> list[tuple[int, BoundsFormat, "re.Match"]]:
    """(0-based line, format, match) of every bounds line of ``data`` (``BOUNDS_FORMATS``; box
    lines in the head and tail where slicers write them, outlines anywhere), in file order.
    ``line_start``: the byte offset of each line (``Program.line_start``)."""
    import numpy as np
    out = []
    for fmt in BOUNDS_FORMATS:
        if fmt.needle and fmt.needle not in data:
            continue
        pat = re.compile(fmt.pattern)
        parts = [(0, data)] if fmt.kind == "outline" else _ends(data)
        for off, part in parts:
            for m in pat.finditer(part):
                pos = off + m.start()
                line = int(np.searchsorted(line_start, pos, side="right")) - 1
                out.append((line, fmt, m, off))
    seen, uniq = set(), []
    for line, fmt, m, off in sorted(out, key=lambda t: t[0]):
        if line not in seen:
            seen.add(line)
            uniq.append((line, fmt, m, off))
    return uniq


def _fmt(value: float, like: bytes) -> str:
    dec = len(like.split(b".", 1)[1]) if b"." in like else 0
    s = f"{value:.{max(dec, 3)}f}"
    s = s.rstrip("0").rstrip(".") if "." in s else s
    return "0" if s in ("-0", "") else s


def rotated_bounds(data: bytes, line_start, rotate, points_xy) -> dict[int, str]:
    """{0-based line: new text (its line ending kept)} for every bounds line of ``data`` after the
    print is rotated by ``rotate`` ((k, 2) points -> (k, 2) points). A box becomes the box of the
    rotated print: of ``points_xy`` (the print's extrusion end points, unrotated) those inside the
    stated box (``BOX_TOL_MM``: the slicer's box is the print's, skirt and all, or the model's),
    rotated (the box's corners if none is inside); an outline's points are rotated one by one."""
    import numpy as np
    found = bounds_lines(data, line_start)
    box = {}
    for _, fmt, m, _ in found:
        if fmt.kind == "box":
            for k, v in m.groupdict().items():
                if v is not None:
                    box.setdefault(k, float(v))
    pts = np.asarray(points_xy, float).reshape(-1, 2)
    if len(box) == 4:
        inside = ((pts[:, 0] >= box["minx"] - BOX_TOL_MM) & (pts[:, 0] <= box["maxx"] + BOX_TOL_MM)
                  & (pts[:, 1] >= box["miny"] - BOX_TOL_MM) & (pts[:, 1] <= box["maxy"] + BOX_TOL_MM))
        pts = pts[inside]
        if len(pts) < 2:
            pts = np.array([[box["minx"], box["miny"]], [box["maxx"], box["miny"]],
                            [box["maxx"], box["maxy"]], [box["minx"], box["maxy"]]])
    new_box = {}
    if len(pts):
        r = np.asarray(rotate(pts), float)
        new_box = {"minx": r[:, 0].min(), "maxx": r[:, 0].max(), "miny": r[:, 1].min(), "maxy": r[:, 1].max()}
    out = {}
    for line, fmt, m, off in found:
        a, b = int(line_start[line]), int(line_start[line + 1])
        text = data[a:b]
        body = text.rstrip(b"\r\n")
        ending = text[len(body):]
        if fmt.kind == "box":
            if not new_box:
                continue
            base = off + m.start() - a
            pieces, at = [], 0
            for k in ("minx", "maxx", "miny", "maxy"):
                if m.groupdict().get(k) is None:
                    continue
                s, e = m.start(k) - m.start() + base, m.end(k) - m.start() + base
                pieces.append((s, e, _fmt(float(new_box[k]), body[s:e]).encode()))
            new = b""
            for s, e, v in sorted(pieces):
                new += body[at:s] + v
                at = e
            new += body[at:]
        else:
            pairs = list(_PAIR.finditer(body))
            if not pairs:
                continue
            xy = np.array([[float(p.group(2)), float(p.group(4))] for p in pairs])
            r = np.asarray(rotate(xy), float)
            new, at = b"", 0
            for p, (x, y) in zip(pairs, r):
                new += (body[at:p.start(2)] + _fmt(x, p.group(2)).encode() + p.group(3)
                        + _fmt(y, p.group(4)).encode())
                at = p.end(4)
            new += body[at:]
        out[line] = (new + ending).decode("utf-8", "surrogateescape")
    return out
