"""The energy model: the paper's tables reproduced exactly, hand-computed programs, profiles."""
from __future__ import annotations

import numpy as np
import pytest

from gatesopt import parse
from gatesopt.energy import PowerCoefficients, load_profile, profile, step_energy_j, step_power_w


FIVE_LINES = "G21\nG90\nM83\nG1 F1200 X10 Y0 E0.5\nG0 F3000 X10 Y30\n"


def test_hand_computed_five_line_program():
    p = parse(FIVE_LINES)
    r = profile(p)
    # extrusion: L = 10 mm at 20 mm/s -> 0.5 s at 40.00 W (mean of Table 2's G1 rows) = 20 J
    # travel:    L = 30 mm at 50 mm/s -> 0.6 s at 21.30 W (Table 2 G0)               = 12.78 J
    assert r.time_s == pytest.approx(1.1)
    assert r.energy_j == pytest.approx(20.0 + 12.78)
    assert sum(r.sectors_j.values()) == pytest.approx(r.energy_j)


@pytest.mark.parametrize("text, all_on, one_gated", [
    ("G1 X10 F600\n", 21.30, 12.53),         # Table 2 G0 / Table 4 G0
    ("M83\nG1 X10 E1 F600\n", 40.00, 24.97),  # means of the seven G1 rows of Tables 2 and 4
])
def test_paper_tables_2_and_4_exactly(text, all_on, one_gated):
    p = parse(text)
    c = load_profile("paper").coefficients(p)
    on = np.ones((1, 4), bool)
    y_off = on.copy()
    y_off[0, 1] = False
    assert step_power_w(c, on)[0] == pytest.approx(all_on, abs=1e-12)
    assert step_power_w(c, y_off)[0] == pytest.approx(one_gated, abs=1e-12)


def test_both_xy_gated_is_the_linear_assumption():
    p = parse("G1 X10 F600\n")
    c = load_profile("paper").coefficients(p)
    both = np.array([[False, False, True, True]])
    assert step_power_w(c, both)[0] == pytest.approx(21.30 - 2 * (21.30 - 12.53))


def test_control_instruction_powers_from_table_2():
    p = parse("G1 X1 F600\nG4 S10\nG28\n")
    r = profile(p)
    assert r.by_kind_j["dwell"] == pytest.approx(2.41 * 10)
    assert r.by_kind_j["home"] == pytest.approx(20.84 * 5.0)   # 5 s homing: named assumption


def test_energy_is_linear_in_the_enable_matrix():
    p = parse("M83\nG1 X10 E1 F600\nG1 X10 Y10\n")
    c = load_profile("paper").coefficients(p)
    rng = np.random.default_rng(0)
    d = np.array([0.3, 0.7])
    for _ in range(10):
        en = rng.random((2, 4)) > 0.5
        en[:, :2] = True        # XY on: the linear regime
        expect = d * (c.base_w + (c.motor_w * en).sum(1))
        assert step_energy_j(d, c, en) == pytest.approx(expect)


def test_pieces_of_a_split_step_add_up():
    p = parse("M83\nG1 X10 E1 F600\n")
    c = load_profile("paper").coefficients(p)
    whole = step_energy_j(p.duration_s, c, np.ones((1, 4), bool)).sum()
    rows = np.array([0, 0, 0])
    pieces = step_energy_j(np.array([0.2, 0.5, p.duration_s[0] - 0.7]), c.take(rows), np.ones((3, 4), bool))
    assert pieces.sum() == pytest.approx(whole)


def test_component_profile_and_motor_off_saves_its_power():
    prof = load_profile("component_example")
    p = parse("M104 S200\nM140 S60\nM106 S255\nG1 X10 F600\n")
    c = prof.coefficients(p)
    on = np.ones((1, 4), bool)
    off = on.copy()
    off[0, 2] = False
    assert step_power_w(c, on)[0] - step_power_w(c, off)[0] == pytest.approx(prof.params["motor_w"][2])
    expect_base = (prof.params["base_w"] + 40.0 * 0.30 + 220.0 * 0.35 + 1.2 + 1.5)  # X steps
    assert c.base_w[0] == pytest.approx(expect_base)


def test_profile_from_file_and_bad_profiles(tmp_path):
    good = tmp_path / "mine.toml"
    good.write_text('name="mine"\nkind="component"\nbase_w=1\nmotor_w=[1,1,1,1]\nhotend_w=0\nbed_w=0\nfan_w=0\n')
    assert load_profile(good).name == "mine"
    bad = tmp_path / "bad.toml"
    bad.write_text('kind="component"\nbase_w=1\n')
    with pytest.raises(ValueError, match="missing key 'motor_w'"):
        load_profile(bad)
    broken = tmp_path / "broken.toml"
    broken.write_text("kind = \n")
    with pytest.raises(ValueError, match="not a valid TOML"):
        load_profile(broken)
    with pytest.raises(ValueError, match="unknown energy profile 'nope'"):
        load_profile("nope")


def test_motor_disable_lowers_energy_in_the_profile():
    base = parse("G1 X10 F600\nG1 X20\n")
    gated = parse("G1 X10 F600\nS0 Y\nG1 X20\n")
    assert profile(gated).energy_j < profile(base).energy_j
    # exactly the Y share of the second move: (21.30 - 12.53) W * 10 mm / 10 mm/s
    assert profile(base).energy_j - profile(gated).energy_j == pytest.approx(8.77 * 1.0)


def test_per_layer_sums_to_total_over_layered_steps():
    text = (";LAYER:0\nM83\nG1 Z0.2 F600\nG1 X10 E1\n;LAYER:1\nG1 Z0.4\nG1 X0 E1\n")
    r = profile(parse(text))
    assert r.layer_energy_j.sum() == pytest.approx(r.energy_j)
    assert len(r.layer_time_s) == 2


def test_power_coefficients_take_keeps_parent_rows():
    c = PowerCoefficients(np.array([0, 1], np.int32), np.array([1.0, 2.0]), np.ones((2, 4)), np.zeros(2),
                          np.zeros(2), np.zeros(2))
    t = c.take(np.array([1, 1, 0]))
    assert t.base_w.tolist() == [2.0, 2.0, 1.0]
    assert t.motor_w.shape == (3, 4)


def test_power_by_enable_pattern_matches_the_formula():
    p = parse("M83\nM106 S255\nG1 X10 E1 F600\nG1 X20 Y5\nG4 S1\n")
    c = load_profile("paper").coefficients(p)
    for pattern in range(16):
        en = np.array([[(pattern >> m) & 1 for m in range(4)]] * p.n_steps, bool)
        both_off = ~en[:, 0] & ~en[:, 1]
        expect = c.base_w + (c.motor_w * en).sum(1) + both_off * c.xy_off_w
        assert step_power_w(c, en) == pytest.approx(expect)


def test_sectors_equal_a_direct_per_step_sum():
    p = parse("M104 S200\nM83\nG1 X10 E1 F600\nM106 S255\nG1 X20 Y5 E1\nS0 Y\nG1 X30\nG4 S1\n")
    for name in ("paper", "component_example"):
        r = profile(p, name)
        c = load_profile(name).coefficients(p)
        en = p.enabled
        d = p.duration_s
        assert r.sectors_j["X"] == pytest.approx((c.motor_w[:, 0] * en[:, 0] * d).sum())
        assert r.sectors_j["heater"] == pytest.approx((c.heater_w * d).sum())
        assert r.sectors_j["fans"] == pytest.approx((c.fans_w * d).sum())
        assert sum(r.sectors_j.values()) == pytest.approx(r.energy_j)
        assert r.energy_j == pytest.approx(step_energy_j(d, c, en).sum())
