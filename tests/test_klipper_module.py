"""integrations/klipper/gatesopt_gating.py: the Klipper extras module that switches stepper enable
pins at print time (issue 34).

The module's logic runs here against small fakes written to Klipper's documented behaviour (a
look-ahead queue that runs timing callbacks when moves leave it, an EnableTracking whose state
callbacks run before its reference-counted StepperEnablePin is switched, a stepper's active
callbacks); every test asserts exact pin times or counts that a wrong rule would change. The last
tests replay G-code through Klipper's real host (klippy batch mode) with the module installed in
a temp copy, and skip with a reason where no Klipper checkout is configured (GATESOPT_KLIPPER,
GATESOPT_KLIPPY_PYTHON, GATESOPT_KLIPPER_DICT).
"""
from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import REPO

MODULE_PATH = REPO / "integrations" / "klipper" / "gatesopt_gating.py"
BENCH_PATH = REPO / "bench" / "klipper_gating.py"


def _load(name, path):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


gg = _load("gatesopt_gating_under_test", MODULE_PATH)

SA, EL, SCHED = 0.0018, 0.0010, 0.100
LEAD0 = SA + gg.STEP_EARLY_S + gg.CLOCK_SLACK_S        # on_lead without input shaper
DELAY0 = EL + gg.CLOCK_SLACK_S                         # off_delay without input shaper
NEED0 = LEAD0 + DELAY0 + SCHED                         # rule A without input shaper


# ---------------------------------------------------------------- fakes (Klipper's behaviour)

class FakeMove:
    """A planned move: direction ratios, min_move_t, and its planned duration."""
    def __init__(self, axes_r, min_move_t, duration=None):
        self.axes_r = list(axes_r) + [0.0] * (4 - len(axes_r))
        self.min_move_t = min_move_t
        self.accel_t, self.cruise_t, self.decel_t = 0.0, duration if duration is not None else min_move_t, 0.0
        self.timing_callbacks = []


def mx(t, dur=None):
    return FakeMove([1.0, 0.0, 0.0], t, dur)


def my(t, dur=None):
    return FakeMove([0.0, 1.0, 0.0], t, dur)


def mxy(t, dur=None):
    return FakeMove([0.6, 0.8, 0.0], t, dur)


def me(t, dur=None):
    return FakeMove([0.0, 0.0, 0.0, 1.0], t, dur)


class FakeToolhead:
    """Look-ahead queue: moves wait until process()/flush; leaving it they get print times
    end to end and their timing callbacks run with their end time (toolhead._process_lookahead)."""
    def __init__(self):
        self.queue = []
        self.print_time = 1.0
        self.core = None
        self.dwells = []

    def move(self, move):          # toolhead.move -> lookahead.add_move (wrapped by the module)
        self.queue.append(move)
        self.core.note_move(move)

    def process(self, count=None):
        count = len(self.queue) if count is None else count
        moves, self.queue = self.queue[:count], self.queue[count:]
        for m in moves:
            self.print_time += m.accel_t + m.cruise_t + m.decel_t
            for cb in m.timing_callbacks:
                cb(self.print_time)

    def register_lookahead_callback(self, cb):
        if not self.queue:
            cb(self.get_last_move_time())
            return
        self.queue[-1].timing_callbacks.append(cb)

    def get_last_move_time(self):
        self.process()
        return self.print_time

    def dwell(self, delay):
        self.process()
        self.dwells.append(delay)
        self.print_time += max(0.0, delay)


class FakeMcu:
    """An MCU whose clock is the print time (1 tick a second: pin times compare exactly); config
    callbacks and move-queue slot requests as klippy/mcu.py's MCUConfigHelper takes them."""
    def __init__(self):
        self.est = 0.0
        self.config_callbacks, self.reserved_slots, self.finalized = [], 0, False

    def estimated_print_time(self, eventtime):
        return self.est

    def min_schedule_time(self):
        return SCHED

    def print_time_to_clock(self, print_time):
        return print_time

    def seconds_to_clock(self, seconds):
        return seconds

    def register_config_callback(self, cb):
        assert not self.finalized, "config callback after the MCU config was built"
        self.config_callbacks.append(cb)

    def request_move_queue_slot(self):
        assert not self.finalized, "move-queue slot requested after the MCU read their count"
        self.reserved_slots += 1

    def finalize_config(self):     # MCUConfigHelper._connect: callbacks, then the slot count is read
        for cb in self.config_callbacks:
            cb()
        self.finalized = True


class FakeCommand:
    """queue_digital_out as serialqueue takes it: every send with its minclock and reqclock."""
    def __init__(self):
        self.sent = []

    def send(self, args, minclock=0, reqclock=0):
        oid, clock, on = args
        self.sent.append({"clock": clock, "value": on, "minclock": minclock, "reqclock": reqclock})


class FakeDigitalOut:
    """MCU_digital_out (klippy/mcu.py): set_digital sends queue_digital_out with minclock = the
    pin's previous change (its _last_clock)."""
    def __init__(self, mcu):
        self.mcu = mcu
        self._oid, self._invert, self._last_clock, self._set_cmd = 7, False, 0, FakeCommand()

    def get_mcu(self):
        return self.mcu

    def set_digital(self, print_time, value):
        clock = self.mcu.print_time_to_clock(print_time)
        self._set_cmd.send([self._oid, clock, (not not value) ^ self._invert],
                           minclock=self._last_clock, reqclock=clock)
        self._last_clock = clock

    @property
    def events(self):
        ev = [(m["clock"], int(m["value"])) for m in self._set_cmd.sent]
        times = [t for t, _ in ev]
        # one digital_out takes its events in increasing clock (the MCU's queue is FIFO)
        assert times == sorted(times), "pin event out of order"
        return ev


class FakePin:
    """StepperEnablePin: reference counted; the pin changes when the count crosses zero."""
    def __init__(self, mcu, dedicated=True, has_pin=True):
        self.mcu_enable = FakeDigitalOut(mcu) if has_pin else None
        self.enable_count = 0 if has_pin else 9999
        self.is_dedicated = dedicated and has_pin

    def set_enable(self, print_time):
        if not self.enable_count:
            self.mcu_enable.set_digital(print_time, 1)
        self.enable_count += 1

    def set_disable(self, print_time):
        self.enable_count -= 1
        if not self.enable_count:
            self.mcu_enable.set_digital(print_time, 0)


class FakeStepper:
    def __init__(self, name, axes):
        self.name, self.axes, self.active_cbs = name, axes, []

    def get_name(self):
        return self.name

    def is_active_axis(self, a):
        return a in self.axes

    def add_active_callback(self, cb):
        self.active_cbs.append(cb)

    def fire_active(self, print_time):   # itersolve_check_active found an active move
        cbs, self.active_cbs = self.active_cbs, []
        for cb in cbs:
            cb(print_time)


class FakeTracking:
    """EnableTracking: state callbacks run before the pin changes; a disable arms the
    auto-enable (an active callback)."""
    def __init__(self, stepper, pin):
        self.stepper, self.enable, self.callbacks, self.is_enabled = stepper, pin, [], False

    def register_state_callback(self, cb):
        self.callbacks.append(cb)

    def motor_enable(self, print_time):
        if not self.is_enabled:
            for cb in self.callbacks:
                cb(print_time, True)
            self.enable.set_enable(print_time)
            self.is_enabled = True

    def motor_disable(self, print_time):
        if self.is_enabled:
            for cb in self.callbacks:
                cb(print_time, False)
            self.enable.set_disable(print_time)
            self.is_enabled = False
            self.stepper.add_active_callback(self.motor_enable)

    def is_motor_enabled(self):
        return self.is_enabled

    def has_dedicated_enable(self):
        return self.enable.is_dedicated


class Rig:
    """A cartesian printer (X and Y gateable) with the module's core attached; ``slots`` changes of
    a pin queued at once (2: each pin sent through the module's PinQueue)."""
    def __init__(self, margins=None, min_off=0.0, axes=None, spacing=None, slots=1):
        self.mcu = FakeMcu()
        self.th = FakeToolhead()
        self.margins = dict(margins or {"stepper_x": (0.0, 0.0), "stepper_y": (0.0, 0.0)})
        axes = axes or {"stepper_x": "x", "stepper_y": "y"}
        self.steppers, self.tracking = {}, {}
        for name, ax in axes.items():
            s = FakeStepper(name, ax)
            t = FakeTracking(s, FakePin(self.mcu))
            if slots > 1:
                out = t.enable.mcu_enable
                out.set_digital = gg.PinQueue(out, slots).set_digital
            t.motor_enable(0.5)          # Klipper enabled it (homing)
            self.steppers[name], self.tracking[name] = s, t
        self.said = []
        self.core = gg.GatingCore(
            self.th, {n: (self.steppers[n], self.tracking[n]) for n in axes},
            lambda stepper: self.margins[stepper.get_name()],
            lambda pin: self.mcu.est, SCHED, SA, EL, min_off, respond=self.said.append,
            pin_spacing_s=spacing, pin_queue_slots=slots)
        self.th.core = self.core

    def events(self, name):
        """The module's pin changes (Klipper's first enable at 0.5 left out)."""
        return self.tracking[name].enable.mcu_enable.events[1:]

    def count(self, name):
        return self.tracking[name].enable.enable_count


def run_interval(rig, gap_moves, before=None, after=None):
    """X move, GATESOPT_GATE X, gap moves, X move; all processed. Returns (t_end, t_next)."""
    rig.th.move(before or mx(0.5))
    rig.core.command_gate(["stepper_x"])
    for m in gap_moves:
        rig.th.move(m)
    rig.th.move(after or mx(0.3))
    t0 = rig.th.print_time
    rig.th.process()
    t_end = t0 + 0.5 if before is None else None
    return t_end


# ---------------------------------------------------------------- pure helpers

def test_formulas_give_the_documented_times():
    assert gg.off_delay_s(0.015, EL) == pytest.approx(0.015 + EL + 1e-6, abs=1e-15)
    assert gg.on_lead_s(0.02, SA) == pytest.approx(0.02 + SA + 25e-6 + 1e-6, abs=1e-15)
    t_off, t_on = gg.gate_times(10.0, 12.0, 0.02, 0.015, SA, EL)
    assert t_off == pytest.approx(10.016001, abs=1e-12) and t_on == pytest.approx(12.0 - 0.021826, abs=1e-12)
    # rule A: the floor between two events of one pin is max(min_off_time, min_schedule_time)
    assert gg.required_gap_s(0.0, 0.0, SA, EL, 0.0, SCHED) == pytest.approx(NEED0, abs=1e-15)
    assert gg.required_gap_s(0.0, 0.0, SA, EL, 0.5, SCHED) == pytest.approx(NEED0 - SCHED + 0.5, abs=1e-15)


def test_parse_stepper_list():
    assert gg.parse_stepper_list(" stepper_x ,stepper_y,stepper_x") == ["stepper_x", "stepper_y"]
    for bad in ("", "stepper_x,", ",stepper_y", "stepper_x,,stepper_y", "  "):
        with pytest.raises(ValueError):
            gg.parse_stepper_list(bad)


def test_move_activates_follows_itersolve_check_active():
    assert gg.move_activates([0.0, 1.0, 0.0], (1,))
    assert not gg.move_activates([0.0, 1.0, 0.0], (0,))
    assert gg.move_activates([1e-12, 1.0, 0.0], (0,))          # any nonzero ratio steps
    assert gg.move_activates([0.0, 1.0, 0.0], (0, 1))          # corexy: A is active on x and y
    assert not gg.move_activates([0.0, 0.0, 0.0, 1.0], (0, 1, 2))  # extrude-only


def test_enable_refusals_name_the_cause():
    mcu = FakeMcu()
    st_x = FakeStepper("stepper_x", "x")
    kin = {"stepper_x": st_x, "stepper_y": FakeStepper("stepper_y", "y")}
    ok = FakeTracking(st_x, FakePin(mcu))
    assert gg.enable_refusal("stepper_x", kin, ok) is None
    assert "not a kinematic stepper" in gg.enable_refusal("extruder", kin, None)
    assert "no enable_pin" in gg.enable_refusal("stepper_x", kin, FakeTracking(st_x, FakePin(mcu, has_pin=False)))
    assert "shares its enable_pin" in gg.enable_refusal("stepper_x", kin, FakeTracking(st_x, FakePin(mcu, dedicated=False)))


# ---------------------------------------------------------------- decisions and exact pin times

def test_one_interval_exact_pin_times_no_dwell():
    rig = Rig()
    run_interval(rig, [my(0.4), my(0.6)])
    # X move ends at 1.5; the Y moves take 1.0 s; the next X move starts at 2.5
    assert rig.events("stepper_x") == [(pytest.approx(1.5 + DELAY0, abs=1e-12), 0),
                                       (pytest.approx(2.5 - LEAD0, abs=1e-12), 1)]
    assert rig.events("stepper_y") == []
    assert rig.count("stepper_x") == 1 and rig.th.dwells == []
    st = rig.core.status()["steppers"]["stepper_x"]
    assert st["intervals_gated"] == 1 and st["off_time_s"] == pytest.approx(1.0 - DELAY0 - LEAD0, abs=1e-6)


def test_too_short_interval_stays_on_and_is_counted():
    rig = Rig()
    run_interval(rig, [my(NEED0 - 1e-6)])
    assert rig.events("stepper_x") == []
    assert rig.core.status()["steppers"]["stepper_x"]["skipped"]["short"] == 1
    rig2 = Rig()
    run_interval(rig2, [my(NEED0 + 1e-9)])      # just enough
    assert len(rig2.events("stepper_x")) == 2


def test_pin_spacing_option_sets_rules_a_and_b_and_the_event_spacing():
    """min_pin_spacing 0.05: a 0.09 s stretch (rule A's 0.1 s floor skips it) is gated with its
    pin events >= 0.05 s apart; two offs whose on -> off is 0.06 s apart are both gated (rule B at
    0.1 s keeps the second on). The MCU's min_schedule_time still bounds the lead over now."""
    rig = Rig(spacing=0.05)
    run_interval(rig, [my(NEED0 - SCHED + 0.05 + 1e-9)])
    (t_off, v0), (t_on, v1) = rig.events("stepper_x")
    assert (v0, v1) == (0, 1) and 0.05 <= t_on - t_off < SCHED
    rig_default = Rig()
    run_interval(rig_default, [my(NEED0 - SCHED + 0.05 + 1e-9)])
    assert rig_default.events("stepper_x") == []
    for spacing, gated in ((0.05, 2), (None, 1)):
        r = Rig(spacing=spacing)
        run_interval(r, [my(0.5)], after=mx(0.06))
        r.core.command_gate(["stepper_x"])
        r.th.move(my(0.5))
        r.th.move(mx(0.1))
        r.th.process()
        ev = r.events("stepper_x")
        assert len(ev) == 2 * gated
        assert all(b[0] - a[0] >= (spacing or SCHED) - 1e-12 for a, b in zip(ev, ev[1:]))
    rig.mcu.est = 1e6      # an off must still lead the MCU's clock by min_schedule_time
    assert rig.core._earliest_event(rig.core.gates["stepper_x"]) == 1e6 + SCHED


def test_proof_uses_min_move_t_not_the_planned_duration():
    """Short moves that acceleration makes slow prove only their min_move_t."""
    rig = Rig()
    run_interval(rig, [my(0.01, dur=0.2) for _ in range(5)])   # 1.0 s planned, 0.05 s proven
    assert rig.events("stepper_x") == []
    assert rig.core.status()["steppers"]["stepper_x"]["skipped"]["short"] == 1


def test_extrude_only_moves_count_and_do_not_activate():
    rig = Rig()
    run_interval(rig, [me(0.06), me(0.06)])
    assert [v for _, v in rig.events("stepper_x")] == [0, 1]


def test_input_shaper_windows_widen_the_off_and_the_requirement():
    pre, post = 0.0125, 0.0125   # mzv at 30 Hz
    rig = Rig(margins={"stepper_x": (pre, post), "stepper_y": (pre, post)})
    run_interval(rig, [my(0.5)])
    assert rig.events("stepper_x") == [(pytest.approx(1.5 + post + DELAY0, abs=1e-12), 0),
                                       (pytest.approx(2.0 - pre - LEAD0, abs=1e-12), 1)]
    # a gap that proves an interval without the shaper does not with it
    rig2 = Rig(margins={"stepper_x": (pre, post), "stepper_y": (pre, post)})
    run_interval(rig2, [my(NEED0 + 0.01)])
    assert rig2.events("stepper_x") == []


def test_margins_are_reread_and_the_larger_one_used():
    """SET_INPUT_SHAPER between the line and the next X move: the on uses the larger pre."""
    rig = Rig()
    rig.th.move(mx(0.5))
    rig.core.command_gate(["stepper_x"])
    rig.th.move(my(0.5))
    rig.th.process()                                  # off sent with post 0
    rig.margins["stepper_x"] = (0.03, 0.02)
    rig.th.move(mx(0.3))
    rig.th.process()
    assert rig.events("stepper_x")[1][0] == pytest.approx(2.0 - 0.03 - LEAD0, abs=1e-12)


def test_margins_that_shrink_after_the_line_still_count():
    """The window read at the line is kept when the shaper is switched off before the off."""
    rig = Rig(margins={"stepper_x": (0.03, 0.02), "stepper_y": (0.0, 0.0)})
    rig.th.move(mx(0.5))
    rig.core.command_gate(["stepper_x"])
    rig.margins["stepper_x"] = (0.0, 0.0)
    rig.th.move(my(0.5))
    rig.th.move(mx(0.3))
    rig.th.process()
    assert rig.events("stepper_x") == [(pytest.approx(1.5 + 0.02 + DELAY0, abs=1e-12), 0),
                                       (pytest.approx(2.0 - 0.03 - LEAD0, abs=1e-12), 1)]


def test_off_waits_for_the_proof_when_the_lookahead_flushes_first():
    """t_end known before the moves that prove the interval arrive (lazy look-ahead)."""
    rig = Rig()
    rig.th.move(mx(0.5))
    rig.core.command_gate(["stepper_x"])
    rig.th.move(my(0.05))
    rig.th.process()                 # t_end = 1.5 known; 0.05 s proven: no off yet
    assert rig.events("stepper_x") == []
    rig.th.move(my(0.1))             # now proven: the off goes out at t_end's time
    assert rig.events("stepper_x") == [(pytest.approx(1.5 + DELAY0, abs=1e-12), 0)]
    rig.th.move(mx(0.2))
    rig.th.process()
    assert rig.events("stepper_x")[1] == (pytest.approx(1.65 - LEAD0, abs=1e-12), 1)


def test_off_waits_for_t_end_when_the_proof_comes_first():
    rig = Rig()
    rig.th.move(mx(0.5))
    rig.core.command_gate(["stepper_x"])
    rig.th.move(my(0.3))
    rig.th.move(mx(0.2))             # interval closed and proven before any move left the queue
    assert rig.events("stepper_x") == []
    rig.th.process()
    assert rig.events("stepper_x") == [(pytest.approx(1.5 + DELAY0, abs=1e-12), 0),
                                       (pytest.approx(1.8 - LEAD0, abs=1e-12), 1)]


def test_a_window_that_grows_before_t_end_is_checked_again():
    rig = Rig()
    rig.th.move(mx(0.5))
    rig.core.command_gate(["stepper_x"])
    rig.th.move(my(NEED0 + 0.001))
    rig.th.move(mx(0.2))                     # proven with no shaper; t_end not known yet
    rig.margins["stepper_x"] = (0.01, 0.01)
    rig.th.process()
    assert rig.events("stepper_x") == []
    assert rig.core.status()["steppers"]["stepper_x"]["skipped"]["short"] == 1


def test_an_off_whose_time_has_passed_is_never_scheduled():
    rig = Rig()
    rig.th.move(mx(0.5))
    rig.core.command_gate(["stepper_x"])
    rig.th.move(my(0.05))
    rig.th.process()                 # t_end = 1.5, not proven yet
    rig.mcu.est = 1.45               # real time: the MCU is 50 ms before t_off
    rig.th.move(my(0.5))
    rig.th.move(mx(0.2))
    rig.th.process()
    assert rig.events("stepper_x") == []
    assert rig.core.status()["steppers"]["stepper_x"]["skipped"]["late"] == 1


def test_rule_b_spacing_from_the_previous_on():
    # the second interval's off would come < min_schedule_time after the first one's on
    rig = Rig()
    run_interval(rig, [my(0.5)], after=mx(0.05))
    rig.core.command_gate(["stepper_x"])
    rig.th.move(my(0.5))
    rig.th.move(mx(0.1))
    rig.th.process()
    ev = rig.events("stepper_x")
    assert len(ev) == 2 and rig.core.status()["steppers"]["stepper_x"]["skipped"]["spacing"] == 1
    # with a longer active stretch it is gated, and its off is >= min_sched after the last on
    rig2 = Rig()
    run_interval(rig2, [my(0.5)], after=mx(0.1))
    rig2.core.command_gate(["stepper_x"])
    rig2.th.move(my(0.5))
    rig2.th.move(mx(0.1))
    rig2.th.process()
    ev2 = rig2.events("stepper_x")
    assert [v for _, v in ev2] == [0, 1, 0, 1] and ev2[2][0] - ev2[1][0] >= SCHED


# ---------------------------------------------------------------- two queued changes per pin

def mcu_queue_model(sent, spacing):
    """What serialqueue and the MCU make of one pin's queue_digital_out sends (in send order):
    serialqueue.c check_upcoming_queues releases a message once the MCU clock has passed its
    minclock, in FIFO order within the pin's command queue; src/gpiocmds.c queues it and applies
    it at its clock. Returns (least lead: clock - release, most changes pending on the MCU at a
    release); asserts the clocks increase (the MCU's queue is FIFO)."""
    release, lead, pending = [], [], []
    for i, m in enumerate(sent):
        r = max([m["minclock"]] + release[-1:])
        release.append(r)
        assert m["reqclock"] == m["clock"] and (i == 0 or m["clock"] > sent[i - 1]["clock"])
        lead.append(m["clock"] - r)
        pending.append(sum(1 for n in sent[:i + 1] if n["clock"] > r))
    return (min(lead[1:]) if len(lead) > 1 else None), max(pending)


def sends(rig, name):
    return rig.tracking[name].enable.mcu_enable._set_cmd.sent


def test_two_queued_changes_gate_a_short_interval_with_full_lead():
    """pin_queue_slots 2: a 0.03 s stretch of Y moves (rule A is the margins alone) is gated; its
    on goes out with minclock = the change two back (Klipper's enable at 0.5), so the MCU holds two
    changes of the pin and each message still has >= 0.1 s of lead; with one slot it stays on."""
    rig = Rig(slots=2)
    run_interval(rig, [my(0.03)])
    (t_off, v0), (t_on, v1) = rig.events("stepper_x")
    assert (v0, v1) == (0, 1)
    assert t_off == pytest.approx(1.5 + DELAY0, abs=1e-12) and t_on == pytest.approx(1.53 - LEAD0, abs=1e-12)
    sent = sends(rig, "stepper_x")
    assert [m["minclock"] for m in sent] == [0, 0, 0.5]        # two back: none, none, Klipper's enable
    lead, pending = mcu_queue_model(sent, SCHED)
    assert lead >= SCHED and pending == 2
    one = Rig(slots=1)
    run_interval(one, [my(0.03)])
    assert one.events("stepper_x") == [] and one.core.status()["steppers"]["stepper_x"]["skipped"]["short"] == 1
    # the same pin times sent by Klipper's own set_digital (minclock = the last change) would
    # have 0.03 s of lead: the queue is what makes them safe
    assert t_on - t_off < SCHED


@pytest.mark.parametrize("first_gap,active,second_gap,gated,why", [
    (0.5, 0.05, 0.5, 2, ""),              # offs 0.55 s apart, ons 0.55 s apart
    (0.5, 0.02, 0.05, 1, "on"),           # ons 0.02 + 0.05 s apart
    (0.05, 0.02, 0.5, 1, "off"),          # offs 0.05 + 0.02 s apart
    (0.07, 0.04, 0.07, 2, ""),            # offs and ons 0.11 s apart (one slot: both too short)
    (0.07, 0.04, 0.05, 1, "on"),          # ons 0.09 s apart
])
def test_two_queued_rule_b_off_after_off_and_on_after_on(first_gap, active, second_gap, gated, why):
    """Each change waits for the change two back: i's off to j's off and i's on to j's on at least
    the spacing, on the moves' min_move_t; the second interval is skipped for the spacing when
    either is shorter, and every message keeps >= 0.1 s of lead."""
    rig = Rig(slots=2)
    run_interval(rig, [my(first_gap)], after=mx(active))
    rig.core.command_gate(["stepper_x"])
    rig.th.move(my(second_gap))
    rig.th.move(mx(0.1))
    rig.th.process()
    ev = rig.events("stepper_x")
    assert len(ev) == 2 * gated
    assert rig.core.status()["steppers"]["stepper_x"]["skipped"]["spacing"] == 2 - gated
    lead, pending = mcu_queue_model(sends(rig, "stepper_x"), SCHED)
    assert lead >= SCHED - 1e-12 and pending <= 2


def test_two_queued_rule_b_counts_min_move_t_as_the_solver_does():
    """Slow moves (planned 0.2 s, min_move_t 0.02 and 0.05 s): the ons are 0.4 s apart in print
    time but 0.07 s on the lower-bound clock, which is all gatesopt's solver can know: the module
    skips the second interval as the solver and the verifier say it will."""
    rig = Rig(slots=2)
    run_interval(rig, [my(0.5)], after=mx(0.02, dur=0.2))
    rig.core.command_gate(["stepper_x"])
    rig.th.move(my(0.05, dur=0.2))
    rig.th.move(mx(0.1))
    rig.th.process()
    assert len(rig.events("stepper_x")) == 2
    assert rig.core.status()["steppers"]["stepper_x"]["skipped"]["spacing"] == 1


def test_two_queued_after_a_forced_on_the_on_is_proven_in_real_time():
    """After SET_GATESOPT_GATING ENABLE=0/1 the pin's last change (the forced on) is tied to no
    move, so rule B cannot be counted on the lower-bound clock; the next off is sent only if its on
    can still come 0.1 s after that change (else the on would be late: a step while off)."""
    for second_gap, gated in ((0.03, False), (0.3, True)):
        rig = Rig(slots=2)
        rig.th.move(mx(0.5))
        rig.core.command_gate(["stepper_x"])
        rig.th.move(my(0.5))
        rig.th.process()
        assert rig.core.force_on(["stepper_x"]) == 1
        rig.th.move(mx(0.02))
        rig.core.command_gate(["stepper_x"])
        rig.th.move(my(second_gap))
        rig.th.move(mx(0.1))
        rig.th.process()
        st = rig.core.status()["steppers"]["stepper_x"]
        assert st["late_enables"] == 0 and st["intervals_gated"] == 1 + gated
        assert st["skipped"]["spacing"] == (not gated)
        lead, pending = mcu_queue_model(sends(rig, "stepper_x"), SCHED)
        assert lead >= SCHED - 1e-12 and pending <= 2


def test_repeated_line_and_two_steppers_in_one_line():
    rig = Rig()
    rig.th.move(mxy(0.5))
    rig.core.command_gate(["stepper_x", "stepper_y"])
    rig.core.command_gate(["stepper_x"])                 # no X move since: already covered
    rig.th.move(me(0.5))
    rig.th.move(mx(0.1))
    rig.th.move(my(0.1))
    rig.th.process()
    assert [v for _, v in rig.events("stepper_x")] == [0, 1]
    assert rig.events("stepper_y")[1][0] == pytest.approx(1.0 + 0.5 + 0.5 + 0.1 - LEAD0, abs=1e-12)
    assert rig.core.status()["steppers"]["stepper_x"]["skipped"]["repeated"] == 1


def test_corexy_stepper_is_activated_by_a_y_only_move():
    rig = Rig(axes={"stepper_x": "xy", "stepper_y": "xy"})
    run_interval(rig, [my(0.5)])
    assert rig.events("stepper_x") == []
    assert rig.core.status()["steppers"]["stepper_x"]["skipped"]["short"] == 1


def test_disabled_gating_and_klipper_disabled_stepper_do_nothing():
    rig = Rig()
    rig.core.gates["stepper_x"].enabled = False
    run_interval(rig, [my(1.0)])
    assert rig.events("stepper_x") == []
    rig.core.gates["stepper_x"].enabled = True
    rig.tracking["stepper_x"].motor_disable(rig.th.get_last_move_time() + 0.1)
    run_interval(rig, [my(1.0)])
    skipped = rig.core.status()["steppers"]["stepper_x"]["skipped"]
    assert skipped["disabled"] == 1 and skipped["motor_off"] == 1
    assert [v for _, v in rig.events("stepper_x")] == [0]     # only Klipper's own disable


# ---------------------------------------------------------------- Klipper's bookkeeping

def test_motor_off_while_gated_sends_nothing_and_keeps_the_count():
    rig = Rig()
    rig.th.move(mx(0.5))
    rig.core.command_gate(["stepper_x"])
    rig.th.move(my(0.5))
    rig.th.process()                                       # off sent, next X move unknown
    t_off = rig.events("stepper_x")[0][0]
    tr = rig.tracking["stepper_x"]
    pt = rig.th.get_last_move_time() + 0.1                 # M84: flush, dwell DISABLE_STALL_TIME
    tr.motor_disable(pt)
    rig.core.motor_off_done()
    assert not tr.is_motor_enabled() and rig.events("stepper_x") == [(t_off, 0)]
    rig.th.move(mx(0.2))                                   # the interval was cancelled: no "on"
    rig.th.process()
    assert rig.events("stepper_x") == [(t_off, 0)] and rig.count("stepper_x") == 0
    tr.stepper.fire_active(rig.th.print_time)              # Klipper's auto-enable
    assert rig.events("stepper_x")[-1][1] == 1 and rig.count("stepper_x") == 1 and tr.is_motor_enabled()
    # Y was not gated: Klipper's disable is an ordinary pin change
    rig.tracking["stepper_y"].motor_disable(pt)
    assert rig.events("stepper_y") == [(pt, 0)] and rig.count("stepper_y") == 0


def test_set_stepper_enable_0_then_1_while_gated():
    rig = Rig()
    rig.th.move(mx(0.5))
    rig.core.command_gate(["stepper_x"])
    rig.th.move(my(0.5))
    rig.th.process()
    tr = rig.tracking["stepper_x"]
    pt = rig.th.get_last_move_time() + 0.1
    tr.motor_disable(pt)
    assert rig.count("stepper_x") == -1       # Klipper's set_disable found it at 0: no message
    tr.motor_enable(pt + 0.2)                 # the module sets it back to 0 first
    assert rig.count("stepper_x") == 1 and rig.events("stepper_x")[-1] == (pt + 0.2, 1)


def test_homing_switches_every_gated_stepper_on_before_it_moves():
    rig = Rig()
    rig.th.move(mx(0.5))
    rig.core.command_gate(["stepper_x"])
    rig.th.move(my(0.5))
    rig.th.process()
    t_off = rig.events("stepper_x")[0][0]
    rig.core.command_gate(["stepper_y"])       # open, not proven: must never be sent
    before = rig.th.print_time
    assert rig.core.force_on() == 1            # homing:home_rails_begin
    t_on = max(before, t_off + SCHED)
    assert rig.events("stepper_x") == [(t_off, 0), (pytest.approx(t_on, abs=1e-12), 1)]
    assert rig.th.print_time == pytest.approx(t_on + LEAD0, abs=1e-12)   # dwelt until on + lead
    rig.th.move(my(0.5))
    rig.th.move(mx(0.5))
    rig.th.process()
    assert len(rig.events("stepper_x")) == 2 and rig.events("stepper_y") == []
    assert rig.count("stepper_x") == 1 and rig.count("stepper_y") == 1
    assert rig.core.force_on() == 0 and len(rig.th.dwells) == 1   # nothing gated: no dwell


def test_force_on_lets_a_queued_activating_move_switch_on_at_its_own_time():
    rig = Rig()
    rig.th.move(mx(0.5))
    rig.core.command_gate(["stepper_x"])
    rig.th.move(my(0.5))
    rig.th.process()
    rig.th.move(mx(0.2))                       # queued, not yet planned
    assert rig.core.force_on() == 0 and rig.th.dwells == []
    assert rig.events("stepper_x")[1] == (pytest.approx(2.0 - LEAD0, abs=1e-12), 1)


def test_safety_net_enables_a_stepper_moved_by_an_unseen_path():
    rig = Rig()
    rig.th.move(mx(0.5))
    rig.core.command_gate(["stepper_x"])
    rig.th.move(my(0.5))
    rig.th.process()
    st_x = rig.steppers["stepper_x"]
    assert len(st_x.active_cbs) == 1
    st_x.fire_active(1.2)                      # the move before the line: nothing to do, re-armed
    assert len(rig.events("stepper_x")) == 1 and len(st_x.active_cbs) == 1
    st_x.fire_active(2.5)                      # something stepped X without the look-ahead
    ev = rig.events("stepper_x")
    assert ev[1] == (pytest.approx(max(2.5 - LEAD0, ev[0][0] + SCHED), abs=1e-12), 1)
    assert rig.core.status()["late_safety_enables"] == 1 and rig.said and rig.said[0].startswith("!! ")
    rig.th.move(mx(0.2))
    rig.th.process()
    assert len(rig.events("stepper_x")) == 2 and rig.count("stepper_x") == 1


def test_safety_net_quiet_on_the_normal_activating_move():
    rig = Rig()
    run_interval(rig, [my(0.5)])
    rig.steppers["stepper_x"].fire_active(2.0)
    assert rig.core.status()["late_safety_enables"] == 0 and len(rig.events("stepper_x")) == 2


# ---------------------------------------------------------------- property: never a step while off

def _steps_windows(timeline, pre, post):
    """Per stepper, the intervals in which it may step: [start - pre, end + post] of each
    activating move."""
    return {name: [(s - pre, e + post) for s, e, act in timeline if name in act]
            for name in ("stepper_x", "stepper_y")}


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["x", "y", "xy", "e", "gx", "gy", "gxy", "flush"]),
                          st.floats(0.001, 0.4)), min_size=1, max_size=60),
       st.sampled_from([(0.0, 0.0), (0.0125, 0.0125), (0.03, 0.02)]), st.sampled_from([1, 2]))
def test_no_step_while_off_and_pin_events_well_spaced(ops, margins, slots):
    """Random moves, lines and look-ahead flushes: no step window overlaps an off (margins
    counted), the planned time is untouched, and each change of a pin comes >= the spacing after
    the change ``slots`` back: the MCU never holds more than ``slots`` changes of the pin and each
    message has >= 0.1 s of lead when serialqueue releases it."""
    rig = Rig(margins={"stepper_x": margins, "stepper_y": margins}, slots=slots)
    timeline = []                               # (start, end, active steppers) per move
    th = rig.th

    def track(m, active):
        def cb(end, m=m, active=active):
            timeline.append((end - m.cruise_t, end, active))
        m.timing_callbacks.append(cb)

    for op, t in ops:
        if op == "flush":
            th.process(len(th.queue) // 2)
        elif op.startswith("g"):
            rig.core.command_gate(["stepper_" + a for a in op[1:]])
        else:
            axes_r = [1.0 if "x" in op else 0.0, 1.0 if "y" in op else 0.0, 0.0, 1.0 if op == "e" else 0.0]
            m = FakeMove(axes_r, t, t * 1.5)
            th.move(m)
            track(m, {"stepper_" + a for a in op if a in "xy"})
    th.move(mxy(0.1))
    track(th.queue[-1], {"stepper_x", "stepper_y"})
    th.process()
    pre, post = margins
    windows = _steps_windows(timeline, pre, post)
    for name in ("stepper_x", "stepper_y"):
        ev = rig.events(name)
        times = [t for t, _ in ev]
        assert times == sorted(times)
        assert all(b - a >= SCHED - 1e-12 for a, b in zip(times, times[slots:]))
        lead, pending = mcu_queue_model(sends(rig, name), SCHED)
        assert (lead is None or lead >= SCHED - 1e-12) and pending <= slots
        assert [v for _, v in ev] == [0, 1] * (len(ev) // 2)     # off/on pairs, ends on
        for (t_off, _), (t_on, _) in zip(ev[0::2], ev[1::2]):
            for lo, hi in windows[name]:
                # no step window overlaps [t_off - end_late, t_on + start_ahead]
                assert hi + EL <= t_off + 1e-12 or lo - SA >= t_on - 1e-12
        assert rig.count(name) == 1
    assert th.dwells == []                                           # planned time untouched


# ---------------------------------------------------------------- the Klipper glue (config, commands)

class ConfigError(Exception):
    pass


class CommandError(Exception):
    pass


class FakeConfig:
    error = ConfigError

    def __init__(self, printer, options):
        self.printer, self.options = printer, options

    def get_printer(self):
        return self.printer

    def get_name(self):
        return "gatesopt_gating"

    def get(self, name, default=None):
        return self.options.get(name, default)

    def getfloat(self, name, default=None, minval=None, maxval=None):
        v = float(self.options.get(name, default))
        if (minval is not None and v < minval) or (maxval is not None and v > maxval):
            raise ConfigError("Option '%s' out of range" % name)
        return v

    def getint(self, name, default=None, minval=None, maxval=None):
        try:
            v = int(self.options.get(name, default))      # configfile.py: int(), no "2.0"
        except ValueError:
            raise ConfigError("Unable to parse option '%s'" % name) from None
        if (minval is not None and v < minval) or (maxval is not None and v > maxval):
            raise ConfigError("Option '%s' out of range" % name)
        return v


class FakeGcmd:
    error = CommandError

    def __init__(self, params):
        self.params, self.said = params, []

    def get(self, name, default=KeyError):
        if name in self.params:
            return self.params[name]
        if default is KeyError:
            raise CommandError("Error on '%s': missing %s" % ("cmd", name))
        return default

    def get_int(self, name, default=KeyError, minval=None, maxval=None):
        v = int(self.get(name, default))
        if (minval is not None and v < minval) or (maxval is not None and v > maxval):
            raise CommandError("out of range")
        return v

    def respond_info(self, msg):
        self.said.append(msg)


class FakePrinter:
    config_error = ConfigError
    command_error = CommandError

    def __init__(self, steppers, pins):
        self.mcu = FakeMcu()
        self.th = FakeToolhead()
        self.th.lookahead = type("LA", (), {"add_move": lambda self_, m: self.th.queue.append(m)})()
        kin = type("Kin", (), {"get_steppers": lambda self_: list(steppers.values())})()
        self.th.get_kinematics = lambda: kin
        self.tracking = {n: FakeTracking(s, pins[n]) for n, s in steppers.items()}
        for t in self.tracking.values():
            t.motor_enable(0.5)
        se = type("SE", (), {})()

        def lookup_enable(name):        # stepper_enable.py: an unknown name is a config error
            if name not in self.tracking:
                raise ConfigError("Unknown stepper '%s'" % (name,))
            return self.tracking[name]
        se.lookup_enable = lookup_enable
        self.commands, self.handlers = {}, {}
        gcode = type("G", (), {})()
        gcode.register_command = lambda name, fn, desc=None: self.commands.__setitem__(name, fn)
        gcode.respond_raw = lambda msg: None
        self.objects = {"toolhead": self.th, "stepper_enable": se, "gcode": gcode}

    def get_reactor(self):
        return type("R", (), {"monotonic": lambda self_: 0.0})()

    def lookup_object(self, name, default=KeyError):
        if name in self.objects:
            return self.objects[name]
        if default is KeyError:
            raise ConfigError(name)
        return default

    def register_event_handler(self, event, fn):
        self.handlers.setdefault(event, []).append(fn)

    def lookup_objects(self, module=None):
        return [("mcu", self.mcu)] if module == "mcu" else []

    def send_event(self, event, *args):
        if event == "klippy:connect" and not self.mcu.finalized:
            self.mcu.finalize_config()      # the MCU's own connect handler runs first
        for fn in self.handlers.get(event, []):
            fn(*args)


def make_printer(pins=None, options=None):
    mcu = FakeMcu()
    steppers = {n: FakeStepper(n, a) for n, a in (("stepper_x", "x"), ("stepper_y", "y"), ("stepper_z", "z"))}
    pins = pins or {}
    pins = {n: pins.get(n) or FakePin(mcu) for n in steppers}
    for p in pins.values():
        if p.mcu_enable is not None:
            p.mcu_enable.mcu = mcu
    printer = FakePrinter(steppers, pins)
    printer.mcu = mcu
    module = gg.load_config(FakeConfig(printer, options or {}))
    return printer, module


def test_config_defaults_and_ranges():
    printer, module = make_printer()
    assert module.names == ["stepper_x", "stepper_y"]
    assert (module.start_ahead_s, module.end_late_s, module.min_off_s) == (0.0018, 0.0010, 0.0)
    assert module.pin_spacing_s == gg.DEFAULT_PIN_SPACING_S == 0.1
    printer.send_event("klippy:connect")
    assert module.core.pin_spacing_s == 0.1 and module.core.min_sched_s == SCHED
    printer2, module2 = make_printer(options={"min_pin_spacing": "0.04"})
    printer2.send_event("klippy:connect")
    assert module2.core.pin_spacing_s == 0.04
    for bad in ("0.02", "1.5"):
        with pytest.raises(ConfigError):
            make_printer(options={"min_pin_spacing": bad})
    with pytest.raises(ConfigError):
        make_printer(options={"end_late": "0.2"})
    with pytest.raises(ConfigError):
        make_printer(options={"steppers": "stepper_x,,stepper_y"})
    assert set(printer.commands) == {"GATESOPT_GATE", "SET_GATESOPT_GATING", "GATESOPT_GATING_STATUS"}


def test_pin_queue_option_reserves_slots_and_sends_every_change_through_the_queue():
    """pin_queue_slots (default 2): one move-queue slot more per gated enable pin, requested from the
    MCU's config callback (before the MCU reads the count), each pin's set_digital replaced by a
    PinQueue -- Klipper's own changes (auto-enable, M84) go through it too and keep the pin's
    _last_clock; 1 is Klipper's own set_digital and no slot; other values are config errors."""
    printer, module = make_printer()
    assert module.pin_queue_slots == gg.DEFAULT_PIN_QUEUE_SLOTS == 2
    assert printer.mcu.reserved_slots == 0          # not before the MCU builds its config
    printer.send_event("klippy:connect")
    assert printer.mcu.reserved_slots == 2 and module.core.pin_queue_slots == 2
    assert sorted(module.queues) == ["stepper_x", "stepper_y"]
    out = printer.tracking["stepper_x"].enable.mcu_enable
    assert out.set_digital == module.queues["stepper_x"].set_digital
    # Klipper's own M84 and auto-enable: through the queue, minclock = the change two back
    printer.tracking["stepper_x"].motor_disable(3.0)
    printer.tracking["stepper_x"].motor_enable(3.5)
    assert [m["minclock"] for m in out._set_cmd.sent] == [0, 0, 0.5] and out._last_clock == 3.5
    st = module.get_status(0)
    assert st["pin_queue_slots"] == 2 and st["steppers"]["stepper_x"]["pin_changes_sent"] == 2
    assert st["steppers"]["stepper_x"]["pin_lead_min_s"] == 3.0      # 3.5 - 0.5 (the first: minclock 0)
    assert mcu_queue_model(out._set_cmd.sent, SCHED) == (3.0, 2)
    one_printer, one = make_printer(options={"pin_queue_slots": "1"})
    one_printer.send_event("klippy:connect")
    assert one_printer.mcu.reserved_slots == 0 and one.queues == {} and one.core.pin_queue_slots == 1
    for bad in ("0", "3", "2.0"):
        with pytest.raises(ConfigError):
            make_printer(options={"pin_queue_slots": bad})
    # a Klipper whose MCU_digital_out lacks what the queue sends with: refused at start-up
    printer, module = make_printer()
    del printer.tracking["stepper_y"].enable.mcu_enable._set_cmd
    with pytest.raises(ConfigError, match="pin_queue_slots: 2: stepper_y: .*_set_cmd"):
        printer.send_event("klippy:connect")


@pytest.mark.parametrize("options,pins,message", [
    ({"steppers": "stepper_x, extruder"}, None, "not a kinematic stepper"),
    (None, {"stepper_y": FakePin(FakeMcu(), has_pin=False)}, "no enable_pin"),
    (None, {"stepper_x": FakePin(FakeMcu(), dedicated=False)}, "shares its enable_pin"),
])
def test_startup_refusals_are_config_errors(options, pins, message):
    printer, module = make_printer(pins=pins, options=options)
    with pytest.raises(ConfigError, match=message):
        printer.send_event("klippy:connect")


def test_commands_validate_and_control_gating(monkeypatch):
    # chelper's itersolve window, as a cartesian stepper without input shaper reports it
    monkeypatch.setattr(gg, "stepper_margins", lambda stepper: (0.0, 0.0))
    printer, module = make_printer(options={"steppers": "stepper_x, stepper_y, stepper_z"})
    printer.send_event("klippy:connect")
    gate = printer.commands["GATESOPT_GATE"]
    for params in ({}, {"STEPPERS": ""}, {"STEPPERS": "stepper_x,"}, {"STEPPERS": "stepper_q"},
                   {"STEPPERS": "extruder"}):
        with pytest.raises(CommandError):
            gate(FakeGcmd(params))
    setg = printer.commands["SET_GATESOPT_GATING"]
    with pytest.raises(CommandError):
        setg(FakeGcmd({"ENABLE": "2"}))
    with pytest.raises(CommandError):
        setg(FakeGcmd({"STEPPER": "stepper_q", "ENABLE": "0"}))
    # the wrapped look-ahead feeds the core; a gated X is switched on by ENABLE=0
    th, la = printer.th, printer.th.lookahead
    la.add_move(mx(0.5))
    gate(FakeGcmd({"STEPPERS": "stepper_x"}))
    la.add_move(my(0.5))
    th.process()
    assert module.core.gates["stepper_x"].pin_off
    g = FakeGcmd({"STEPPER": "stepper_x", "ENABLE": "0"})
    setg(g)
    assert not module.core.gates["stepper_x"].pin_off and "disabled" in g.said[0]
    la.add_move(mx(0.5))
    gate(FakeGcmd({"STEPPERS": "stepper_x"}))
    la.add_move(my(1.0))
    la.add_move(mx(0.5))
    th.process()
    assert module.get_status(0)["steppers"]["stepper_x"]["skipped"]["disabled"] == 1
    setg(FakeGcmd({"ENABLE": "1"}))
    status = FakeGcmd({})
    printer.commands["GATESOPT_GATING_STATUS"](status)
    assert "stepper_x: enabled; gated 1; off" in status.said[0] and "forced on 1" in status.said[0]
    # homing and motor_off events reach the core
    la.add_move(mx(0.5))
    gate(FakeGcmd({"STEPPERS": "stepper_x"}))
    la.add_move(my(1.0))
    th.process()
    printer.send_event("homing:home_rails_begin", None, [])
    assert not module.core.gates["stepper_x"].pin_off


# ---------------------------------------------------------------- Klipper's supported Pythons

def test_module_is_python2_syntax(tmp_path):
    """klippy still runs on Python 2.7 (klippy.py's shebang): the module must compile there."""
    env = dict(os.environ)
    if shutil.which("pyenv"):   # a pyenv shim runs only with a 2.7 version selected
        versions = subprocess.run(["pyenv", "versions", "--bare"], capture_output=True, text=True).stdout
        v27 = [v for v in versions.split() if v.startswith("2.7")]
        if v27:
            env["PYENV_VERSION"] = v27[-1]
    py2 = shutil.which("python2.7") or shutil.which("python2")
    if py2 is None or subprocess.run([py2, "-c", "1"], capture_output=True, env=env).returncode != 0:
        pytest.skip("no Python 2.7 interpreter on this machine")
    dst = tmp_path / "gatesopt_gating.py"
    shutil.copy(MODULE_PATH, dst)
    run = subprocess.run([py2, "-m", "py_compile", str(dst)], capture_output=True, text=True, env=env)
    assert run.returncode == 0, run.stderr


# ---------------------------------------------------------------- Klipper's real host (batch mode)

kg = _load("klipper_gating_bench", BENCH_PATH)
SETUP = kg.klipper_setup()
needs_klipper = pytest.mark.skipif(
    SETUP is None, reason="no Klipper checkout (GATESOPT_KLIPPER, GATESOPT_KLIPPY_PYTHON, GATESOPT_KLIPPER_DICT)")

SMALL_GCODE = """\
G28
G90
G1 Z1 F600
G1 X10 Y10 F6000
G1 X100 F6000
GATESOPT_GATE STEPPERS=stepper_x
G1 Y100 F3000
G1 Y20
G1 E2 F1200
G1 X50 F6000
GATESOPT_GATE STEPPERS=stepper_y
G1 X150 F6000
G1 X20
G1 Y60 F6000
GATESOPT_GATE STEPPERS=stepper_x
G1 Y62
G1 X22
G1 X40 Y40
GATESOPT_GATE STEPPERS=stepper_x,stepper_y
G1 Z5 F300
G1 E4 F1200
G1 X60 Y60 F6000
GATESOPT_GATING_STATUS
"""


@pytest.fixture(scope="module")
def klippy_dir(tmp_path_factory):
    return kg.prepare_klippy(SETUP[0], tmp_path_factory.mktemp("klippy"))


@needs_klipper
@pytest.mark.parametrize("slots", [1, 2], ids=["one_queued", "two_queued"])
@pytest.mark.parametrize("shaper", [False, True], ids=["no_shaper", "mzv30"])
def test_klippy_batch_replay(klippy_dir, tmp_path, shaper, slots):
    """Klipper's own host: the planned time unchanged, no step while off, the margins kept, and
    every change of a pin at least the spacing after the change ``pin_queue_slots`` back (the
    lead its message has when serialqueue releases it). With one change in flight X's short
    interval (Y62 then X22: 0.02 s) stays on; with two it is gated (without a shaper)."""
    _, python, mcu_dict = SETUP
    cfg = kg.PRINTER_CFG + (kg.SHAPER_CFG if shaper else "")
    plain = "".join(ln + "\n" for ln in SMALL_GCODE.splitlines() if not ln.startswith("GATESOPT"))
    base = kg.run_klippy(klippy_dir, python, mcu_dict, cfg, plain, tmp_path, "base")
    gating_cfg = kg.GATING_CFG + f"pin_queue_slots: {slots}\n"
    gated = kg.run_klippy(klippy_dir, python, mcu_dict, cfg + gating_cfg, SMALL_GCODE, tmp_path, "gated")
    # planned print time unchanged: every step of every stepper at the same clock
    assert kg.planned_time_diff_s(base, gated) <= 1e-6
    status = kg.gating_status(gated)
    # X's short interval: 0.02 s of Y moves; with mzv 30 Hz the margins alone are 0.028 s
    short_gated = slots == 2 and not shaper
    assert status["stepper_x"]["gated"] == 2 + short_gated and status["stepper_y"]["gated"] == 2
    assert status["stepper_x"]["skipped"] == ({} if short_gated else {"short": 1})
    for name in ("stepper_x", "stepper_y"):
        m = kg.pin_metrics(gated, name)
        assert m["offs"] == status[name]["gated"]
        assert m["steps_while_off"] == 0
        assert m["start_ahead_min_s"] >= 0.0018 and m["end_late_min_s"] >= 0.0010
        q = kg.pin_queue_metrics(gated, name, slots)
        assert q["ordered"] and q["lead_min_s"] >= 0.1 - 1e-6
        if short_gated and name == "stepper_x":   # X's short interval needs the queue
            assert kg.pin_queue_metrics(gated, name, 1)["lead_min_s"] < 0.1
    assert "steps_while_off" in kg.pin_metrics(base, "stepper_x")


@needs_klipper
def test_without_the_module_klipper_skips_the_lines(klippy_dir, tmp_path):
    _, python, mcu_dict = SETUP
    plain = "".join(ln + "\n" for ln in SMALL_GCODE.splitlines() if not ln.startswith("GATESOPT"))
    base = kg.run_klippy(klippy_dir, python, mcu_dict, kg.PRINTER_CFG, plain, tmp_path, "base")
    lines = kg.run_klippy(klippy_dir, python, mcu_dict, kg.PRINTER_CFG, SMALL_GCODE, tmp_path, "lines")
    assert 'Unknown command:"GATESOPT_GATE"' in lines.log
    assert kg.planned_time_diff_s(base, lines) == 0.0
    assert lines.enable == base.enable


def test_insert_gate_lines_after_the_last_move_of_an_axis():
    text = "G28\nG90\nG1 X1 Y1\nG1 X2\nG1 X2 Y3 E1\nG1 E2\nG1 X5 Y3\nG91\nG1 Y1\nG1 Y1\nG1 X1\n"
    out, added = kg.insert_gate_lines(text)
    assert out.splitlines() == [
        "G28", "G90", "G1 X1 Y1", "GATESOPT_GATE STEPPERS=stepper_y", "G1 X2",
        "GATESOPT_GATE STEPPERS=stepper_x", "G1 X2 Y3 E1", "GATESOPT_GATE STEPPERS=stepper_y",
        "G1 E2", "G1 X5 Y3", "GATESOPT_GATE STEPPERS=stepper_x", "G91", "G1 Y1", "G1 Y1",
        "GATESOPT_GATE STEPPERS=stepper_y", "G1 X1"]
    assert added == 5
