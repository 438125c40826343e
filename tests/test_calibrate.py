"""`gatesopt calibrate`: a log synthesized from a known profile is recovered; bad logs are refused."""
from __future__ import annotations

import numpy as np
import pytest

from gatesopt import parse
from gatesopt.calibrate import CalibrationError, PowerLog, fit, read_power_log, synthesize_log, write_power_log
from gatesopt.cli import main
from gatesopt.energy import load_profile


# a print with heat-up, fan changes, motors switched off at the end and an idle tail: every
# parameter the component model has is visible in it
PRINT = "\n".join([
    "M140 S60", "M104 S200", "M190 S60", "M109 S200", "G28", "G90", "M83", "G1 Z0.2 F600",
    *[f"G1 X{40 * (i % 2)} Y{i * 0.5:.1f} E1.5 F1200" for i in range(120)],
    "M106 S255",
    *[f"G1 X{40 * (i % 2)} Y{60 + i * 0.5:.1f} E1.5 F1200" for i in range(120)],
    "M106 S0", "G1 Z10 F600", "M18 X Y", "G4 S40", "M18 E", "G4 S30", "M84", "G4 S30", "M104 S0", "G4 S20",
]) + "\n"


def truth():
    prof = load_profile("component_example")
    p = dict(prof.params)
    p.update(base_w=6.0, motor_w=[5.0, 4.0, 3.5, 2.5], hotend_w=35.0, bed_w=180.0, fan_w=2.0, moving_extra_w=1.0)
    return prof.__class__(name="truth", kind="component", params=p, time=prof.time)


def test_synthetic_log_is_recovered():
    program = parse(PRINT)
    log = synthesize_log(program, truth(), sample_s=1.0, noise_w=0.5, offset_s=37.0, seed=1)
    cal = fit(program, log)
    assert cal.offset_s == pytest.approx(37.0, abs=2.0)
    assert cal.time_scale == pytest.approx(1.0, abs=0.03)
    expect = {"base_w": 6.0, "hotend_w": 35.0, "bed_w": 180.0, "fan_w": 2.0}
    for k, v in expect.items():
        assert cal.params[k] == pytest.approx(v, rel=0.15, abs=1.0), k
    assert cal.rel_error < 0.05
    assert cal.energy_error < 0.03
    # X and Y are switched off on the same line: only their sum is determined, and the fit says so
    assert not cal.identifiable["motor_x_w"] and not cal.identifiable["motor_y_w"]
    assert cal.params["motor_x_w"] + cal.params["motor_y_w"] == pytest.approx(9.0, rel=0.1)
    assert cal.identifiable["motor_e_w"] and cal.identifiable["bed_w"]


def test_fitted_profile_loads_and_predicts_the_log(tmp_path):
    program = parse(PRINT)
    log = synthesize_log(program, truth(), noise_w=0.2, offset_s=5.0, seed=2)
    cal = fit(program, log)
    path = tmp_path / "fit.toml"
    path.write_text(cal.profile_toml)
    prof = load_profile(path)
    assert prof.kind == "component"
    from gatesopt.energy import profile
    e_truth = profile(program, truth()).energy_j
    e_fit = profile(program, prof).energy_j
    assert e_fit == pytest.approx(e_truth, rel=0.05)


def test_too_short_and_unrelated_logs_are_refused():
    program = parse(PRINT)
    short = synthesize_log(program, truth(), sample_s=1.0)
    short = PowerLog(short.time_s[:40], short.power_w[:40], "short.csv")
    with pytest.raises(CalibrationError, match="short.csv: too short"):
        fit(program, short)
    rng = np.random.default_rng(0)
    n = 2000
    noise = PowerLog(np.arange(n, dtype=float), rng.uniform(10, 300, n), "noise.csv")
    with pytest.raises(CalibrationError, match="does not match"):
        fit(program, noise)


def test_read_power_log_formats_and_errors(tmp_path):
    p = tmp_path / "log.csv"
    p.write_text("timestamp,watts\n" + "".join(f"2026-01-01 10:00:{i:02d},{50 + i}\n" for i in range(20)))
    log = read_power_log(p)
    assert log.time_s[:3].tolist() == [0, 1, 2] and log.power_w[0] == 50
    bad = tmp_path / "bad.csv"
    bad.write_text("t,w\n" + "".join(f"{i},{i}\n" for i in range(12)) + "13,abc\n")
    with pytest.raises(CalibrationError, match=r"bad.csv:14: watts 'abc'"):
        read_power_log(bad)
    back = tmp_path / "back.csv"
    back.write_text("".join(f"{t},{5}\n" for t in [0, 1, 2, 3, 2, 5, 6, 7, 8, 9, 10]))
    with pytest.raises(CalibrationError, match="must increase"):
        read_power_log(back)


def test_calibrate_cli(tmp_path, capsys):
    g = tmp_path / "print.gcode"
    g.write_text(PRINT)
    log = synthesize_log(parse(PRINT), truth(), noise_w=0.3, offset_s=12.0)
    lp = tmp_path / "log.csv"
    write_power_log(log, lp)
    out = tmp_path / "mine.toml"
    assert main(["calibrate", "--gcode", str(g), "--power-log", str(lp), "-o", str(out),
                 "--time-model", "paper"]) == 0
    assert "energy error" in capsys.readouterr().out
    assert load_profile(out).name == "calibrated"
    # never overwrite without --force
    assert main(["calibrate", "--gcode", str(g), "--power-log", str(lp), "-o", str(out), "--time-model", "paper"]) == 2
    assert "exists" in capsys.readouterr().err
