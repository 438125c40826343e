"""Parse warnings (issue 37): never silent about what the firmware would read or do differently
from what the file seems to say; one line each, with file and line. Property tests (hypothesis)
against a reference reading of each case.

The reference for numbers is Klipper's own tokenizer (klippy/gcode.py ``_process_commands``: the
upper-cased line split at letters, the last value of a letter kept, ``float`` of each value),
which for these lines reads what Marlin's parser.cpp reads too (``value_float`` stops at E/e).
"""
from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gatesopt import GcodeError, parse_text
from gatesopt.parse import ABSURD_FEED_MM_S, CRAWL_FEED_MM_S

HEAD = "G21\nG90\nM82\nG92 E0\nG1 X5 Y5 F1200\nG1 X10 Y5 E1\n"
N_HEAD = HEAD.count("\n")
START = {"X": 10.0, "Y": 5.0, "Z": 0.0, "E": 1.0}        # where HEAD leaves the axes
_KLIPPER_ARGS = re.compile("([A-Z_]+|[A-Z*])")      # klippy/gcode.py GCodeDispatch.args_r
_STRTOD = re.compile(r"[+-]?(?:0[xX][0-9a-fA-F]+|\d+\.?\d*|\.\d+)")


def klipper_move(line: str) -> dict | None:
    """Where Klipper moves X Y Z E on a G1 ``line``: klippy/gcode.py ``_process_commands`` (the
    upper-cased line split at runs of letters, the last value of a name kept) and
    extras/gcode_move.py ``cmd_G1`` (``float`` of each axis given; None: "Unable to parse move")."""
    parts = _KLIPPER_ARGS.split(line.split(";")[0].strip().upper())
    params = {parts[i]: parts[i + 1].strip() for i in range(1, len(parts), 2)}
    try:
        return {L: float(params[L]) if L in params else START[L] for L in "XYZE"}
    except ValueError:
        return None


def marlin_move(line: str) -> dict:
    """Where Marlin 2.x moves X Y Z E on a G1 ``line``: parser.cpp ``GCodeParser::parse`` with
    FASTER_GCODE_PARSER (each letter a word; a value when ``valid_float``; the value part skipped
    over [0-9.+-]; the last pointer of a letter kept), parser.h ``value_float`` (strtod of the text
    up to a blank or an E/e) and G0_G1.cpp (an axis moves when ``seenval``)."""
    p = line.split(";")[0].strip()
    i = 2                       # after "G1"
    params = {}
    while i < len(p):
        c = p[i].upper()
        i += 1
        if "A" <= c <= "Z":
            while i < len(p) and p[i] == " ":
                i += 1
            rest = p[i:]
            ok = bool(re.match(r"[+-]?\.?\d", rest))          # valid_float
            params[c] = rest if ok else None
        if not (i < len(p) and "A" <= p[i] <= "Z"):
            while i < len(p) and p[i] in "0123456789.+-":
                i += 1
            while i < len(p) and p[i] == " ":
                i += 1
    out = dict(START)
    for L in "XYZE":
        v = params.get(L)
        if v is not None:
            text = re.split(r"[ eE]", v)[0]
            m = _STRTOD.match(text)
            out[L] = (int(m.group(0), 16) if "x" in m.group(0).lower() else float(m.group(0))) if m else 0.0
    return out


mantissa = st.one_of(st.integers(0, 999).map(str),
                     st.tuples(st.integers(0, 99), st.integers(0, 999)).map(lambda t: f"{t[0]}.{t[1]}"))
exponent_number = st.tuples(mantissa, st.sampled_from("eE"), st.sampled_from(["", "+", "-"]),
                            st.integers(0, 400)).map(lambda t: f"{t[0]}{t[1]}{t[2]}{t[3]}")
plain_number = st.one_of(mantissa, mantissa.map(lambda m: "-" + m))
hex_number = st.integers(0, 255).map(lambda v: f"0x{v:x}")
word = st.tuples(st.sampled_from("XYZE"), st.one_of(plain_number, exponent_number, hex_number))


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(word, min_size=1, max_size=4), st.booleans())
def test_a_move_is_read_as_firmware_reads_it_or_refused(words, compact):
    """A G1 line is read where Marlin and Klipper both move to, or refused with one line naming
    file and line: an exponent on a line whose words are apart (``G1 X1e400 Y10``: both firmwares
    read X1 E400), a hexadecimal number (``Y0x10``: 16 or 0 to Marlin, depending on its C library,
    Y0 X10 to Klipper), a line the two firmwares read differently, or a coordinate beyond any
    printer. Compact words (``G1X10Y5E.2``, E straight after a number) are read as firmware
    reads them."""
    sep = "" if compact else " "
    line = "G1" + sep + sep.join(f"{L}{v}" for L, v in words)
    klipper, marlin = klipper_move(line), marlin_move(line)
    agree = klipper is not None and all(klipper[L] == pytest.approx(marlin[L], abs=1e-9) for L in "XYZE")
    exponent = not compact and re.search(r"\d[eE][+-]?\d+(?![\d.])", line) is not None
    # a number written like a hexadecimal one: firmwares read it in two ways (refused)
    hexadecimal = re.search(r"[A-Za-z][+-]?0[xX]", line) is not None
    try:
        prog = parse_text(HEAD + line + "\n", source="w.gcode")
    except GcodeError as err:
        msg = str(err)
        assert msg.startswith(f"w.gcode:{N_HEAD + 1}: ") and "\n" not in msg
        assert ((exponent and "no firmware reads exponents" in msg)
                or (hexadecimal and "hexadecimal" in msg) or not agree or "absurd" in msg), msg
        return
    assert agree and not exponent and not hexadecimal, line
    end = prog.end_mm[-1]
    for q, L in enumerate("XYZE"):
        assert end[q] == pytest.approx(klipper[L], abs=1e-9), (line, L)
    letters = [L for L, _ in words]
    if len(set(letters)) < len(letters):
        assert any("given twice" in w for w in prog.warnings), prog.warnings


@settings(max_examples=150, deadline=None)
@given(st.one_of(st.floats(1e-6, 1e12, allow_nan=False), st.sampled_from([5.9, 6.0, 300000.0, 300001.0])),
       st.integers(0, 3))
def test_a_feed_beyond_any_printer_or_a_crawl_is_said_once(feed_mm_min, where):
    """``F99999999999`` (1.7e9 mm/s) and ``F1`` (0.017 mm/s) each get one warning line at the
    first move that uses them, saying what firmware does; a feed in between, none."""
    lines = ["G1 X20 Y20 F1200", "G1 X30 Y20 E2", "G1 X30 Y30 E3", "G1 X20 Y30 E4"]
    lines[where] += f" F{feed_mm_min:.6f}"
    text = HEAD + "\n".join(lines) + "\nG1 F1200\n"
    prog = parse_text(text, source="f.gcode")
    feed_mm_s = float(f"{feed_mm_min:.6f}") / 60.0
    said = [w for w in prog.warnings if "feed" in w]
    fast, slow = feed_mm_s > ABSURD_FEED_MM_S, feed_mm_s < CRAWL_FEED_MM_S
    if not (fast or slow):
        assert said == []
        return
    assert len(said) == 1, said
    assert said[0].startswith(f"f.gcode:{N_HEAD + where + 1}: ")
    assert ("beyond any printer" in said[0]) == fast and ("crawl" in said[0]) == slow
    assert (f"{3 - where} more moves" in said[0]) == (where < 3)


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 400))
def test_a_file_cut_inside_a_move_is_said(cut_from_end):
    """A file cut short (no line ending at its end) inside a move gets one warning naming that
    line; cut inside another command or a comment, or not cut, none."""
    body = HEAD + "".join(f"G1 X{10 + k}.5 Y{20 + k}.25 E{1 + k}.125 ; move {k}\nM106 S{k}\n"
                          for k in range(12))
    text = body[:len(body) - cut_from_end]
    last = text.rsplit("\n", 1)[-1]
    try:
        prog = parse_text(text, source="c.gcode")
    except GcodeError as err:        # cut inside a word (``G1 X14.5 Y``): refused, and said why
        assert str(err).startswith(f"c.gcode:{text.count(chr(10)) + 1}: ")
        assert str(err).endswith("the file ends inside this line: was it cut short?")
        return
    said = [w for w in prog.warnings if "cut short" in w]
    if text.endswith("\n") or not re.match(r"G1 [XYZE]", last):
        assert said == []
        return
    assert len(said) == 1 and said[0].startswith(f"c.gcode:{text.count(chr(10)) + 1}: {last.strip()[:20]}")


def test_the_survey_inputs_each_get_their_line():
    """The three silent acceptances of the first-hour survey (issue 37), on real slicer output."""
    from conftest import PROJECT_INSTANCES
    base = (PROJECT_INSTANCES / "square_lines.gcode").read_text()
    n = base.count("\n")
    with pytest.raises(GcodeError, match=rf"^x\.gcode:{n + 1}: G1 X1e400 Y10: X1e400: no firmware "
                                          r"reads exponents: Marlin and Klipper both read X1 E400"):
        parse_text(base + "G1 X1e400 Y10\n", source="x.gcode")
    w = parse_text(base + "G1 X100 Y100 F99999999999\n", source="x.gcode").warnings
    assert any(s.startswith(f"x.gcode:{n + 1}: G1 X100 Y100 F99999999999: feed 1.667e+09 mm/s") for s in w)
    w = parse_text(base + "G1 X10", source="x.gcode").warnings
    assert any(s.startswith(f"x.gcode:{n + 1}: G1 X10: the file ends inside this move") for s in w)
    # not a move: read as firmware reads it, with a warning; text commands are text
    w = parse_text(base + "M104 S2.1e2\nM117 Printing 1e5 copies...\n", source="x.gcode").warnings
    assert [s for s in w if "exponent" in s] == [
        f"x.gcode:{n + 1}: M104 S2.1e2: S2.1e2: no firmware reads exponents: Marlin and Klipper "
        "both read S2.1 E2, and so does gatesopt"]
    assert not any("twice" in s for s in w)


def test_real_slicer_output_gets_none_of_these_warnings():
    """No false alarm on the corpus (39 real files): none of them has an exponent, a letter given
    twice on a command, an absurd feed, or a move cut short (three end without a line ending:
    a comment, and FullControl's ``M84 ; disable steppers``)."""
    from conftest import shared_files
    from gatesopt import parse
    files = shared_files()
    if not files:
        pytest.skip("development corpus not found")
    new = ("exponent", "given twice", "feed ", "cut short")
    for f in files:
        prog = parse(f)
        assert not [w for w in prog.warnings if any(k in w for k in new)], f
    assert np.isfinite(len(files))
