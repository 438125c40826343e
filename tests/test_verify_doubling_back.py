"""A path that doubles back on itself (A then B collinear, then C back over both): the verifier's
joining of split pieces must not merge A and B into "C reversed" (found by the pipeline fuzz)."""
from __future__ import annotations

import pytest

import gatesopt
from gatesopt.gating import GatingOptions
from gatesopt.gating.pipeline import run
from gatesopt.verify import verify

TEXT = ("G21\nG90\nM83\nM104 S200\nM109 S200\nG28\nG92 E0\n;LAYER_CHANGE\n;Z:0.2\nG1 Z0.200 F600\n"
        "G1 E-0.80000 F2100\nG1 X80.000 Y80.000 F9000\nG1 E0.80000 F2100\nG1 F1800\n"
        "G1 X80.000 Y80.000 E0.00000\n;LAYER_CHANGE\n;Z:0.4\nG1 Z0.400 F600\nM106 S255\n"
        "G1 E-0.80000 F2100\nG1 X80.000 Y80.000 F9000\nG1 E0.80000 F2100\nG1 F1800\n"
        "G1 X80.000 Y81.000 E0.03300\nG1 X80.000 Y82.000 E0.03300\nG1 X80.000 Y80.000 E0.06600\n"
        "G1 E-0.80000 F2100\nG1 Z10 F600\nM104 S0\nM107\nM84\n")


@pytest.mark.parametrize("firmware", ["marlin", "klipper"])
@pytest.mark.parametrize("rotate", ["none", "auto"])
def test_gated_output_of_a_path_that_doubles_back_verifies(firmware, rotate):
    prog = gatesopt.parse(TEXT.encode())
    res = run(prog, GatingOptions.for_firmware(firmware, rotate=rotate, num_workers=1),
              formulation="dp", time_limit_s=10.0, order=False)
    assert res.report.ok, [str(f) for f in res.report.findings]


def test_a_missing_piece_of_that_path_is_still_caught():
    prog = gatesopt.parse(TEXT.encode())
    bad = gatesopt.parse(TEXT.replace("G1 X80.000 Y81.000 E0.03300\n", "G1 X80.000 Y81.000\n").encode())
    rep = verify(prog, bad)
    assert not rep.ok
    assert any(f.check in ("geometry", "extrusion") for f in rep.findings)
