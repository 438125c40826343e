"""Property tests: random G-code never crashes the parser, and always re-emits identically."""
from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gatesopt import GcodeError, parse, parse_text
from gatesopt.program import E

number = st.one_of(
    st.integers(-500, 500).map(str),
    st.floats(-500, 500, allow_nan=False).map(lambda v: f"{v:.4f}"),
    st.sampled_from(["", "-", ".", "1.2.3", "nan", "inf", "{machine_depth}", "1e5", "+3", "-.5"]),
)
word = st.tuples(st.sampled_from("XYZEFIJRPS"), number).map(lambda t: t[0] + t[1])
command = st.sampled_from(["G0", "G1", "G1", "G1", "G2", "G3", "G4", "G28", "G90", "G91", "G92", "G20",
                           "G21", "M82", "M83", "M104", "M109", "M106", "M107", "M84", "M18", "M17",
                           "S0", "S1", "T0", "M117", "SET_VELOCITY_LIMIT", "N5 G1", "g1", "M486"])
comment = st.sampled_from(["", " ; c", " (x) ", ";LAYER_CHANGE", ";Z:0.2", ";TYPE:Perimeter", ";LAYER:3", " *12"])
line = st.one_of(
    st.tuples(command, st.lists(word, max_size=5), comment).map(lambda t: " ".join([t[0], *t[1]]) + t[2]),
    comment,
    st.text(alphabet=st.characters(codec="utf-8", exclude_characters="\n\x00"), max_size=30),
)
program_text = st.tuples(st.lists(line, min_size=1, max_size=30), st.sampled_from(["\n", "\r\n"]),
                         st.booleans()).map(lambda t: t[1].join(t[0]) + (t[1] if t[2] else ""))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(program_text)
def test_random_gcode_never_crashes_and_round_trips(text):
    try:
        prog = parse_text(text)
    except GcodeError as err:
        msg = str(err)
        assert msg.startswith("<text>") and "\n" not in msg
        return
    assert prog.to_gcode() == text
    assert np.all(np.isfinite(prog.start_mm)) and np.all(np.isfinite(prog.end_mm))
    assert np.all(prog.duration_s >= 0)
    assert np.allclose(prog.end_mm[:-1], prog.start_mm[1:])


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=400))
def test_random_bytes_give_a_program_or_a_clear_error(data):
    try:
        prog = parse(data)
    except GcodeError as err:
        assert "\n" not in str(err)
        return
    assert prog.to_bytes() == data


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.floats(-100, 100), st.floats(-100, 100), st.floats(0, 5)), min_size=1, max_size=40),
       st.booleans())
def test_relative_and_absolute_e_agree(points, relative):
    """The same path written with M82 or M83 gives the same cumulative E."""
    e_total = 0.0
    absolute_lines, relative_lines = ["M82"], ["M83"]
    for x, y, de in points:
        de = round(de, 4)
        e_total = round(e_total + de, 4)
        absolute_lines.append(f"G1 X{x:.3f} Y{y:.3f} E{e_total:.4f} F1200")
        relative_lines.append(f"G1 X{x:.3f} Y{y:.3f} E{de:.4f} F1200")
    a = parse("\n".join(absolute_lines) + "\n")
    r = parse("\n".join(relative_lines) + "\n")
    assert np.allclose(a.end_mm[:, E], r.end_mm[:, E], atol=1e-6)
    assert np.allclose(a.duration_s, r.duration_s)


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 6).flatmap(lambda places: st.decimals(min_value=-99999, max_value=99999, places=places,
                                                             allow_nan=False, allow_infinity=False)))
def test_numbers_parse_exactly_like_python_float(d):
    """The kernel's decimal parsing gives the correctly rounded double, as float(text) does."""
    text = f"{d:f}"
    p = parse(f"G1 X{text} F600\n")
    assert p.end_mm[0, 0] == float(text)
