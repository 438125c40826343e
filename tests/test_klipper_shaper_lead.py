"""The stock klipper dialect's start lead from the printer's [input_shaper] (issue 34).

Klipper re-enables a motor at the print time of its ``SET_STEPPER_ENABLE ... ENABLE=1`` line, but an
input shaper sends a move's steps up to its pre-active time before the move's nominal start
(klippy/chelper/kin_shaper.c ``shaper_note_generation_time``: ``pre_active`` = the last pulse time
after ``init_shaper`` reversed the pulses and ``shift_pulses`` time-centred them). Without a
printer config the dialect counts 60 ms (any of Klipper's shapers at 20 Hz or more); with one, the
printer's own pre-active time. The expected numbers are computed here by hand from Klipper's
klippy/extras/shaper_defs.py ``get_mzv_shaper`` / ``get_zv_shaper``.
"""
from __future__ import annotations

import math

import pytest

from gatesopt.firmware import klipper as kl
from gatesopt.gating.options import GatingOptions
from gatesopt.printer_config import read_printer_config

START_AHEAD_S = 1.8e-3


def mzv_pre_s(freq_hz, zeta=0.1):
    # shaper_defs.get_mzv_shaper: K = exp(-.75 zeta pi / df), t_d = 1 / (f df),
    # A = [1 - 1/sqrt2, (sqrt2 - 1) K, (1 - 1/sqrt2) K^2], T = [0, .375 t_d, .75 t_d];
    # pre-active = the amplitude-weighted mean time of the pulses (T_0 = 0)
    df = math.sqrt(1 - zeta * zeta)
    k = math.exp(-0.75 * zeta * math.pi / df)
    t_d = 1 / (freq_hz * df)
    a = [1 - 1 / math.sqrt(2), (math.sqrt(2) - 1) * k, (1 - 1 / math.sqrt(2)) * k * k]
    t = [0.0, 0.375 * t_d, 0.75 * t_d]
    return sum(x * y for x, y in zip(a, t)) / sum(a)


def zv_pre_s(freq_hz, zeta=0.1):
    # shaper_defs.get_zv_shaper: K = exp(-zeta pi / df), A = [1, K], T = [0, .5 t_d]
    df = math.sqrt(1 - zeta * zeta)
    k = math.exp(-zeta * math.pi / df)
    t_d = 1 / (freq_hz * df)
    return k * 0.5 * t_d / (1 + k)


def options(tmp_path, shaper_text):
    cfg = tmp_path / "printer.cfg"
    cfg.write_text("[printer]\nkinematics: cartesian\nmax_velocity: 300\nmax_accel: 3000\n\n" + shaper_text)
    return GatingOptions.for_firmware("klipper", printer=read_printer_config(cfg), start_ahead_s=START_AHEAD_S)


def test_mzv_30hz_lead(tmp_path):
    assert mzv_pre_s(30) == pytest.approx(0.0108325, abs=1e-7)
    o = options(tmp_path, "[input_shaper]\nshaper_type: mzv\nshaper_freq_x: 30\nshaper_freq_y: 30\n")
    assert o.start_ahead_s == pytest.approx(START_AHEAD_S + mzv_pre_s(30) + kl.SHAPER_LEAD_SLACK_S, rel=1e-12)


def test_per_axis_shapers_take_the_largest(tmp_path):
    # X zv at 50 Hz (5.3 ms), Y mzv at 25 Hz (13.0 ms): Y's pre-active decides
    o = options(tmp_path, "[input_shaper]\nshaper_type_x: zv\nshaper_freq_x: 50\n"
                          "shaper_type_y: mzv\nshaper_freq_y: 25\n")
    pre = max(zv_pre_s(50), mzv_pre_s(25))
    assert pre == pytest.approx(mzv_pre_s(25))
    assert o.start_ahead_s == pytest.approx(START_AHEAD_S + pre + kl.SHAPER_LEAD_SLACK_S, rel=1e-12)


def test_no_shaper_no_lead_and_no_config_the_default(tmp_path):
    assert options(tmp_path, "").start_ahead_s == pytest.approx(START_AHEAD_S, rel=1e-12)
    o = GatingOptions.for_firmware("klipper", start_ahead_s=START_AHEAD_S)
    assert o.start_ahead_s == pytest.approx(START_AHEAD_S + kl.SHAPER_LEAD_S, rel=1e-12)
