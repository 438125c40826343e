"""bench/klipper_replay.py: the MCU stream decode (always) and a replay through Klipper's own host
(when a Klipper checkout, a klippy Python and an MCU dictionary are configured)."""
from __future__ import annotations

import math
import sys

import numpy as np
import pytest

from conftest import REPO

sys.path.insert(0, str(REPO / "bench"))
import klipper_replay as kr  # noqa: E402

FREQ = 1_000_000.0  # 1 tick = 1 us in the synthetic streams

# A stepper on PA4 (dir PA6) with its enable pin PD7, active low: level 1 on the wire = off.
HEAD = """\
allocate_oids count=4
config_stepper oid=2 step_pin=PA4 dir_pin=PA6 invert_step=0 step_pulse_ticks=32
config_digital_out oid=3 pin=PD7 value=1 default_value=1 max_duration=0
finalize_config crc=0
"""
BODY = """\
set_next_step_dir oid=2 dir=1
queue_digital_out oid=3 clock=900 on_ticks=0
queue_step oid=2 interval=1000 count=3 add=10
queue_step oid=2 interval=500 count=2 add=0
queue_digital_out oid=3 clock=4500 on_ticks=1
set_next_step_dir oid=2 dir=0
queue_step oid=2 interval=1000 count=2 add=-100
queue_digital_out oid=3 clock=5500 on_ticks=0
"""
# step clocks: 1000, 2010 (+1010), 3030 (+1020); 3530, 4030; 5030, 5930 (+900)
STEPS = [1000, 2010, 3030, 3530, 4030, 5030, 5930]

PINS = {"extruder": kr.StepperPins("extruder", "PA4", "PA6", False, "PD7", True, 100.0)}


def stream(text: str) -> kr.McuStream:
    return kr.decode_stream(kr.parse_dump(text.splitlines(), FREQ))


def test_step_clocks_follow_interval_count_add():
    s = stream(HEAD + BODY)
    rows = s.steps["PA4"]
    assert kr.step_clocks(rows).tolist() == STEPS
    assert rows.n_steps == 7
    assert rows.first.tolist() == [1000, 3530, 5030]
    assert rows.last.tolist() == [3030, 4030, 5930]
    # direction: 5 steps forward, then 2 back
    assert int((rows.count * rows.sign).sum()) == 3


def test_off_intervals_steps_while_off_start_ahead_end_late():
    s = stream(HEAD + BODY)
    start, end = kr.off_intervals(s.pins["PD7"], initial_on=False, inverted=True)
    # off from the start until 900, then from 4500 to 5500
    assert start.tolist() == [0, 4500] and end.tolist() == [900, 5500]
    rep = kr.replay_metrics(s, PINS)
    e = rep.steppers["extruder"]
    assert e.steps == 7 and e.net_steps == 3
    assert e.gated == 1
    assert e.steps_while_off == 1 and e.gated_steps_while_off == 1     # the step at 5030
    assert e.start_ahead_min_s == pytest.approx((5930 - 5500) / FREQ, abs=1e-12)
    assert e.end_late_min_s == pytest.approx((4500 - 4030) / FREQ, abs=1e-12)
    assert e.off_time_s == pytest.approx(1000 / FREQ, abs=1e-12)
    assert e.while_off_s.tolist() == [[4500 / FREQ, 5500 / FREQ]]
    assert rep.end_s == pytest.approx(5930 / FREQ)
    assert rep.first_extrusion_s == pytest.approx(1000 / FREQ)


def test_a_step_at_the_pin_on_clock_is_not_off_but_one_at_the_off_clock_is():
    body = ("queue_digital_out oid=3 clock=100 on_ticks=0\n"
            "queue_step oid=2 interval=1000 count=1 add=0\n"          # 1000: pin goes off here
            "queue_digital_out oid=3 clock=1000 on_ticks=1\n"
            "queue_step oid=2 interval=1000 count=1 add=0\n"          # 2000: pin comes on here
            "queue_digital_out oid=3 clock=2000 on_ticks=0\n"
            "queue_step oid=2 interval=1000 count=1 add=0\n")         # 3000
    e = kr.replay_metrics(stream(HEAD + body), PINS).steppers["extruder"]
    # [1000, 2000) is off: the step at 1000 is in it, the one at 2000 is not; but the off
    # interval has a step before it only if one comes before 1000: none, so it is not gated
    assert e.steps_while_off == 1 and e.gated == 0


def test_an_inverted_dir_pin_flips_the_sign():
    pins = {"extruder": kr.StepperPins("extruder", "PA4", "PA6", True, "PD7", True, 100.0)}
    assert kr.replay_metrics(stream(HEAD + BODY), pins).steppers["extruder"].net_steps == -3


def test_pin_clocks_unwrap_past_32_bits_and_reset_step_clock():
    # two steps 2**31 - 648 ticks apart carry the stepper past 2**32; the pin clock and the
    # reset_step_clock are 32-bit values on the wire
    big = 2**31 - 300
    c2 = 2 * big
    pin_clock = c2 + 1000
    reset64 = c2 + 5000
    body = ("queue_digital_out oid=3 clock=10 on_ticks=0\n"
            f"queue_step oid=2 interval={big} count=2 add=0\n"
            f"queue_digital_out oid=3 clock={pin_clock % 2**32} on_ticks=1\n"
            f"reset_step_clock oid=2 clock={reset64 % 2**32}\n"
            "queue_step oid=2 interval=300 count=2 add=0\n"
            f"queue_digital_out oid=3 clock={(reset64 + 100) % 2**32} on_ticks=0\n")
    assert c2 < 2**32 < pin_clock
    s = stream(HEAD + body)
    assert kr.step_clocks(s.steps["PA4"]).tolist() == [big, c2, reset64 + 300, reset64 + 600]
    assert s.pins["PD7"].clock.tolist() == [10, pin_clock, reset64 + 100]
    e = kr.replay_metrics(s, PINS).steppers["extruder"]
    assert e.gated == 1 and e.steps_while_off == 0
    assert e.off_time_s == pytest.approx((reset64 + 100 - pin_clock) / FREQ)
    assert e.start_ahead_min_s == pytest.approx(200 / FREQ)


def test_a_step_after_more_than_2_32_ticks_of_idle_is_unwrapped():
    # Klipper sends a step far after the previous one as a lone queue_step whose interval is the
    # gap cut to 32 bits (stepcompress.c, stepcompress_flush_far), at its place in clock order
    big = 2**31 - 300
    text = (HEAD + "config_stepper oid=4 step_pin=PA5 dir_pin=PA7 invert_step=0 step_pulse_ticks=32\n"
            "queue_step oid=2 interval=1000 count=1 add=0\n"                 # A: 1000
            f"queue_step oid=4 interval={big} count=2 add=0\n"               # B: .., 2**32 - 600
            "queue_step oid=4 interval=3000 count=1 add=0\n"                 # B: 2**32 + 2400
            f"queue_step oid=2 interval={(2**32 + 3000 - 1000) % 2**32} count=1 add=0\n"  # A far
            "queue_step oid=2 interval=500 count=1 add=0\n")                 # A: + 500
    s = stream(text)
    assert kr.step_clocks(s.steps["PA4"]).tolist() == [1000, 2**32 + 3000, 2**32 + 3500]
    assert kr.step_clocks(s.steps["PA5"]).tolist() == [big, 2 * big, 2 * big + 3000]
    assert s.far_intervals == 1


def test_unwrap32_picks_the_nearest_64_bit_clock():
    ref = np.array([5, 2**32 - 5, 3 * 2**32 + 7], np.int64)
    got = kr.unwrap32(np.array([2**32 - 3, 4, 1]), ref)
    assert got.tolist() == [-3, 2**32 + 4, 3 * 2**32 + 1]


def _random_rows(rng, n_rows):
    interval = rng.integers(200, 5000, n_rows)
    count = rng.integers(1, 60, n_rows)
    # add keeps every interval positive: interval + (count - 1) * add > 0
    add = np.array([rng.integers(-((i - 1) // max(c - 1, 1)), 50) if c > 1 else 0
                    for i, c in zip(interval, count)], np.int64)
    adv = kr._row_advance(interval, count, add)
    start = np.concatenate([[0], np.cumsum(adv)[:-1]]) + 17
    return kr.StepRows(start.astype(np.int64), interval.astype(np.int64), count.astype(np.int64),
                       add, np.ones(n_rows, np.int64))


def test_steps_before_and_step_clock_at_match_the_expanded_steps():
    rng = np.random.default_rng(34)
    for _ in range(20):
        rows = _random_rows(rng, int(rng.integers(1, 40)))
        clocks = kr.step_clocks(rows)
        assert (np.diff(clocks) > 0).all()
        t = np.concatenate([clocks, clocks + 1, clocks - 1, rng.integers(0, clocks[-1] + 100, 200), [0]])
        assert (kr.steps_before(rows, t) == np.searchsorted(clocks, t, side="left")).all()
        g = rng.integers(0, len(clocks), 50)
        assert (kr.step_clock_at(rows, g) == clocks[g]).all()


def test_off_intervals_drop_repeated_levels_and_zero_length_gaps():
    ev = kr.PinEvents(np.array([5, 7, 9, 9, 12, 12, 20], np.int64), np.array([0, 0, 1, 0, 0, 1, 1]))
    start, end = kr.off_intervals(ev, initial_on=False, inverted=True)
    # active low: 0 = on. off [0,5); on at 5, 7 (no change); off at 9, on at 9 (zero length,
    # dropped); on at 12; off at 12 and stays off
    assert start.tolist() == [0, 12] and end.tolist() == [5, kr.OPEN_END]


# --- the binary stream -----------------------------------------------------------------------

def _vlq(v: int) -> list[int]:
    """Klipper's variable-length quantity (docs/Protocol.md)."""
    out = []
    if v >= 0xC000000 or v < -0x4000000:
        out.append((v >> 28) & 0x7F | 0x80)
    if v >= 0x180000 or v < -0x80000:
        out.append((v >> 21) & 0x7F | 0x80)
    if v >= 0x3000 or v < -0x1000:
        out.append((v >> 14) & 0x7F | 0x80)
    if v >= 0x60 or v < -0x20:
        out.append((v >> 7) & 0x7F | 0x80)
    out.append(v & 0x7F)
    return out


DICT = {
    "commands": {
        "allocate_oids count=%c": 8,
        "finalize_config crc=%u": 9,
        "config_stepper oid=%c step_pin=%c dir_pin=%c invert_step=%c step_pulse_ticks=%u": 100,
        "config_digital_out oid=%c pin=%u value=%c default_value=%c max_duration=%u": 101,
        "queue_step oid=%c interval=%u count=%hu add=%hi": 200,
        "set_next_step_dir oid=%c dir=%c": 3,
        "reset_step_clock oid=%c clock=%u": 4,
        "queue_digital_out oid=%c clock=%u on_ticks=%u": 5,
        "update_digital_out oid=%c value=%c": 6,
    },
    "config": {"CLOCK_FREQ": FREQ},
    "enumerations": {"pin": {"PA0": [0, 8], "PD0": [24, 8]}},
}


def _encode(text: str) -> bytes:
    fmts = {f.split()[0]: (i, f) for f, i in DICT["commands"].items()}
    pins = {}
    for root, (start, count) in DICT["enumerations"]["pin"].items():
        for j in range(count):
            pins[f"{root[:-1]}{int(root[-1]) + j}"] = start + j
    msgs = []
    for line in text.splitlines():
        name, *kvs = line.split()
        mid, fmt = fmts[name]
        kv = dict(x.split("=") for x in kvs)
        m = _vlq(mid)
        for part in fmt.split()[1:]:
            p = part.split("=")[0]
            m += _vlq(pins[kv[p]] if p.endswith("pin") else int(kv[p]))
        msgs.append(m)
    out, block, seq = bytearray(), [], 0
    for m in msgs + [None]:
        if m is None or len(block) + len(m) > 59:
            out += bytes([len(block) + 5, 0x10 | seq]) + bytes(block) + b"\x00\x00\x7e"
            block, seq = [], (seq + 1) & 0x0F
        if m is not None:
            block += m
    return bytes(out)


def test_decode_serial_equals_the_parsedump_text():
    body = BODY + ("queue_step oid=2 interval=805306368 count=1 add=0\n"
                   "queue_step oid=2 interval=4000 count=60 add=-33\n"
                   "reset_step_clock oid=2 clock=4294967295\n"
                   "update_digital_out oid=3 value=1\n")
    text = HEAD + body * 5
    binary = kr.decode_serial(_encode(text), DICT)
    dump = kr.parse_dump(text.splitlines(), FREQ)
    assert binary.n_messages == dump.n_messages == len(text.splitlines())
    assert binary.stepper_oids == dump.stepper_oids == {2: "PA4"}
    assert binary.out_oids == dump.out_oids == {3: ("PD7", 1)}
    for table in ("step", "dir", "reset", "pin"):
        a, b = getattr(binary, table), getattr(dump, table)
        assert a.keys() == b.keys()
        for k in a:
            assert a[k].tolist() == b[k].tolist(), (table, k)
    assert binary.step["add"].min() == -100 and binary.reset["clock"].tolist() == [2**32 - 1] * 5


def test_decode_serial_refuses_a_broken_block():
    data = bytearray(_encode(HEAD))
    data[-1] = 0
    with pytest.raises(kr.ReplayError, match="no valid block"):
        kr.decode_serial(bytes(data), DICT)


# --- G-code side, config ---------------------------------------------------------------------

def test_extrude_only_moves_and_gating_lines():
    g = ("G1 X1 Y2 E0.5\nG1 E-0.8 F2100 ; retract\nG1 F1800\nG0 Z0.4\nG1 e0.8\n"
         "SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=0\nS0 X\nM18 X\nM84\n;G1 E5\n")
    assert kr.count_extrude_only_moves(g) == 2
    assert kr.gating_lines(g, "klipper") == 1 and kr.gating_lines(g, "3dgates") == 1
    assert kr.gating_lines(g, "marlin") == 1
    assert "SET_STEPPER_ENABLE" not in kr.strip_gating_lines(g, "klipper")
    assert "M84" in kr.strip_gating_lines(g, "marlin") and "M18 X" not in kr.strip_gating_lines(g, "marlin")


def test_replay_text_homes_first_and_drops_unexpanded_placeholder_words():
    text, n = kr.replay_text("M104 S{material_print_temperature}\nG1 X1 ; {not code}\n"
                             "G1 X0 Y{machine_depth} ;Present print\n{machine_end_gcode}\n")
    lines = text.splitlines()
    assert n == 3 and lines[0].startswith("G28")
    assert lines[1].split(";")[0].strip() == "M104" and lines[2] == "G1 X1 ; {not code}"
    # the X word stays: gatesopt's parse drops only the word without a value, and so X moves in
    # the replay as in gatesopt's model (made a comment, X's last off had no step after it)
    assert lines[3].split(";")[0].strip() == "G1 X0"
    assert lines[4].startswith(";")


def test_an_off_after_the_last_step_counts_to_the_print_end():
    # X (PD7) goes off at 4500 after its last step at 4030 and stays off; another stepper (PF0)
    # steps until 9000: X's off time counts 4500 -> 9000 (gatesopt's report counts it to the end
    # of its timeline); klippy's own motor-off after the last step of all (10000) is no gating
    head = HEAD + ("config_stepper oid=5 step_pin=PF0 dir_pin=PF1 invert_step=0 step_pulse_ticks=32\n"
                   "config_digital_out oid=6 pin=PD6 value=1 default_value=1 max_duration=0\n")
    body = ("queue_digital_out oid=3 clock=900 on_ticks=0\n"
            "queue_digital_out oid=6 clock=900 on_ticks=0\n"
            "queue_step oid=2 interval=1000 count=3 add=10\n"
            "queue_step oid=2 interval=500 count=2 add=0\n"
            "queue_digital_out oid=3 clock=4500 on_ticks=1\n"
            "queue_step oid=5 interval=1000 count=9 add=0\n"
            "queue_digital_out oid=6 clock=10000 on_ticks=1\n"
            "queue_digital_out oid=3 clock=10000 on_ticks=1\n")
    pins = dict(PINS, other=kr.StepperPins("other", "PF0", "PF1", False, "PD6", True, 100.0))
    rep = kr.replay_metrics(stream(head + body), pins)
    x, o = rep.steppers["extruder"], rep.steppers["other"]
    assert rep.end_s == pytest.approx(9000 / FREQ)
    assert x.gated == 0 and x.tail_off_s == pytest.approx(4500 / FREQ)
    assert x.off_time_s == pytest.approx(4500 / FREQ)
    assert x.end_late_min_s == pytest.approx((4500 - 4030) / FREQ)
    assert o.tail_off_s == 0.0 and o.off_time_s == 0.0


def test_the_printer_has_one_dedicated_valid_enable_pin_per_stepper():
    pins = kr.stepper_pins(kr.printer_config())
    assert set(pins) == set(kr.STEPPERS)
    used = [p for sp in pins.values() for p in (sp.step_pin, sp.dir_pin, sp.enable_pin)]
    assert len(set(used)) == len(used)
    # atmega2560 port names: PA..PL without PI, bits 0..7
    assert all(len(p) == 3 and p[0] == "P" and p[1] in "ABCDEFGHJKL" and p[2] in "01234567" for p in used)
    assert all(sp.enable_inverted for sp in pins.values())
    assert pins["stepper_x"].steps_per_mm == pytest.approx(80.0)
    assert pins["stepper_z"].steps_per_mm == pytest.approx(400.0)


def test_config_variants():
    cfg = kr.printer_config(kr.parse_shaper("mzv:30"), {"start_ahead_ms": "1.8"}, 0.04)
    assert "[input_shaper]\nshaper_type_x: mzv\nshaper_freq_x: 30\nshaper_type_y: mzv" in cfg
    assert "[gatesopt_gating]\nstart_ahead_ms: 1.8\n" in cfg
    assert "[extruder]\npressure_advance: 0.04\n" in cfg
    assert kr.parse_shaper("none") is None
    assert kr.parse_shaper("zv:40:ei:55") == kr.Shaper("zv", 40.0, "ei", 55.0)
    with pytest.raises(ValueError):
        kr.parse_shaper("foo:30")


def test_find_host_says_what_is_missing(tmp_path, monkeypatch):
    for v in (kr.ENV_KLIPPER, kr.ENV_PYTHON, kr.ENV_DICT):
        monkeypatch.delenv(v, raising=False)
    assert "no Klipper checkout" in kr.find_host()
    assert "not a Klipper checkout" in kr.find_host(str(tmp_path))
    (tmp_path / "klippy").mkdir()
    (tmp_path / "klippy" / "klippy.py").write_text("")
    assert "no Python for klippy" in kr.find_host(str(tmp_path))
    assert "no MCU data dictionary" in kr.find_host(str(tmp_path), sys.executable)


# --- through Klipper's own host --------------------------------------------------------------

HOST = kr.find_host()
needs_klipper = pytest.mark.skipif(
    isinstance(HOST, str), reason=f"no Klipper host for the replay: {HOST}")

TINY = """\
G28
G1 X10 F6000
G4 P100
SET_STEPPER_ENABLE STEPPER=stepper_x ENABLE=0
G4 P100
G1 X20 F6000
G4 P100
"""


@pytest.fixture(scope="module")
def klippy():
    with kr.KlippyRunner(HOST) as k:
        yield k


@pytest.fixture(scope="module")
def tiny_serial(klippy, tmp_path_factory):
    """The MCU stream klippy writes for TINY (no input shaper), complete (klippy may cut the
    tail of its output at exit on a loaded machine: replay_metrics' ``complete``)."""
    import subprocess
    d = tmp_path_factory.mktemp("tiny")
    cfg = kr.printer_config()
    (d / "p.cfg").write_text(cfg)
    (d / "in.gcode").write_text(TINY)
    for _ in range(5):
        subprocess.run([str(HOST.python), str(klippy.klippy / "klippy.py"), str(d / "p.cfg"),
                        "-i", str(d / "in.gcode"), "-o", str(d / "o.serial"),
                        "-d", str(HOST.dictionary), "-l", str(d / "log")], check=True)
        st = kr.decode_stream(kr.decode_serial((d / "o.serial").read_bytes(), klippy.dictionary))
        if kr.replay_metrics(st, kr.stepper_pins(cfg)).complete:
            break
    return d / "o.serial"


def test_a_stream_without_the_final_motor_off_is_not_complete():
    # HEAD + BODY ends with the pin on: cut short; with a last off after the last step: complete
    assert not kr.replay_metrics(stream(HEAD + BODY), PINS).complete
    done = HEAD + BODY + "queue_digital_out oid=3 clock=7000 on_ticks=1\n"
    assert kr.replay_metrics(stream(done), PINS).complete


@needs_klipper
def test_binary_decode_equals_klippys_parsedump(klippy, tiny_serial):
    import subprocess
    text = subprocess.run([str(HOST.python), str(klippy.klippy / "parsedump.py"), str(HOST.dictionary),
                           str(tiny_serial)], capture_output=True, text=True, check=True).stdout
    dump = kr.parse_dump(text.splitlines(), klippy.dictionary["config"]["CLOCK_FREQ"])
    binary = kr.decode_serial(tiny_serial.read_bytes(), klippy.dictionary)
    assert binary.n_messages == dump.n_messages > 1000
    assert binary.stepper_oids == dump.stepper_oids and binary.out_oids == dump.out_oids
    for table in ("step", "dir", "reset", "pin"):
        a, b = getattr(binary, table), getattr(dump, table)
        for k in a:
            assert a[k].tolist() == b[k].tolist(), (table, k)


@needs_klipper
def test_replay_of_a_tiny_file_counts_steps_and_times_moves_exactly(klippy, tiny_serial):
    st = kr.decode_stream(kr.decode_serial(tiny_serial.read_bytes(), klippy.dictionary))
    assert st.freq_hz == 16e6
    # the X steps of the two moves: after the last homing move (Z)
    x = kr.step_clocks(st.steps["PF0"])
    x = x[x > st.steps["PL3"].last[-1]]
    start, end = kr.off_intervals(st.pins["PD7"], initial_on=False, inverted=True)
    assert len(start) == 3 and end[-1] == kr.OPEN_END   # before homing, gated, after the file
    before, after = x[x < start[1]], x[x >= end[1]]
    assert len(before) == 800 and len(after) == 800 and len(x) == 1600   # 10 mm * 80 steps/mm
    # each move from rest to rest: trapezoid 100 mm/s, 3000 mm/s^2 = 10/100 + 100/3000 s; a
    # step comes when the position crosses half a step (0.5 * 3000 * t^2 = 0.0125 / 2)
    t_half = math.sqrt(0.0125 / 3000)
    for m in (before, after):
        assert (m[-1] - m[0]) / st.freq_hz == pytest.approx(10 / 100 + 100 / 3000 - 2 * t_half, abs=50e-6)
    rep = kr.replay_metrics(st, kr.stepper_pins(kr.printer_config()))
    xr = rep.steppers["stepper_x"]
    assert xr.gated == 1 and xr.steps_while_off == 0 and xr.net_steps > -10**6
    # off 0.1 s (G4) + 0.1 s (DISABLE_STALL_TIME, klippy/extras/stepper_enable.py) after the
    # move, on at the next move's start (auto-enable), 0.1 s (stall) + 0.1 s (G4) later
    assert xr.off_time_s == pytest.approx(0.2, abs=1e-6)
    assert xr.end_late_min_s == pytest.approx(0.2 + t_half, abs=30e-6)
    assert xr.start_ahead_min_s == pytest.approx(t_half, abs=30e-6)
    assert rep.steppers["stepper_y"].gated == 0 and rep.steppers["extruder"].steps == 0


@needs_klipper
def test_with_an_input_shaper_klipper_steps_before_its_auto_enable(klippy):
    # input shaping starts a move's steps before its nominal start, where Klipper's auto-enable
    # (klippy/stepper.py, _check_active -> itersolve_check_active returns the move's print_time)
    # switches the pin on: steps are sent while the pin is still off
    rep = klippy.run(kr.printer_config(kr.parse_shaper("mzv:30")), TINY)
    plain = klippy.run(kr.printer_config(), TINY)
    x = rep.steppers["stepper_x"]
    assert x.gated == 1 and x.gated_steps_while_off > 0
    assert x.steps == plain.steppers["stepper_x"].steps
    assert plain.steppers["stepper_x"].steps_while_off == 0


@needs_klipper
def test_klippy_errors_come_back_with_klippys_message(klippy):
    with pytest.raises(kr.ReplayError, match="Must home axis first"):
        klippy.run(kr.printer_config(), "G1 X10 F600\n")


#: the bench printer's extruder (printer.cfg: 16 microsteps x 200 per 34.406 mm rotation
#: distance; max_extrude_only_accel by Klipper's default, max_accel 3000 mm/s^2 x 4 x nozzle
#: diameter^2 / filament area = 798 mm/s^2) takes this long from rest to its first step, half a step on (0.5 * a * t^2): an E-only
#: move starting (or ending) at rest puts its first (last) step that far inside it
E_ACCEL_MM_S2 = 3000 * 4 * 0.4 ** 2 / (math.pi * 0.875 ** 2)
E_HALF_STEP_S = math.sqrt(2 * (0.5 / (16 * 200 / 34.406)) / E_ACCEL_MM_S2)


def _planned_from_first_e_s(text: str, source: str, tmp_path) -> tuple[str, float]:
    """(the bench printer.cfg, gatesopt's planned time of ``text`` on it from the start of its
    first move with E to the end): what Klipper's planned steps of the same text span, from the
    first extruder step to the last, plus half an E step at each end (``E_HALF_STEP_S``)."""
    from gatesopt import parse
    from gatesopt.limits import machine_limits
    from gatesopt.planner import plan
    from gatesopt.printer_config import read_printer_config
    cfg_text = kr.printer_config()
    cfg = tmp_path / "printer.cfg"
    cfg.write_text(cfg_text)
    prog = parse(text, source=source)
    pl = plan(prog, machine_limits(prog, printer=read_printer_config(cfg)))
    ms = pl.move_step
    first_e = int(np.flatnonzero(prog.end_mm[ms, 3] != prog.start_mm[ms, 3])[0])
    return cfg_text, float(pl.duration_s[ms[first_e]:].sum())


# layer changes as slicers write them: retract, Z hop, travel, Z down, unretract, print
LAYERS = "G90\nM83\nG1 Z1 F600\nG1 X20 Y20 F6000\nG1 E1 F1800\nG1 X60 E2 F1800\n" + "".join(
    f"G1 E-0.8 F2100\nG1 Z{1.2 + 0.2 * i:.1f} F720\nG1 X{20 + 5 * i} Y{40 + 5 * i} F9000\n"
    f"G1 E0.8 F2100\nG1 X{60 - 5 * i} Y{20 + 5 * i} E2 F1800\n" for i in range(6)) + "G1 E-0.8 F2100\n"


@needs_klipper
def test_planner_times_z_and_extrude_only_moves_as_klipper(klippy, tmp_path):
    # gatesopt's planner on the bench printer.cfg (max_z_velocity 5, max_z_accel 100, the
    # extruder's default max_extrude_only_accel 798 mm/s^2) against Klipper's own planned steps:
    # from the first extruder step (the E-only move starting from rest) to the last (the final
    # retraction ending at rest). Each end is one half E step off the move's boundary
    # (0.5 * 798 * t^2 = half of 1 / 93.0 mm). Timed at 3000 mm/s^2 the 14 extrude-only moves were
    # 29 ms shorter each (the 0.058 s per layer change seen on the corpus).
    cfg_text, ours = _planned_from_first_e_s(LAYERS, "layers.gcode", tmp_path)
    rep = klippy.run(cfg_text, kr.replay_text(LAYERS)[0])
    assert rep.print_s == pytest.approx(ours - 2 * E_HALF_STEP_S, abs=2e-3)


def test_replay_text_gives_m83_to_a_file_that_leaves_relative_e_to_its_start_macro():
    # Kiri:Moto writes relative E and leaves M83 to the printer's print_start: gatesopt reads it
    # as relative (gatesopt.parse.undeclared_relative_e), klippy starts in absolute E
    body = "".join(f"G1 X{i % 7 + 1} Y{i % 5 + 1} E0.{i % 9 + 1}\n" for i in range(40))
    text, _ = kr.replay_text("print_start bed=70\n" + body)
    assert text.splitlines()[1].startswith("M83")
    assert kr.relative_e_undeclared(body)
    # an absolute file (E only grows), or one that says M82 itself, gets no M83
    growing = "".join(f"G1 X{i % 7 + 1} Y{i % 5 + 1} E{i + 1}\n" for i in range(40))
    assert not kr.relative_e_undeclared(growing)
    assert "M83" not in kr.replay_text(growing)[0]
    assert "M83" not in kr.replay_text("M82\n" + growing)[0]
    assert "M83" not in kr.replay_text(body, relative_e=False)[0]


# Kiri:Moto's way: relative E without an M83 of its own (the printer's print_start sets it); each
# island: travel, 6 mm unretract, three short extrusions, 6 mm retraction (no G90 either: under
# Marlin's rules, which gatesopt reads a file without a flavor by, G90 would set E absolute too)
UNDECLARED_RELATIVE = "G1 Z1 F600\n" + "".join(
    f"G1 X{20 + 3 * i} Y{20 + 3 * i} F4800\nG1 E6 F4200\nG1 X{23 + 3 * i} Y{20 + 3 * i} E0.09 F660\n"
    f"G1 X{23 + 3 * i} Y{23 + 3 * i} E0.09\nG1 X{20 + 3 * i} Y{23 + 3 * i} E0.09\nG1 E-6 F4200\n"
    for i in range(8))


@needs_klipper
def test_a_file_without_m83_is_replayed_as_gatesopt_reads_it(klippy, tmp_path):
    # gatesopt reads the E words as relative (gatesopt.parse.undeclared_relative_e); the replay
    # gives klippy the M83 the printer's start macro would. Its planned time from the first
    # extruder step (the first unretract, from rest) to the last (the last retraction, ending at
    # rest) is then gatesopt's less half an E step at each end; replayed in Klipper's default
    # absolute E, each print move after an unretract is a 5.9 mm retraction at
    # max_extrude_only_accel / |E per mm| and the print takes far longer
    cfg_text, ours = _planned_from_first_e_s(UNDECLARED_RELATIVE, "kiri.gcode", tmp_path)
    assert kr.relative_e_undeclared(UNDECLARED_RELATIVE)
    rep = klippy.run(cfg_text, kr.replay_text(UNDECLARED_RELATIVE)[0])
    assert rep.print_s == pytest.approx(ours - 2 * E_HALF_STEP_S, abs=2e-3)
    absolute = klippy.run(cfg_text, kr.replay_text(UNDECLARED_RELATIVE, relative_e=False)[0])
    assert absolute.print_s > ours + 0.1


# arcs as Klipper cuts them (gcode_arcs.py planArc): Orca's spiral lifts (one not turned, one a
# full circle of 7 chords), arcs with E, and a junction across an acceleration change
ARCS = ("G90\nM83\nG1 X100 Y100 Z1 F6000\nG1 E1 F1800\n"
        "SET_VELOCITY_LIMIT ACCEL=5000 SQUARE_CORNER_VELOCITY=20\n"
        "G3 Z1.4 I-.427 J1.139 F30000\nG3 Z1.8 I-1.2166 J0 F30000\nG1 X120 Y110 E1 F6000\n"
        "G2 X110 Y120 I-10 J0 E2 F6000\nSET_VELOCITY_LIMIT ACCEL=2000\nG1 X90 Y120 E1\n"
        "G3 X110 Y120 I10 J0 E1 F3000\nG1 E-1 F1800\n")


@needs_klipper
def test_planner_times_arcs_as_klipper(klippy, tmp_path):
    # gatesopt's planner against Klipper's planned steps, from the first extruder step to the
    # last (E-only moves from and to rest at both ends: half an E step each, as above). Before
    # Klipper's arc rules (chords, their average speed, the spiral lift that does not turn, each
    # move's own junction deviation) the planner had this 0.27 s longer than Klipper (2.335 vs 2.064 s)
    cfg_text, ours = _planned_from_first_e_s(ARCS, "arcs.gcode", tmp_path)
    rep = klippy.run(cfg_text, kr.replay_text(ARCS)[0])
    assert rep.print_s == pytest.approx(ours - 2 * E_HALF_STEP_S, abs=5e-3)
