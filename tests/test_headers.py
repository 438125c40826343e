"""The "; gatesopt: ..." header lines: what the emitters write (``gatesopt.headers``) is what the
verifier reads back."""
import gatesopt
from gatesopt.headers import ORDER_HEADER, ROTATE_HEADER
from gatesopt.verify import read_rotation, verify

PRINT = "G90\nM83\nG1 X0 Y0 F3000\nG1 X10 Y0 E1\nG1 X10 Y10 E1\n"


def test_rotation_header_as_written_is_read_back():
    line = ROTATE_HEADER.format(deg="30", cx="10.5", cy="-2")
    assert read_rotation(gatesopt.parse(line + "\n" + PRINT)) == (30.0, 10.5, -2.0)
    assert read_rotation(gatesopt.parse(PRINT)) == (0.0, 0.0, 0.0)


def test_order_header_makes_verify_check_a_reordering():
    original = gatesopt.parse(PRINT)
    same = verify(original, gatesopt.parse(PRINT), start_ahead_s=0, end_late_s=0)
    marked = verify(original, gatesopt.parse(ORDER_HEADER + "\n" + PRINT), start_ahead_s=0, end_late_s=0)
    assert same.ok and not same.reordered
    assert marked.ok and marked.reordered and "ordering" in marked.checks
