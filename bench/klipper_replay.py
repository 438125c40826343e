"""Proof from the real thing (issue 34): G-code through Klipper's own host, the MCU stream decoded.

Klipper's host (klippy) runs in batch mode on a printer described by bench/klipper/printer.cfg:
``klippy.py printer.cfg -i in.gcode -o out.serial -d mcu.dict`` plans every move exactly as on a
printer (look-ahead, input shaper, step compression) and writes the commands it would send to the
MCU. This bench decodes that stream (the binary itself, or ``parsedump.py`` text) into absolute step
clocks per stepper and enable-pin changes, and measures what gatesopt's gating does in Klipper's
real planner: planned print time, steps sent while a motor's enable pin is off, start-ahead and
end-late, off time per motor against gatesopt's own report.

    python bench/klipper_replay.py run --files 'real_slic3r131_stars.gcode' \\
        --firmware 3dgates,klipper,marlin --solve-args=--no-order --solve-args= \\
        --input-shaper none,mzv:30 [--module PATH] [--write]
    python bench/klipper_replay.py replay FILE.gcode [--input-shaper mzv:30]   # one file, no solve
    python bench/klipper_replay.py config [--input-shaper mzv:30]             # the printer.cfg used

Klipper is never built here: it needs a checkout of Klipper3d/klipper (``--klipper`` or
$GATESOPT_KLIPPER), a Python that runs klippy (``--python`` or $GATESOPT_KLIPPY_PYTHON: cffi,
greenlet, jinja2, pyserial) and an MCU data dictionary (``--dict`` or $GATESOPT_KLIPPER_DICT: the
``out/klipper.dict`` a firmware build for a test MCU leaves, e.g. ``make`` with
test/configs/atmega2560.config). The checkout is only read: klippy runs from a temporary copy of
its ``klippy/`` folder (where it compiles its C helper, and where ``--module`` links an extras
module; our bench/klipper/gatesopt_replay_drain.py is always linked, it holds klippy's exit until
the stream is written).

The decode functions (``decode_serial``, ``parse_dump``, ``decode_stream``, ``steps_before``,
``off_intervals``, ``stepper_replay``, ``replay_metrics``) are pure functions over numpy arrays.
"""
from __future__ import annotations

import argparse
import configparser
import dataclasses
import gzip
import glob
import json
import math
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "instances"
BASE_CONFIG = Path(__file__).resolve().parent / "klipper" / "printer.cfg"
# our extras module that holds klippy's exit until the MCU stream is written (see its header)
DRAIN_MODULE = Path(__file__).resolve().parent / "klipper" / "gatesopt_replay_drain.py"
#: logs where batch mode restarts the print clock later than a printer would after a flush
CLOCK_MODULE = Path(__file__).resolve().parent / "klipper" / "gatesopt_replay_clock.py"
RESULTS = REPO / "docs" / "RESULTS.md"
SECTION = "## Klipper replay: gating in Klipper's own planner"

ENV_KLIPPER, ENV_PYTHON, ENV_DICT = "GATESOPT_KLIPPER", "GATESOPT_KLIPPY_PYTHON", "GATESOPT_KLIPPER_DICT"
STEPPERS = ("stepper_x", "stepper_y", "stepper_z", "extruder")
MOTOR_OF = {"stepper_x": "X", "stepper_y": "Y", "stepper_z": "Z", "extruder": "E"}
CLOCK32 = 1 << 32
OPEN_END = np.iinfo(np.int64).max  # the end clock of an off interval that never ends


class ReplayError(RuntimeError):
    """klippy could not replay a file (its own error message), or the stream cannot be decoded."""


# --------------------------------------------------------------------------------------------
# Where Klipper is
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class KlipperHost:
    """A Klipper checkout (read only), the Python that runs its klippy, an MCU data dictionary."""
    klipper_dir: Path
    python: Path
    dictionary: Path


def find_host(klipper: str | None = None, python: str | None = None,
              dictionary: str | None = None) -> KlipperHost | str:
    """The Klipper host from the options or $GATESOPT_KLIPPER, $GATESOPT_KLIPPY_PYTHON,
    $GATESOPT_KLIPPER_DICT; a sentence saying what is missing when it is not all there."""
    k = klipper or os.environ.get(ENV_KLIPPER)
    p = python or os.environ.get(ENV_PYTHON)
    d = dictionary or os.environ.get(ENV_DICT)
    if not k:
        return (f"no Klipper checkout: give --klipper DIR or set {ENV_KLIPPER} to a clone of "
                "https://github.com/Klipper3d/klipper (its klippy/ folder is run in batch mode)")
    kd = Path(k)
    if not (kd / "klippy" / "klippy.py").is_file():
        return f"{kd} is not a Klipper checkout: {kd / 'klippy' / 'klippy.py'} does not exist"
    if not p:
        return (f"no Python for klippy: give --python PY or set {ENV_PYTHON} to a Python with "
                f"klippy's requirements ({kd / 'scripts' / 'klippy-requirements.txt'})")
    if not Path(p).exists():
        return f"the Python for klippy does not exist: {p}"
    if not d:
        d = str(kd / "out" / "klipper.dict")
        if not Path(d).is_file():
            return (f"no MCU data dictionary: give --dict FILE or set {ENV_DICT}; one comes from "
                    "building Klipper's firmware for a test MCU (e.g. `make` with "
                    "test/configs/atmega2560.config and gcc-avr), which leaves out/klipper.dict")
    if not Path(d).is_file():
        return f"the MCU data dictionary does not exist: {d}"
    return KlipperHost(kd, Path(p), Path(d))


# --------------------------------------------------------------------------------------------
# The printer
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Shaper:
    """[input_shaper] of the replayed printer: one shaper type and frequency per axis."""
    type_x: str
    freq_x_hz: float
    type_y: str
    freq_y_hz: float

    @property
    def label(self) -> str:
        if (self.type_x, self.freq_x_hz) == (self.type_y, self.freq_y_hz):
            return f"{self.type_x} {self.freq_x_hz:g} Hz"
        return f"{self.type_x} {self.freq_x_hz:g} / {self.type_y} {self.freq_y_hz:g} Hz"


SHAPER_TYPES = ("zv", "mzv", "zvd", "ei", "2hump_ei", "3hump_ei")


def parse_shaper(text: str) -> Shaper | None:
    """'none' -> None; 'mzv:30' (both axes); 'mzv:30:ei:45' (x then y)."""
    t = text.strip().lower()
    if t in ("", "none", "off"):
        return None
    parts = t.split(":")
    if len(parts) == 2:
        parts = parts * 2
    if len(parts) != 4:
        raise ValueError(f"input shaper {text!r}: write TYPE:HZ or TYPE_X:HZ:TYPE_Y:HZ or none")
    tx, fx, ty, fy = parts
    for ty_ in (tx, ty):
        if ty_ not in SHAPER_TYPES:
            raise ValueError(f"input shaper type {ty_!r}: one of {', '.join(SHAPER_TYPES)}")
    try:
        return Shaper(tx, float(fx), ty, float(fy))
    except ValueError:
        raise ValueError(f"input shaper {text!r}: the frequency is not a number") from None


def printer_config(shaper: Shaper | None = None, gating: dict[str, str] | None = None,
                   pressure_advance_s: float | None = None, base: str | None = None) -> str:
    """The printer.cfg of a replay: bench/klipper/printer.cfg, plus an [input_shaper] section,
    a pressure advance, and a [gatesopt_gating] section (with ``gating``, even empty)."""
    text = base if base is not None else BASE_CONFIG.read_text()
    if pressure_advance_s:
        text = text.replace("[extruder]\n", f"[extruder]\npressure_advance: {pressure_advance_s:g}\n", 1)
    extra = []
    if shaper is not None:
        extra.append("[input_shaper]\n"
                     f"shaper_type_x: {shaper.type_x}\nshaper_freq_x: {shaper.freq_x_hz:g}\n"
                     f"shaper_type_y: {shaper.type_y}\nshaper_freq_y: {shaper.freq_y_hz:g}\n")
    if gating is not None:
        extra.append("[gatesopt_gating]\n" + "".join(f"{k}: {v}\n" for k, v in gating.items()))
    return text.rstrip("\n") + "\n" + "".join("\n" + e for e in extra)


@dataclass(frozen=True)
class StepperPins:
    """One stepper of the config: its pins (names as the MCU's enumeration spells them)."""
    name: str
    step_pin: str
    dir_pin: str
    dir_inverted: bool
    enable_pin: str
    enable_inverted: bool
    steps_per_mm: float


def _pin(text: str) -> tuple[str, bool]:
    t = text.strip()
    inverted = "!" in t
    return t.lstrip("^~!").strip(), inverted


def stepper_pins(cfg_text: str) -> dict[str, StepperPins]:
    """Each [stepper_*] / [extruder] section's pins and steps/mm (full steps 200 unless
    ``full_steps_per_rotation``; klippy/stepper.py, parse_step_distance)."""
    cp = configparser.RawConfigParser(inline_comment_prefixes=("#", ";"), strict=False)
    cp.read_string(cfg_text)
    out = {}
    for name in STEPPERS:
        if not cp.has_section(name):
            continue
        s = cp[name]
        step, _ = _pin(s["step_pin"])
        dirp, dir_inv = _pin(s["dir_pin"])
        en, en_inv = _pin(s.get("enable_pin", ""))
        full = float(s.get("full_steps_per_rotation", "200")) * float(s.get("microsteps", "1"))
        out[name] = StepperPins(name, step, dirp, dir_inv, en, en_inv,
                                full / float(s["rotation_distance"]))
    return out


# --------------------------------------------------------------------------------------------
# The MCU stream: messages -> tables (binary or parsedump text)
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class McuCommands:
    """The commands of one MCU stream that the decode needs, as columns. ``pos`` is a message's
    index in the stream (the order the host queued them); clocks are the MCU's 32-bit values."""
    freq_hz: float
    stepper_oids: dict[int, str]              # oid -> step pin
    out_oids: dict[int, tuple[str, int]]      # oid -> (pin, initial value on the wire)
    step: dict[str, np.ndarray]               # queue_step: pos oid interval count add
    dir: dict[str, np.ndarray]                # set_next_step_dir: pos oid dir
    reset: dict[str, np.ndarray]              # reset_step_clock: pos oid clock
    pin: dict[str, np.ndarray]                # queue_digital_out / update_digital_out: pos oid clock value (clock -1: now)
    n_messages: int


_FIELDS = {
    "queue_step": ("oid", "interval", "count", "add"),
    "set_next_step_dir": ("oid", "dir"),
    "reset_step_clock": ("oid", "clock"),
    "queue_digital_out": ("oid", "clock", "on_ticks"),
    "update_digital_out": ("oid", "value"),
}


def _commands_from_columns(freq_hz: float, cols: dict[str, dict[str, np.ndarray]],
                           stepper_oids, out_oids, n_messages) -> McuCommands:
    qd, ud = cols["queue_digital_out"], cols["update_digital_out"]
    pos = np.concatenate([qd["pos"], ud["pos"]])
    order = np.argsort(pos, kind="stable")
    pin = {"pos": pos[order],
           "oid": np.concatenate([qd["oid"], ud["oid"]])[order],
           "clock": np.concatenate([qd["clock"], np.full(len(ud["pos"]), -1, np.int64)])[order],
           "value": (np.concatenate([qd["on_ticks"], ud["value"]]) != 0).astype(np.int64)[order]}
    return McuCommands(
        freq_hz=float(freq_hz), stepper_oids=dict(stepper_oids), out_oids=dict(out_oids),
        step=cols["queue_step"], dir=cols["set_next_step_dir"], reset=cols["reset_step_clock"],
        pin=pin, n_messages=int(n_messages))


def parse_dump(lines, freq_hz: float) -> McuCommands:
    """``parsedump.py`` text (one message a line, ``name key=value ...``) -> McuCommands."""
    rows: dict[str, list] = {k: [] for k in _FIELDS}
    stepper_oids, out_oids = {}, {}
    pos = -1
    for line in lines:
        name, _, rest = line.strip().partition(" ")
        if not name or name.startswith("seq:"):
            continue
        pos += 1
        if name in rows:
            kv = dict(p.split("=", 1) for p in rest.split())
            rows[name].append([pos] + [int(kv[f]) for f in _FIELDS[name]])
        elif name == "config_stepper":
            kv = dict(p.split("=", 1) for p in rest.split())
            stepper_oids[int(kv["oid"])] = kv["step_pin"]
        elif name == "config_digital_out":
            kv = dict(p.split("=", 1) for p in rest.split())
            out_oids[int(kv["oid"])] = (kv["pin"], int(kv["value"]))
    cols = {}
    for name, fields in _FIELDS.items():
        a = np.array(rows[name], dtype=np.int64).reshape(-1, len(fields) + 1)
        cols[name] = {"pos": a[:, 0], **{f: a[:, i + 1] for i, f in enumerate(fields)}}
    return _commands_from_columns(freq_hz, cols, stepper_oids, out_oids, pos + 1)


def _enumerations(dictionary: dict) -> dict[str, dict[int, str]]:
    """value -> name for every enumeration of a data dictionary (ranges ``"PA0": [0, 8]``
    expand to PA0..PA7, as klippy/msgproto.py's fill_enumerations reads them)."""
    out = {}
    for ename, enums in dictionary.get("enumerations", {}).items():
        rev = {}
        for name, value in enums.items():
            if isinstance(value, int):
                rev[value] = str(name)
                continue
            root = str(name).rstrip("0123456789")
            first = int(str(name)[len(root):]) if len(root) < len(str(name)) else 0
            start, count = value
            for i in range(count):
                rev[start + i] = f"{root}{first + i}"
        out[ename] = rev
    return out


_MESSAGE_DEST, _MESSAGE_SYNC = 0x10, 0x7E


def decode_serial(data: bytes, dictionary: dict) -> McuCommands:
    """The binary stream klippy writes with ``-o`` -> McuCommands, without parsedump.

    The format is Klipper's protocol (docs/Protocol.md; klippy/msgproto.py): blocks of
    [length][0x10|seq][messages][crc16][0x7e]; a message is its command id and parameters, each
    a variable-length quantity (7 bits a byte, high bit = more bytes follow, first byte with bits
    0x60 set = negative). Messages never span blocks. Commands with string parameters are not
    expected in a stepper/pin stream and raise ReplayError (parse_dump reads them).
    """
    cmds = {int(i): fmt for fmt, i in dictionary["commands"].items()}
    nparams = np.full(max(cmds) + 1, -1, np.int64)
    for i, fmt in cmds.items():
        nparams[i] = len(fmt.split()) - 1
    b = np.frombuffer(data, np.uint8)
    n = len(b)
    # block boundaries: a chain through the length bytes (each block is <= 64 bytes)
    starts, p = [], 0
    while p < n:
        ln = data[p]
        if ln < 5 or p + ln > n or data[p + ln - 1] != _MESSAGE_SYNC or (data[p + 1] & ~0x0F) != _MESSAGE_DEST:
            raise ReplayError(f"MCU stream: no valid block at byte {p}")
        starts.append(p)
        p += ln
    starts = np.asarray(starts, np.int64)
    lens = b[starts].astype(np.int64)
    pay_len = lens - 5
    keep = np.ones(n, bool)   # payload bytes: all but each block's 2 header and 3 trailer bytes
    for off in (0, 1):
        keep[starts + off] = False
    for off in (1, 2, 3):
        keep[starts + lens - off] = False
    pay = b[keep]
    # variable-length integers: one ends at each byte without the high bit
    ends = np.flatnonzero(pay < 0x80)
    vstart = np.concatenate([[0], ends[:-1] + 1])
    vlen = ends - vstart + 1
    if vlen.max(initial=1) > 5:
        raise ReplayError("MCU stream: an integer longer than 5 bytes")
    first = pay[vstart].astype(np.int64)
    v = (first & 0x7F) - np.where((first & 0x60) == 0x60, 0x80, 0)
    del first
    more = np.flatnonzero(vlen > 1)
    for j in range(1, 5):
        v[more] = (v[more] << 7) | (pay[vstart[more] + j] & 0x7F)
        more = more[vlen[more] > j + 1]
    # messages: walk every block at once, one message per round (a block holds a dozen at most)
    blk_first_int = np.searchsorted(vstart, np.cumsum(np.concatenate([[0], pay_len[:-1]])))
    blk_end_int = np.concatenate([blk_first_int[1:], [len(v)]])
    ids_ok = (v >= 0) & (v < len(nparams))
    step_ = np.where(ids_ok, nparams[np.clip(v, 0, len(nparams) - 1)], -1)
    msg_starts = []
    cur, end = blk_first_int.copy(), blk_end_int
    while len(cur):
        live = cur < end
        cur, end = cur[live], end[live]
        if not len(cur):
            break
        k = step_[cur]
        if (k < 0).any():
            raise ReplayError(f"MCU stream: unknown command id {int(v[cur[k < 0][0]])}")
        msg_starts.append(cur)
        cur = cur + 1 + k
    mstart = np.sort(np.concatenate(msg_starts)) if msg_starts else np.zeros(0, np.int64)
    mid = v[mstart]
    by_name = {fmt.split()[0]: (i, fmt) for i, fmt in cmds.items()}
    for i in np.unique(mid):
        if "%s" in cmds[int(i)] or "%*s" in cmds[int(i)] or "%.*s" in cmds[int(i)]:
            raise ReplayError(f"MCU stream: command with a string parameter ({cmds[int(i)].split()[0]})")
    enums = _enumerations(dictionary)
    pin_names = enums.get("pin", {})

    def table(name):
        if name not in by_name:
            return np.zeros(0, np.int64), {}
        i, fmt = by_name[name]
        sel = mstart[mid == i]
        out = {}
        for j, part in enumerate(fmt.split()[1:]):
            pname, ptype = part.split("=")
            val = v[sel + 1 + j]
            if ptype in ("%u", "%hu", "%c"):
                val = val & 0xFFFFFFFF
            out[pname] = val
        return np.searchsorted(mstart, sel), out

    cols = {}
    for name, fields in _FIELDS.items():
        pos, t = table(name)
        cols[name] = {"pos": pos, **{f: t.get(f, np.zeros(0, np.int64)) for f in fields}}
    _, cs = table("config_stepper")
    stepper_oids = {int(o): pin_names.get(int(p), f"?{int(p)}") for o, p in zip(cs.get("oid", []), cs.get("step_pin", []))}
    _, cd = table("config_digital_out")
    out_oids = {int(o): (pin_names.get(int(p), f"?{int(p)}"), int(val))
                for o, p, val in zip(cd.get("oid", []), cd.get("pin", []), cd.get("value", []))}
    freq = float(dictionary["config"]["CLOCK_FREQ"])
    return _commands_from_columns(freq, cols, stepper_oids, out_oids, len(mstart))


# --------------------------------------------------------------------------------------------
# Decode: absolute 64-bit clocks per stepper and per pin
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class StepRows:
    """The queue_step commands of one stepper, in order. Step k (0-based) of row i is at
    ``start[i] + (k + 1) * interval[i] + add[i] * k * (k + 1) / 2`` (src/stepper.c,
    stepper_load_next / stepper_event: the first step ``interval`` after the previous row's last
    step, each later interval grown by ``add``; klippy/chelper/stepcompress.c, add_move)."""
    start: np.ndarray      # clock of the previous step (row's reference), int64
    interval: np.ndarray
    count: np.ndarray
    add: np.ndarray
    sign: np.ndarray       # +1 / -1: the logical direction of the row's steps

    @property
    def first(self) -> np.ndarray:
        return self.start + self.interval

    @property
    def last(self) -> np.ndarray:
        c = self.count
        return self.start + c * self.interval + self.add * (c * (c - 1) // 2)

    @property
    def n_steps(self) -> int:
        return int(self.count.sum())


@dataclass(frozen=True)
class PinEvents:
    """The changes of one digital output: clock (int64) and the level on the wire (0/1)."""
    clock: np.ndarray
    value: np.ndarray


@dataclass(frozen=True)
class McuStream:
    freq_hz: float
    steps: dict[str, StepRows]       # by step pin
    pins: dict[str, PinEvents]       # by pin
    initial: dict[str, int]          # pin -> level on the wire at start
    far_intervals: int               # rows whose 32-bit gap was unwrapped (a stepper idle > 2**32 ticks)


def unwrap32(clock32: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """The 64-bit clocks nearest to ``ref`` whose low 32 bits are ``clock32`` (the MCU's clock
    is 32 bits; the host never schedules more than seconds ahead, far less than 2**31 ticks)."""
    clock32 = np.asarray(clock32, np.int64)
    ref = np.asarray(ref, np.int64)
    d = (clock32 - ref) % CLOCK32
    d = np.where(d >= CLOCK32 // 2, d - CLOCK32, d)
    return ref + d


def _row_advance(interval, count, add):
    """Clock from a row's reference to its last step."""
    return count * interval + add * (count * (count - 1) // 2)


def decode_stream(cmds: McuCommands) -> McuStream:
    """McuCommands -> absolute step rows per stepper and pin changes per pin.

    Step clocks are relative (each row starts at the previous row's last step), so they add up
    exactly in 64 bits from the stream's clock 0; only reset_step_clock and pin clocks are
    absolute 32-bit values, unwrapped near the latest step clock queued before them.
    """
    st = cmds.step
    oid, pos = st["oid"], st["pos"]
    adv = _row_advance(st["interval"], st["count"], st["add"])
    start = np.zeros(len(oid), np.int64)
    rs = cmds.reset
    # rows of each stepper, with the reset_step_clock commands that restart its clock
    resets = sorted(zip(rs["pos"].tolist(), rs["oid"].tolist(), rs["clock"].tolist()))

    def compute_starts(seg_start: dict[tuple[int, int], int]):
        out = np.zeros(len(oid), np.int64)
        for o in np.unique(oid):
            sel = np.flatnonzero(oid == o)
            rpos = [(p, c) for (p, oo), c in seg_start.items() if oo == o]
            rpos.sort()
            base = np.zeros(len(sel), np.int64)
            seg_id = np.zeros(len(sel), np.int64)
            for j, (p, c) in enumerate(rpos):
                after = pos[sel] > p
                base[after] = c
                seg_id[after] = j + 1
            a = adv[sel]
            # cumulative advance within each segment
            cs = np.cumsum(a)
            seg_first = np.r_[True, seg_id[1:] != seg_id[:-1]]
            seg_base = np.maximum.accumulate(np.where(seg_first, np.arange(len(sel)), 0))
            before = cs - a - (cs[seg_base] - a[seg_base])
            out[sel] = base + before
        return out

    seg: dict[tuple[int, int], int] = {}
    start = compute_starts(seg)
    for p, o, c32 in resets:   # rare (homing on a real MCU): each one unwrapped after the last
        ref = _ref_at(pos, start + adv, np.array([p]))[0]
        seg[(p, o)] = int(unwrap32(np.array([c32]), np.array([ref]))[0])
        start = compute_starts(seg)
    # A step more than CLOCK_DIFF_MAX after its stepper's previous one is sent alone with the gap
    # as its interval, cut to 32 bits, and queued at its own clock (klippy/chelper/stepcompress.c,
    # stepcompress_flush_far / add_move): after 2**32 ticks of idle (268 s at 16 MHz) the sum of
    # intervals is short by 2**32. Every row's first step is therefore unwrapped near the latest
    # step clock queued before it (the stream is sent in clock order: serialqueue.c,
    # build_and_send_command), and a correction carries to the stepper's later rows.
    far = 0
    for _ in range(256):
        first = start + st["interval"]
        ref = _ref_at(pos, start + adv, pos)
        delta = unwrap32(first % CLOCK32, ref) - first
        if not delta.any():
            break
        for o in np.unique(oid[delta != 0]):
            sel = np.flatnonzero(oid == o)
            r = np.flatnonzero(delta[sel])[0]      # the stepper's earliest wrapped row
            start[sel[r:]] += delta[sel[r]]
            far += 1
    else:
        raise ReplayError("MCU stream: step clocks do not settle after unwrapping")
    # direction of each row: the last set_next_step_dir of its stepper before it
    steps = {}
    for o, step_pin in cmds.stepper_oids.items():
        sel = np.flatnonzero(oid == o)
        dsel = np.flatnonzero(cmds.dir["oid"] == o)
        k = np.searchsorted(cmds.dir["pos"][dsel], pos[sel]) - 1
        dirs = np.concatenate([[0], cmds.dir["dir"][dsel]])   # before any set_next_step_dir: 0
        d = dirs[k + 1]
        steps[step_pin] = StepRows(start[sel], st["interval"][sel], st["count"][sel], st["add"][sel],
                                   np.where(d != 0, 1, -1).astype(np.int64))
    # pins: unwrap each clock near the latest step clock queued before it
    pn = cmds.pin
    ref = _ref_at(pos, start + adv, pn["pos"])
    clock = np.where(pn["clock"] >= 0, unwrap32(np.maximum(pn["clock"], 0), ref), ref)
    pins, initial = {}, {}
    for o, (pin, value0) in cmds.out_oids.items():
        sel = np.flatnonzero(pn["oid"] == o)
        order = np.argsort(clock[sel], kind="stable")
        pins[pin] = PinEvents(clock[sel][order], pn["value"][sel][order])
        initial[pin] = int(value0 != 0)
    return McuStream(cmds.freq_hz, steps, pins, initial, far)


def _ref_at(step_pos: np.ndarray, step_last: np.ndarray, at_pos: np.ndarray) -> np.ndarray:
    """The latest step clock among queue_step messages before each stream position."""
    if not len(step_pos):
        return np.zeros(len(at_pos), np.int64)
    run = np.maximum.accumulate(step_last)
    k = np.searchsorted(step_pos, at_pos) - 1
    return np.where(k >= 0, run[np.maximum(k, 0)], 0)


# --------------------------------------------------------------------------------------------
# Steps and off intervals (pure, vectorised; no step is ever expanded beyond one row)
# --------------------------------------------------------------------------------------------

def step_clocks(rows: StepRows) -> np.ndarray:
    """Every step clock (int64) of the rows, in order. For tests and small streams: a long
    print has tens of millions of steps; the metrics below never expand them."""
    c = rows.count
    r = np.repeat(np.arange(len(c)), c)
    k = np.arange(int(c.sum())) - np.repeat(np.cumsum(c) - c, c)
    return rows.start[r] + (k + 1) * rows.interval[r] + rows.add[r] * (k * (k + 1) // 2)


def steps_before(rows: StepRows, t: np.ndarray) -> np.ndarray:
    """How many steps of ``rows`` come at a clock < t, for each t (binary search within a row:
    a row's step clocks increase, its intervals stay positive)."""
    t = np.asarray(t, np.int64)
    cum = np.concatenate([[0], np.cumsum(rows.count)])
    if not len(rows.count):
        return np.zeros(len(t), np.int64)
    last = rows.last
    i = np.searchsorted(last, t, side="left")            # rows < i end before t
    n = cum[i]
    part = i < len(last)
    ip = i[part]
    lo = np.zeros(len(ip), np.int64)
    hi = rows.count[ip].copy()
    s, iv, ad, tp = rows.start[ip], rows.interval[ip], rows.add[ip], t[part]
    while (lo < hi).any():
        active = lo < hi
        mid = (lo + hi) // 2
        below = s + (mid + 1) * iv + ad * (mid * (mid + 1) // 2) < tp
        lo = np.where(active & below, mid + 1, lo)
        hi = np.where(active & ~below, mid, hi)
    n[part] += lo
    return n


def step_clock_at(rows: StepRows, g: np.ndarray) -> np.ndarray:
    """The clock of step number g (0-based over all rows), for each g."""
    g = np.asarray(g, np.int64)
    cum = np.concatenate([[0], np.cumsum(rows.count)])
    r = np.searchsorted(cum, g, side="right") - 1
    k = g - cum[r]
    return rows.start[r] + (k + 1) * rows.interval[r] + rows.add[r] * (k * (k + 1) // 2)


def off_intervals(events: PinEvents, initial_on: bool, inverted: bool) -> tuple[np.ndarray, np.ndarray]:
    """[start, end) clocks of every interval in which an enable pin is off (driver disabled).

    ``inverted``: the pin is active low (config ``!PD7``): level 1 on the wire = off. The pin is
    off from clock 0 unless ``initial_on``; an interval still open at the end ends at OPEN_END.
    Intervals of zero length (off and on at the same clock) are dropped.
    """
    on = (events.value != 0) != inverted
    state = bool(initial_on)
    starts, ends = [], []
    if not state:
        starts.append(0)
    # only changes matter; repeated writes of the same level are no change
    prev = np.concatenate([[state], on[:-1]]) if len(on) else np.zeros(0, bool)
    change = on != prev
    for c, v in zip(events.clock[change].tolist(), on[change].tolist()):
        if v:
            ends.append(c)
        else:
            starts.append(c)
    if len(ends) < len(starts):
        ends.append(OPEN_END)
    s, e = np.asarray(starts, np.int64), np.asarray(ends, np.int64)
    keep = e > s
    return s[keep], e[keep]


@dataclass(frozen=True)
class StepperReplay:
    """What one stepper did in a replay. Times in seconds of print time (MCU clock / frequency).

    *gated* off intervals are those with a step before and after (the initial off before homing
    and the final off after the print are not gating). A *tail* interval is an off that begins
    after the stepper's last step but before the print's end (the last step of any stepper): a
    gating off that klippy's own motor-off at the end of the input keeps (the motor stays off for
    the rest of the print, e.g. X and Y during the closing Z lift); it counts in ``off_time_s``
    up to the print's end, as gatesopt's report counts it up to the end of its timeline, and its
    end-late in ``end_late_*``. ``start_ahead_s`` of a gated interval =
    its first step at or after the pin is on, minus the pin-on time; ``end_late_s`` = the pin-off
    time minus its last step before. ``steps_while_off`` counts steps at clocks in [off, on) of
    any off interval: each one a step a de-energised driver did not take; ``gated_steps_while_off``
    those of gated intervals (with an input shaper Klipper's own homing sends a few steps before
    the pin of the first homing move is on: the initial interval).
    """
    name: str
    steps: int
    net_steps: int
    first_step_s: float
    last_step_s: float
    steps_while_off: int
    gated_steps_while_off: int
    gated: int
    off_time_s: float               # gated intervals + the tail interval (to the print's end)
    start_ahead_min_s: float
    start_ahead_median_s: float
    end_late_min_s: float
    end_late_median_s: float
    off_s: np.ndarray = field(repr=False)    # gated intervals [start, end] in s, shape (n, 2)
    while_off_s: np.ndarray = field(repr=False)  # the off intervals [start, end] that had steps
    tail_off_s: float = 0.0         # of ``off_time_s``: the tail interval, off to the print's end
    # the enable pin's queue (``pin_queue_leads``): least time from a change to the change 1 and
    # 2 back (nan: no such pair), and whether the changes' clocks increase in stream order
    pin_lead_min_s: tuple = (float("nan"), float("nan"))
    pin_order_ok: bool = True

    def as_dict(self) -> dict:
        d = {k: v for k, v in dataclasses.asdict(self).items() if k not in ("off_s", "while_off_s")}
        d["pin_lead_min_s"] = list(self.pin_lead_min_s)
        d["while_off_intervals_s"] = self.while_off_s.tolist()[:20]
        return d


def pin_queue_leads(events: PinEvents, freq_hz: float, back=(1, 2)) -> dict:
    """The enable pin's queue_digital_out messages as the MCU takes them (every change, Klipper's
    own and a module's): for each k in ``back`` the least ``clock[n] - clock[n - k]`` (s). A
    sender that keeps k changes of the pin queued releases change n when change n - k has run
    (serialqueue.c holds a message until its minclock; Klipper's set_digital: k = 1, the module's
    pin_queue_slots: k = 2), so this is the lead each message then has; and it is >= a spacing
    exactly when no window of that length holds more than k changes: at most k queued on the MCU
    at once if each message is sent that spacing ahead. ``pin_order_ok``: clocks increase in
    stream order (src/gpiocmds.c queues a pin's changes first in, first out)."""
    c = np.asarray(events.clock, np.int64)
    leads = tuple(float((c[k:] - c[:-k]).min()) / freq_hz if len(c) > k else float("nan") for k in back)
    return {"pin_lead_min_s": leads, "pin_order_ok": bool(np.all(np.diff(c) > 0))}


def stepper_replay(name: str, rows: StepRows, off_start: np.ndarray, off_end: np.ndarray,
                   freq_hz: float, end_clock: int | None = None) -> StepperReplay:
    """Steps, steps while off, start-ahead / end-late and off time of one stepper;
    ``end_clock``: the print's last step (any stepper), where a tail interval ends (None: none)."""
    n = rows.n_steps
    nan = float("nan")
    if n == 0:
        return StepperReplay(name, 0, 0, nan, nan, 0, 0, 0, 0.0, nan, nan, nan, nan,
                             np.zeros((0, 2)), np.zeros((0, 2)))
    first = int(rows.first[0])
    last = int(rows.last[-1])
    b_start = steps_before(rows, off_start)
    b_end = steps_before(rows, off_end)
    inside = b_end - b_start
    gated = (b_start > 0) & (b_end < n)
    gs, ge = off_start[gated], off_end[gated]
    tail = (b_start == n) & (off_start < (end_clock if end_clock is not None else -1))
    tail_s = float((np.minimum(off_end[tail], end_clock) - off_start[tail]).sum() / freq_hz) \
        if tail.any() else 0.0
    if gated.any():
        nxt = step_clock_at(rows, b_end[gated])
        ahead = (nxt - ge) / freq_hz
        a_min, a_med = float(ahead.min()), float(np.median(ahead))
    else:
        a_min = a_med = nan
    late_at = gated | tail
    if late_at.any():
        prv = step_clock_at(rows, b_start[late_at] - 1)
        late = (off_start[late_at] - prv) / freq_hz
        l_min, l_med = float(late.min()), float(np.median(late))
    else:
        l_min = l_med = nan
    hit = inside > 0
    wo = np.stack([off_start[hit] / freq_hz,
                   np.where(off_end[hit] == OPEN_END, np.inf, off_end[hit] / freq_hz)], axis=1)
    return StepperReplay(
        name=name, steps=n, net_steps=int((rows.count * rows.sign).sum()),
        first_step_s=first / freq_hz, last_step_s=last / freq_hz,
        steps_while_off=int(inside.sum()), gated_steps_while_off=int(inside[gated].sum()),
        gated=int(gated.sum()),
        off_time_s=float((ge - gs).sum() / freq_hz) + tail_s,
        start_ahead_min_s=a_min, start_ahead_median_s=a_med,
        end_late_min_s=l_min, end_late_median_s=l_med,
        off_s=np.stack([gs / freq_hz, ge / freq_hz], axis=1), while_off_s=wo, tail_off_s=tail_s)


@dataclass(frozen=True)
class Replay:
    """One G-code file through Klipper's planner: per-stepper results and the planned time.
    ``end_s``: the last step of any stepper, from the stream's clock 0 (homing included: the
    same in every variant of a file, so differences of ``end_s`` are what a rewrite adds);
    ``print_s``: from the first extruder step to the last step (the print without homing)."""
    end_s: float
    first_extrusion_s: float
    steppers: dict[str, StepperReplay]
    far_intervals: int
    complete: bool = True
    host_end_s: float = float("nan")
    attempts: int = 1
    klippy_s: float = 0.0
    decode_s: float = 0.0
    unknown: dict[str, int] = field(default_factory=dict)
    #: batch mode's late clock restarts after flushes (bench/klipper/gatesopt_replay_clock.py):
    #: their sum (s) and count; no printer has them
    batch_kick_s: float = 0.0
    batch_kicks: int = 0

    @property
    def print_s(self) -> float:
        return self.end_s - self.first_extrusion_s

    @property
    def steps_while_off(self) -> int:
        return sum(s.steps_while_off for s in self.steppers.values())

    @property
    def gated_steps_while_off(self) -> int:
        return sum(s.gated_steps_while_off for s in self.steppers.values())

    def as_dict(self) -> dict:
        return {"end_s": self.end_s, "first_extrusion_s": self.first_extrusion_s, "print_s": self.print_s,
                "complete": self.complete, "host_end_s": self.host_end_s, "attempts": self.attempts,
                "far_intervals": self.far_intervals, "klippy_s": self.klippy_s,
                "decode_s": self.decode_s, "unknown_commands": self.unknown,
                "batch_kick_s": self.batch_kick_s, "batch_kicks": self.batch_kicks,
                "steppers": {k: v.as_dict() for k, v in self.steppers.items()}}


def replay_metrics(stream: McuStream, pins: dict[str, StepperPins]) -> Replay:
    """Per-stepper metrics of a decoded stream, the steppers and their pins from the config.

    ``Replay.complete``: every stepper's enable pin goes off for good after its last step.
    klippy switches every motor off when the input ends (klippy/extras/stepper_enable.py,
    _handle_request_restart -> motor_off), the last messages it queues; but at exit its
    background writer is stopped without draining its queue (klippy/chelper/serialqueue.c,
    serialqueue_exit -> pollreactor_do_exit), so on a loaded machine the tail of the stream,
    motor-off and sometimes seconds of steps, can be missing. Such a stream is not complete.
    """
    out = {}
    complete = True
    for name, sp in pins.items():
        if sp.step_pin not in stream.steps:
            raise ReplayError(f"{name}: no config_stepper for step pin {sp.step_pin} in the stream")
    # the print's end: the last step of any stepper (a tail interval ends there)
    end = max((int(stream.steps[sp.step_pin].last[-1]) for sp in pins.values()
               if stream.steps[sp.step_pin].n_steps), default=0)
    for name, sp in pins.items():
        rows = stream.steps[sp.step_pin]
        # Klipper's stepcompress sends the logical direction XOR the dir pin's inversion
        # (klippy/chelper/stepcompress.c, set_next_step_dir)
        if sp.dir_inverted:
            rows = dataclasses.replace(rows, sign=-rows.sign)
        ev = stream.pins.get(sp.enable_pin)
        if ev is None:
            raise ReplayError(f"{name}: no config_digital_out for enable pin {sp.enable_pin}")
        # the pin starts with the driver disabled (klippy/extras/stepper_enable.py): its level on
        # the wire at start is 1 exactly when it is active low
        if stream.initial.get(sp.enable_pin, 0) != int(sp.enable_inverted):
            raise ReplayError(f"{name}: enable pin {sp.enable_pin} starts at level "
                              f"{stream.initial.get(sp.enable_pin)}, expected the disabled level")
        s, e = off_intervals(ev, initial_on=False, inverted=sp.enable_inverted)
        out[name] = dataclasses.replace(stepper_replay(name, rows, s, e, stream.freq_hz, end),
                                        **pin_queue_leads(ev, stream.freq_hz))
        if rows.n_steps and not (len(e) and e[-1] == OPEN_END and s[-1] >= rows.last[-1]):
            complete = False
    # the print starts at the first extruder step (homing and heating come before it)
    e = pins.get("extruder")
    e_rows = stream.steps.get(e.step_pin) if e else None
    e_first = int(e_rows.first[0]) if e_rows is not None and e_rows.n_steps else 0
    return Replay(end / stream.freq_hz, e_first / stream.freq_hz, out, stream.far_intervals, complete)


# --------------------------------------------------------------------------------------------
# Running klippy
# --------------------------------------------------------------------------------------------

class KlippyRunner:
    """klippy from a temporary copy of the checkout's klippy/ (the checkout stays untouched;
    klippy compiles its C helper into the copy on first use, kept in a cache for later copies),
    with bench/klipper/gatesopt_replay_drain.py (so that the MCU stream is written in full
    before klippy exits) and optionally another extras module linked into its klippy/extras/."""

    def __init__(self, host: KlipperHost, module: Path | None = None, keep: Path | None = None):
        self.host = host
        self.tmp = Path(tempfile.mkdtemp(prefix="gatesopt-klippy-", dir=keep))
        try:
            self._setup(host, module)
        except BaseException:
            self.close()
            raise

    def _setup(self, host: KlipperHost, module: Path | None) -> None:
        self.klippy = self.tmp / "klippy"
        shutil.copytree(host.klipper_dir / "klippy", self.klippy, symlinks=True,
                        ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        self._chelper_cache = _chelper_cache(self.klippy / "chelper")
        if self._chelper_cache.exists():
            shutil.copy2(self._chelper_cache, self.klippy / "chelper" / "c_helper.so")
        os.symlink(DRAIN_MODULE, self.klippy / "extras" / DRAIN_MODULE.name)
        os.symlink(CLOCK_MODULE, self.klippy / "extras" / CLOCK_MODULE.name)
        if module is not None:
            module = Path(module).resolve()
            if not module.is_file():
                raise ReplayError(f"--module {module}: no such file")
            os.symlink(module, self.klippy / "extras" / module.name)
        self.dictionary = json.loads(Path(host.dictionary).read_bytes())

    def close(self):
        shutil.rmtree(self.tmp, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def run(self, cfg_text: str, gcode_text: str, pins: dict[str, StepperPins] | None = None,
            via_parsedump: bool = False, attempts: int = 3) -> Replay:
        """Replay G-code text on the printer ``cfg_text``; ReplayError with klippy's own message
        when it stops on an error. A stream that comes out cut short (Replay.complete false: no
        final motor-off after the last steps, or its last step well before the print time klippy
        logs at exit) is replayed again, up to ``attempts`` times in all."""
        for attempt in range(1, attempts + 1):
            rep = self._run_once(cfg_text, gcode_text, pins, via_parsedump)
            ok = rep.complete and not (rep.host_end_s - rep.end_s > 1.0)
            if ok:
                return dataclasses.replace(rep, attempts=attempt)
            _progress(f"klipper_replay: MCU stream cut short (last step {rep.end_s:.3f} s, klippy "
                      f"exited at {rep.host_end_s:.3f} s), replaying again")
        raise ReplayError(f"the MCU stream came out cut short {attempts} times in a row")

    def _run_once(self, cfg_text, gcode_text, pins, via_parsedump) -> Replay:
        work = Path(tempfile.mkdtemp(dir=self.tmp))
        try:
            cfg, gc, ser, log = work / "printer.cfg", work / "in.gcode", work / "out.serial", work / "klippy.log"
            cfg.write_text(cfg_text.rstrip("\n") + "\n\n[gatesopt_replay_drain]\n\n[gatesopt_replay_clock]\n")
            gc.write_text(gcode_text)
            t0 = time.perf_counter()
            r = subprocess.run([str(self.host.python), str(self.klippy / "klippy.py"), str(cfg),
                                "-i", str(gc), "-o", str(ser), "-d", str(self.host.dictionary),
                                "-l", str(log)], capture_output=True, text=True)
            klippy_s = time.perf_counter() - t0
            built = self.klippy / "chelper" / "c_helper.so"
            if built.exists() and not self._chelper_cache.exists():
                self._chelper_cache.parent.mkdir(parents=True, exist_ok=True)
                tmp = self._chelper_cache.with_suffix(f".{os.getpid()}.tmp")
                shutil.copy2(built, tmp)
                os.replace(tmp, self._chelper_cache)
            log_text = log.read_text(errors="replace") if log.exists() else ""
            if r.returncode != 0:
                raise ReplayError("klippy stopped: " + _klippy_error(log_text, r.stderr))
            t0 = time.perf_counter()
            if via_parsedump:
                out = subprocess.run([str(self.host.python), str(self.klippy / "parsedump.py"),
                                      str(self.host.dictionary), str(ser)],
                                     capture_output=True, text=True, check=True).stdout
                cmds = parse_dump(out.splitlines(), float(self.dictionary["config"]["CLOCK_FREQ"]))
            else:
                cmds = decode_serial(ser.read_bytes(), self.dictionary)
            rep = replay_metrics(decode_stream(cmds), pins or stepper_pins(cfg_text))
            decode_s = time.perf_counter() - t0
            m = _EXIT_TIME.findall(log_text)
            kicks = [float(k) for k in _KICK.findall(log_text)]
            return dataclasses.replace(rep, klippy_s=klippy_s, decode_s=decode_s,
                                       batch_kick_s=float(sum(kicks)), batch_kicks=len(kicks),
                                       unknown=unknown_commands(log_text),
                                       host_end_s=float(m[-1]) if m else float("nan"))
        finally:
            shutil.rmtree(work, ignore_errors=True)


def _chelper_cache(chelper: Path) -> Path:
    """Where the C helper klippy compiles for these sources is kept between runs (a fresh copy
    of klippy/ would compile it again, ~8 s): keyed by the sources' names, sizes and contents."""
    import hashlib
    h = hashlib.sha1()
    for f in sorted(chelper.glob("*")):
        if f.suffix in (".c", ".h", ".py"):
            h.update(f.name.encode() + f.read_bytes())
    root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return root / "gatesopt" / "klippy-chelper" / h.hexdigest()[:16] / "c_helper.so"


_CONFIG_END = "======================="


def _klippy_error(log_text: str, stderr: str) -> str:
    """The lines of klippy's log that say why it stopped (after the config dump)."""
    tail = log_text.split(_CONFIG_END)[-1].splitlines()
    if "Traceback (most recent call last):" in tail:
        # a config error or a crash: the exception's own line says it
        i = tail.index("Traceback (most recent call last):")
        frames = [ln for ln in tail[i + 1:] if ln and not ln.startswith(" ")]
        head = " ".join(ln.strip() for ln in tail[:i] if ln.strip() and not ln.startswith(("Extruder",)))
        return (head + ": " if head else "") + (frames[0] if frames else "traceback")
    skip = ("Unknown command", "Exiting", "Unfreezing", "Running full", "Sending MCU", "Configured MCU",
            "Loaded MCU", "MCU '", "Extruder max_extrude", "Starting", "Start printer",
            "Args:", "Git version", "Python:", "CPU:", "Restarting", "Stats ")
    msgs = [ln.strip() for ln in tail if ln.strip() and not ln.startswith(skip)]
    if msgs:
        return "; ".join(msgs[:3])
    err = stderr.strip().splitlines()
    return err[-1] if err else "no message"


_UNKNOWN = re.compile(r'Unknown command:"([^"]*)"')
_EXIT_TIME = re.compile(r"Exiting \(print time ([0-9.]+)s\)")
_KICK = re.compile(r"gatesopt_replay_clock: kick ([0-9.]+) at")


def unknown_commands(log_text: str) -> dict[str, int]:
    out: dict[str, int] = {}
    for m in _UNKNOWN.finditer(log_text):
        out[m.group(1)] = out.get(m.group(1), 0) + 1
    return out


# --------------------------------------------------------------------------------------------
# G-code side: what a replay is given, E-only moves, gating lines
# --------------------------------------------------------------------------------------------

_PLACEHOLDER = re.compile(r"\{[^}]*\}")
#: a word (its letter, if any) whose value is an unexpanded placeholder
_PLACEHOLDER_WORD = re.compile(r"[A-Za-z]?\{[^}]*\}")


def relative_e_undeclared(gcode: str, name: str = "") -> bool:
    """The file extrudes before any M82/M83 with E words that only make sense as relative
    lengths (``gatesopt.parse.undeclared_relative_e``: Kiri:Moto leaves M83 to the printer's
    ``print_start`` macro). gatesopt reads such a file as relative E; klippy starts in absolute E
    (klippy/extras/gcode_move.py, ``absolute_extrude = True``) and the bench printer has no such
    macro, so its replay is given the M83 the printer's start macro must send: replayed as
    absolute, every XY move after a 6 mm unretract read as a 5.9 mm retraction, planned at
    ``max_extrude_only_accel`` / |E per mm| (real_kirimoto30: 405 mm/s^2 instead of 3000, the
    off intervals around them 0.11 s longer in the replay than in gatesopt's report)."""
    from gatesopt.parse import undeclared_relative_e
    return undeclared_relative_e(gcode.encode(errors="replace"), name) is not None


def replay_text(gcode: str, relative_e: bool | None = None) -> tuple[str, int]:
    """The text klippy replays: ``G28`` first (a file whose start code is empty would stop at its
    first move: Klipper refuses moves before homing), and every word whose value is a slicer
    placeholder left unexpanded (``M104 S{material_print_temperature}``, ``G1 X0
    Y{machine_depth}`` of a CuraEngine run without a front end: Klipper stops on it) dropped
    from its line, the rest of the line kept: what gatesopt reads there (gatesopt/_scan_words.py:
    a word without a value is ignored, as Marlin's ``seenval()`` does), so that the replay moves
    where gatesopt's model moves (CuraEngine's closing ``G1 X0 Y{machine_depth}`` still moves X;
    made a comment, it left X's last off interval without a step after it). Returns the text and
    the number of lines changed. The same for an original and its gatesopt output.
    ``relative_e``: the file's E words are relative without an M83 of its own
    (``relative_e_undeclared``, read from the text where None): an M83 after the ``G28``."""
    out, n = ["G28 ; gatesopt replay: home first"], 0
    if relative_e is None:
        relative_e = relative_e_undeclared(gcode)
    if relative_e:
        out.append("M83 ; gatesopt replay: relative E, as the file's start macro must set it")
    for line in gcode.splitlines():
        code, sep, comment = line.partition(";")
        if "{" in code and _PLACEHOLDER.search(code):
            kept = _PLACEHOLDER_WORD.sub("", code).rstrip()
            out.append(f"{kept} ; gatesopt replay, unexpanded placeholder dropped: {line}"
                       if kept.strip() else "; gatesopt replay, unexpanded placeholder: " + line)
            n += 1
        else:
            out.append(line)
    return "\n".join(out) + "\n", n


def count_extrude_only_moves(gcode: str) -> int:
    """G0/G1 lines with an E word and no X, Y or Z word: Klipper plans each as a move of its own
    that starts and ends at rest (klippy/toolhead.py, Move: extrude-only moves are not kinematic,
    and calc_junction gives no junction speed to or from one)."""
    n = 0
    for line in gcode.splitlines():
        code = line.split(";", 1)[0].upper().split()
        if not code or code[0] not in ("G0", "G1", "G00", "G01"):
            continue
        letters = {w[0] for w in code[1:]}
        if "E" in letters and not letters & {"X", "Y", "Z"}:
            n += 1
    return n


GATING_LINE = {
    "klipper": re.compile(r"^SET_STEPPER_ENABLE\s+STEPPER=\w+\s+ENABLE=[01]\s*$", re.M),
    "3dgates": re.compile(r"^S[01]\s+[XYZE](\s+[XYZE])*\s*$", re.M),
    "marlin": re.compile(r"^M1[78]\s+[XYZE](\s+[XYZE])*\s*$", re.M),
    "klipper-gating": re.compile(r"^GATESOPT_GATE\s+STEPPERS=[\w,]+\s*$", re.M),
}


def gating_lines(gcode: str, firmware: str) -> int:
    pat = GATING_LINE.get(firmware)
    return len(pat.findall(gcode)) if pat else 0


def strip_gating_lines(gcode: str, firmware: str) -> str:
    """The output without its gating instructions (split moves, order, rotation kept): replayed
    beside it, it separates what the instructions cost from what the rest of the rewrite costs."""
    pat = GATING_LINE.get(firmware)
    if pat is None:
        return gcode
    return "\n".join(ln for ln in gcode.splitlines() if not pat.match(ln)) + "\n"


def read_gcode(path: Path) -> str:
    raw = Path(path).read_bytes()
    if str(path).endswith(".gz"):
        raw = gzip.decompress(raw)
    return raw.decode("utf-8", errors="replace")


# --------------------------------------------------------------------------------------------
# gatesopt side
# --------------------------------------------------------------------------------------------

#: dialects whose firmware times its own switches: solved for the printer.cfg they are replayed on
SCHEDULED = ("klipper-gating",)


def _model_kinematics(path: Path):
    """``kinematics.model_kinematics`` of the file at ``path`` (gzip read as the CLI reads it)."""
    import gzip
    from gatesopt.kinematics import model_kinematics
    raw = path.read_bytes()
    return model_kinematics(gzip.decompress(raw) if path.name.endswith(".gz") else raw)


def solve(path: Path, firmware: str, extra: list[str], out_dir: Path, tag_extra: str = "") -> tuple[Path, dict]:
    """``gatesopt solve`` from this worktree (its installed package, the same Python): the
    output file and its JSON report."""
    if (firmware == "klipper" and not any(w in extra for w in ("--printer-config", "--motors"))
            and _model_kinematics(path) is None):
        # the replay's printer is cartesian: said, as a user without the printer.cfg says it
        # (of unknown kinematics stock Klipper gates no X/Y by default: ``rewrite.printer``; a
        # model the file names decides as before, a corexy one gating nothing)
        extra = [*extra, "--motors", "X,Y"]
    words = [w for w in extra if not w.endswith(".cfg")] + ([tag_extra] if tag_extra else [])
    tag = re.sub(r"[^A-Za-z0-9]+", "_", " ".join(words)).strip("_") or "default"
    stem = path.name.removesuffix(".gz").removesuffix(".gcode")
    out = out_dir / f"{stem}.{firmware}.{tag}.gcode"
    rep = out.with_suffix(".json")
    cmd = [sys.executable, "-m", "gatesopt", "solve", str(path), "--firmware", firmware,
           "-o", str(out), "--json", str(rep), "--force", *extra]
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO)
    if r.returncode != 0 or not out.exists():
        msg = (r.stderr.strip() or r.stdout.strip()).splitlines()
        raise ReplayError("gatesopt solve failed: " + (msg[-1] if msg else f"exit {r.returncode}"))
    return out, json.loads(rep.read_text())


# --------------------------------------------------------------------------------------------
# One comparison row
# --------------------------------------------------------------------------------------------

def _ms(x: float) -> str:
    return "—" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{1000 * x:.2f}"


def compare(orig: Replay, out: Replay, stripped: Replay | None, report: dict, firmware: str,
            orig_text: str, out_text: str) -> dict:
    """One table row: the output against its original, both through Klipper."""
    added = out.end_s - orig.end_s
    n_lines = gating_lines(out_text, firmware)
    n_disable = len(re.findall(r"ENABLE=0|^S0\s|^M18\s", out_text, re.M))
    e_extra = count_extrude_only_moves(out_text) - count_extrude_only_moves(orig_text)
    row = {
        "print_s": orig.print_s, "out_print_s": out.print_s, "added_s": added,
        "added_pct": 100 * added / orig.print_s if orig.print_s else float("nan"),
        "model_added_pct": report.get("added_time_pct"), "gating_lines": n_lines,
        # what gatesopt's report prices the rewrite at, in seconds (its percentage is of its own
        # total, heater waits included), and batch mode's late clock restarts the output has more
        # than the original (``Replay.batch_kick_s``): ``net_added_s`` is what a printer adds
        "priced_s": (report["print_time_after_s"] - report["print_time_before_s"])
        if "print_time_after_s" in report and "print_time_before_s" in report else float("nan"),
        "batch_kick_s": out.batch_kick_s - orig.batch_kick_s,
        "net_added_s": added - (out.batch_kick_s - orig.batch_kick_s),
        "net_added_pct": 100 * (added - (out.batch_kick_s - orig.batch_kick_s)) / orig.print_s
        if orig.print_s else float("nan"),
        "disables": n_disable, "e_only_extra": e_extra, "verified": report.get("verified"),
        "rotation_deg": report.get("rotation_deg", 0.0), "ordered": report.get("ordered"),
        "steps_while_off": {MOTOR_OF[k]: v.gated_steps_while_off for k, v in out.steppers.items()},
        "all_steps_while_off": {MOTOR_OF[k]: v.steps_while_off for k, v in out.steppers.items()},
        "orig_steps_while_off": {MOTOR_OF[k]: v.steps_while_off for k, v in orig.steppers.items()},
        "gated": {MOTOR_OF[k]: v.gated for k, v in out.steppers.items()},
        "start_ahead_min_s": min((v.start_ahead_min_s for v in out.steppers.values() if v.gated), default=float("nan")),
        "start_ahead_median_s": {MOTOR_OF[k]: v.start_ahead_median_s for k, v in out.steppers.items() if v.gated},
        "end_late_min_s": min((v.end_late_min_s for v in out.steppers.values() if v.gated), default=float("nan")),
        "off_time_s": {MOTOR_OF[k]: v.off_time_s for k, v in out.steppers.items() if v.off_time_s > 0},
        "tail_off_s": {MOTOR_OF[k]: v.tail_off_s for k, v in out.steppers.items() if v.tail_off_s > 0},
        "report_off_time_s": report.get("off_time_s", {}),
        "off_time_waits_s": report.get("off_time_waits_s", {}),
        "saving_pct": report.get("saving_pct"),
        "klippy_s": orig.klippy_s + out.klippy_s, "decode_s": orig.decode_s + out.decode_s,
        # the gated pins' queues (pin_queue_leads): least lead with 1 and 2 changes queued
        "pin_lead_min_s": [min((v.pin_lead_min_s[i] for v in out.steppers.values() if v.gated),
                               default=float("nan")) for i in range(2)],
        "pin_order_ok": all(v.pin_order_ok for v in out.steppers.values()),
    }
    if stripped is not None:
        # the rewrite without its instructions (split moves, ordering, rotation) vs the original,
        # and what the instructions add on top of it
        # (batch mode's late restarts left out, ``Replay.batch_kick_s``)
        row["rewrite_s"] = (stripped.end_s - stripped.batch_kick_s) - (orig.end_s - orig.batch_kick_s)
        row["instructions_s"] = (out.end_s - out.batch_kick_s) - (stripped.end_s - stripped.batch_kick_s)
        row["per_disable_ms"] = (1000 * row["instructions_s"] / n_disable) if n_disable else float("nan")
        row["per_split_ms"] = (1000 * row["rewrite_s"] / e_extra) if e_extra and not report.get("ordered") \
            and not report.get("rotation_deg") else float("nan")
    return row


# --------------------------------------------------------------------------------------------
# Table
# --------------------------------------------------------------------------------------------

def _fmt_motors(d: dict, fmt) -> str:
    return " ".join(f"{k} {fmt(v)}" for k, v in d.items() if k in ("X", "Y", "Z", "E")) or "—"


def table(rows: list[dict]) -> str:
    head = ("| file | firmware | solve | shaper | print s | added s (%) | batch kicks s | "
            "net added s (%) | priced s | model % | lines | "
            "ms/disable | E-only +n | ms/split | steps while off | start-ahead min / med ms | "
            "end-late min ms | off s replay / report | klippy s |")
    out = [head, "|" + "---|" * 3 + "---|" + "---:|" * 15]
    for r in rows:
        if "error" in r:
            out.append(f"| {r['file']} | {r['firmware']} | {r['solve']} | {r['shaper']} | "
                       f"{r['error'][:140]} |" + " |" * 14)
            continue
        swo = r["steps_while_off"]
        swo_txt = "0" if not any(swo.values()) else "**" + " ".join(f"{k} {v}" for k, v in swo.items() if v) + "**"
        med = r["start_ahead_median_s"]
        med_txt = min(med.values()) if med else float("nan")
        off = off_text(r)
        model = r.get("model_added_pct")
        out.append(
            f"| {r['file']} | {r['firmware']} | {r['solve']} | {r['shaper']} | {r['print_s']:.1f} | "
            f"{r['added_s']:+.2f} ({r['added_pct']:+.2f} %) | {_signed(r.get('batch_kick_s'))} | "
            f"{_signed(r.get('net_added_s'))} ({_signed(r.get('net_added_pct'))} %) | "
            f"{_signed(r.get('priced_s'))} | "
            f"{'—' if model is None else f'{model:+.2f}'} | {r['gating_lines']} | "
            f"{_fmt_num(r.get('per_disable_ms'))} | {r['e_only_extra']:+d} | {_fmt_num(r.get('per_split_ms'))} | "
            f"{swo_txt} | {_ms(r['start_ahead_min_s'])} / {_ms(med_txt)} | {_ms(r['end_late_min_s'])} | "
            f"{off or '—'} | {r['klippy_s']:.1f} |")
    return "\n".join(out)


def off_pairs(r: dict) -> dict[str, tuple[float, float]]:
    """Per gated motor: (off time in the replay, off time gatesopt's report gives outside heat-up
    waits). klippy's batch mode does not wait for its heaters (M109 / M190 / TEMPERATURE_WAIT return
    at once, klippy/extras/heaters.py ``_wait_for_temperature``), so the part of the report's off
    time that lies in those waits (``off_time_waits_s``: the energy profile's heating time, right
    for a printer) has no counterpart in the replay and is left out of the comparison."""
    rep, waits, got = r.get("report_off_time_s") or {}, r.get("off_time_waits_s") or {}, r.get("off_time_s") or {}
    motors = sorted(set(got) | {k for k, v in rep.items() if v})
    return {k: (float(got.get(k, 0.0)), float(rep.get(k, 0.0)) - float(waits.get(k, 0.0))) for k in motors}


def off_deviation(r: dict) -> float:
    """The largest |replay - report| / report over the gated motors (off time outside heat-up
    waits, ``off_pairs``); nan without gating."""
    dev = [abs(a - b) / b if b > 0 else (0.0 if a == 0 else math.inf) for a, b in off_pairs(r).values()]
    return max(dev) if dev else float("nan")


def off_text(r: dict) -> str:
    """"X 80.3/80.9 Y ..." (replay / report outside heat-up waits), with the waits the report
    counts besides where there are some."""
    waits = {k: float(v) for k, v in (r.get("off_time_waits_s") or {}).items() if v and v > 0.05}
    txt = " ".join(f"{k} {a:.1f}/{b:.1f}" for k, (a, b) in off_pairs(r).items())
    if waits:
        txt += " (+ waits " + " ".join(f"{k} {v:.1f}" for k, v in waits.items()) + ")"
    return txt


def _signed(x) -> str:
    return "—" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:+.2f}"


def _fmt_num(x) -> str:
    return "—" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.1f}"


def _range(vals, fmt="{:.1f}") -> str:
    v = [x for x in vals if x is not None and not (isinstance(x, float) and math.isnan(x))]
    if not v:
        return "—"
    lo, med, hi = min(v), float(np.median(v)), max(v)
    return f"{fmt.format(med)} [{fmt.format(lo)}, {fmt.format(hi)}]"


def summary(rows: list[dict]) -> str:
    """One line per (firmware, solve, shaper): how many files replayed, steps while off, the
    start-ahead / end-late minima and the cost of a disable and of a split move."""
    out = ["| firmware | solve | shaper | files | errors | files with steps while off (steps) | "
           "added % median [min, max] | net added % median [min, max] | net − priced s median [min, max] | "
           "ms/disable | ms/split | start-ahead min ms | "
           "start-ahead median ms (per file) | end-late min ms | off within 2 % |",
           "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    keys = list(dict.fromkeys((r["firmware"], r["solve"], r["shaper"]) for r in rows))
    for key in keys:
        rs = [r for r in rows if (r["firmware"], r["solve"], r["shaper"]) == key]
        ok = [r for r in rs if "error" not in r]
        bad = [r for r in ok if any(r["steps_while_off"].values())]
        nsteps = sum(sum(r["steps_while_off"].values()) for r in bad)
        sa = [r["start_ahead_min_s"] for r in ok if not math.isnan(r["start_ahead_min_s"])]
        el = [r["end_late_min_s"] for r in ok if not math.isnan(r["end_late_min_s"])]
        out.append(f"| {key[0]} | {key[1]} | {key[2]} | {len(ok)} | {len(rs) - len(ok)} | "
                   f"{len(bad)} ({nsteps}) | {_range([r['added_pct'] for r in ok], '{:+.2f}')} | "
                   f"{_range([r.get('net_added_pct') for r in ok], '{:+.2f}')} | "
                   f"{_range([r['net_added_s'] - r['priced_s'] for r in ok if 'net_added_s' in r], '{:+.2f}')} | "
                   f"{_range([r.get('per_disable_ms') for r in ok])} | {_range([r.get('per_split_ms') for r in ok])} | "
                   f"{_ms(min(sa)) if sa else '—'} | "
                   f"{_range([1000 * min(r['start_ahead_median_s'].values()) for r in ok if r['start_ahead_median_s']], '{:.2f}')} | "
                   f"{_ms(min(el)) if el else '—'} | {_within(ok)} |")
    return "\n".join(out)


def _within(rows: list[dict], tol: float = 0.02) -> str:
    """"n of m" files with gating whose off times are within ``tol`` of the report's."""
    dev = [off_deviation(r) for r in rows]
    dev = [d for d in dev if not math.isnan(d)]
    return f"{sum(d <= tol for d in dev)} of {len(dev)}" if dev else "—"


def scheduled_table(rows: list[dict]) -> str:
    """One line per output of a dialect whose firmware times its own switches (klipper-gating,
    replayed with its module): what issue 34 asks of it, with the 3dgates optimum of the same file
    and solve (its row in ``rows``) beside the saving."""
    best = {(r["file"], r["solve"]): r.get("saving_pct") for r in rows
            if r.get("firmware") == "3dgates" and "error" not in r}
    out = ["| file | shaper | print s | added s (%) | lines | steps while off | start-ahead min ms | "
           "end-late min ms | pin lead min ms, 1 / 2 back | gated intervals | off s replay / report | "
           "saving % | 3dgates saving % |",
           "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        if r.get("firmware") not in SCHEDULED:
            continue
        if "error" in r:
            out.append(f"| {r['file']} | {r['shaper']} | {r['error'][:120]} |" + " |" * 10)
            continue
        off = off_text(r)
        sav, opt = r.get("saving_pct"), best.get((r["file"], r["solve"]))
        out.append(
            f"| {r['file']} | {r['shaper']} | {r['print_s']:.1f} | {r['added_s']:+.3f} ({r['added_pct']:+.3f} %) | "
            f"{r['gating_lines']} | {sum(r['steps_while_off'].values())} | {_ms(r['start_ahead_min_s'])} | "
            f"{_ms(r['end_late_min_s'])} | {' / '.join(_ms(x) for x in r.get('pin_lead_min_s', ()))}"
            f"{'' if r.get('pin_order_ok', True) else ' (out of order)'} | "
            f"{_fmt_motors(r['gated'], str)} | {off} | "
            f"{'—' if sav is None else f'{sav:.2f}'} | {'—' if opt is None else f'{opt:.2f}'} |")
    return "\n".join(out)


def section(rows: list[dict], command: str, notes: list[str], title: str | None = None) -> str:
    return "\n".join([
        f"## Klipper replay: {title}" if title else SECTION, "",
        "Command (from the repository root; Klipper checkout, klippy Python and MCU dictionary from "
        f"${ENV_KLIPPER}, ${ENV_PYTHON}, ${ENV_DICT}):", "", "```", command, "```", "",
        "Each file and each gatesopt output of it go through Klipper's own host in batch mode on the "
        "printer of bench/klipper/printer.cfg (cartesian, 300 mm/s, 3000 mm/s², square corner "
        "velocity 5, one enable pin per stepper; *shaper*: an `[input_shaper]` section added); the "
        "MCU stream is decoded into step clocks and enable-pin changes. *print s*: the original's "
        "planned time from its first extrusion to its last step; *added*: the output's planned time "
        "minus the original's, in Klipper; *batch kicks*: of that, the late clock restarts klippy's "
        "batch mode makes after a look-ahead flush and a printer does not (the batch flush timer "
        "moves the last step time 0.25 s ahead when it runs between a flush and the next moves, "
        "which depends on where klippy's 4096-byte reads of the file end; logged by "
        "bench/klipper/gatesopt_replay_clock.py; output's less the original's); *net added*: added "
        "less those; *priced s*: what gatesopt's report says the output adds, in seconds "
        "(`print_time_after_s` − `print_time_before_s`); *model %*: the same as a percentage of "
        "gatesopt's total (heater waits included); *lines*: "
        "gating instructions in the output; *ms/disable*: (output − output without its gating "
        "lines) / disable lines, batch kicks left out; *E-only +n*: extrude-only moves the output has more than the "
        "original (split moves); *ms/split*: (output without gating lines − original) / that count, batch kicks left out, "
        "where nothing else changed (no ordering, no rotation); *steps while off*: steps the MCU "
        "was told to take while that motor's enable pin was off; *start-ahead* / *end-late*: over "
        "every gated off interval (a step before and after it): pin on → next step, last step → "
        "pin off; *off s*: total gated off time per motor in Klipper vs gatesopt's `off_time_s` "
        "less its `off_time_waits_s` (klippy's batch mode skips heater waits, M109 / M190 / "
        "TEMPERATURE_WAIT: the off time the report counts in them is shown as *+ waits*); *off "
        "within 2 %*: files whose every gated motor's off time in Klipper is within 2 % of that.",
        "", summary(rows), "", table(rows), "",
        *(["Outputs for gatesopt's Klipper module (`--module`), each solved for the printer.cfg it is "
           "replayed on (`--printer-config`: the shaper's window, the module's options): *steps while "
           "off* over the module's own pin changes; *gated intervals*: off intervals per motor in the "
           "MCU stream; *saving %*: gatesopt's report (the energy model on the verified output); "
           "*3dgates saving %*: the paper's patched-firmware optimum of the same file and solve.", "",
           scheduled_table(rows), ""] if any(r.get("firmware") in SCHEDULED for r in rows) else []),
        *notes])


# --------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------

DEFAULT_FILES = ("real_slic3r131_stars.gcode", "real_prusa240_m486_arcwelder.gcode",
                 "slic3r13_torus_3dhoney20_acp.gcode", "real_ideamaker420.gcode",
                 "cura413_star_triangles20.gcode.gz")


def corpus_files(spec: str | None) -> list[Path]:
    """Comma-separated names or globs; relative ones are looked up in ../shared/instances."""
    if not spec:
        return [SHARED / f for f in DEFAULT_FILES]
    out = []
    for part in spec.split(","):
        part = part.strip()
        pat = part if os.path.isabs(part) or os.path.exists(part) else str(SHARED / part)
        hits = sorted(Path(p) for p in glob.glob(pat) if p.endswith((".gcode", ".gcode.gz")))
        if not hits:
            raise SystemExit(f"klipper_replay: no G-code file matches {part!r} (looked in {SHARED})")
        out += hits
    return out


def _host_or_exit(a) -> KlipperHost:
    host = find_host(a.klipper, a.python, a.dict)
    if isinstance(host, str):
        raise SystemExit("klipper_replay: " + host)
    return host


def _gating_options(a) -> dict[str, str] | None:
    if not a.module:
        if a.gating_option:
            raise SystemExit("klipper_replay: --gating-option needs --module")
        return None
    opts = {}
    for kv in a.gating_option or []:
        k, _, v = kv.partition("=")
        opts[k.strip()] = v.strip()
    return opts


def cmd_config(a) -> int:
    print(printer_config(parse_shaper(a.input_shaper), _gating_options(a), a.pressure_advance))
    return 0


def cmd_replay(a) -> int:
    host = _host_or_exit(a)
    shaper = parse_shaper(a.input_shaper)
    cfg = printer_config(shaper, _gating_options(a), a.pressure_advance)
    text, skipped = replay_text(read_gcode(Path(a.file)))
    with KlippyRunner(host, Path(a.module) if a.module else None) as k:
        rep = k.run(cfg, text, via_parsedump=a.parsedump)
    d = rep.as_dict()
    d["placeholder_lines"] = skipped
    print(json.dumps(d, indent=1, default=float))
    return 0


def cmd_run(a) -> int:
    command = "python bench/klipper_replay.py " + " ".join(shlex.quote(x) for x in sys.argv[1:])
    if a.from_json:
        saved = json.loads(Path(a.from_json).read_text())
        rows, notes, command = saved["rows"], saved["notes"], saved["command"]
    else:
        rows, notes = replay_rows(a)
    print(summary(rows) + "\n\n" + table(rows))
    if any(r.get("firmware") in SCHEDULED for r in rows):
        print("\n" + scheduled_table(rows))
    if a.json:
        Path(a.json).write_text(json.dumps({"command": command, "notes": notes, "rows": rows},
                                           indent=1, default=_json_default))
    if a.write:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from _markdown import replace_section  # bench/_markdown.py
        replace_section(Path(a.write), section(rows, command, notes, a.title))
    return 0


def replay_rows(a) -> tuple[list[dict], list[str]]:
    """Solve every file with every firmware and solve variant, replay original, output and the
    output without its gating lines on every printer variant: one row per output and printer."""
    host = _host_or_exit(a)
    files = corpus_files(a.files)
    shapers = [parse_shaper(s) for s in a.input_shaper.split(",")]
    firmwares = [f.strip() for f in a.firmware.split(",") if f.strip()]
    variants = a.solve_args if a.solve_args is not None else [""]
    gating = _gating_options(a)
    rows: list[dict] = []
    notes: list[str] = []
    work = Path(a.workdir) if a.workdir else Path(tempfile.mkdtemp(prefix="gatesopt-replay-"))
    work.mkdir(parents=True, exist_ok=True)
    with KlippyRunner(host, Path(a.module) if a.module else None) as k:
        for path in files:
            orig_raw = read_gcode(path)
            rel_e = relative_e_undeclared(orig_raw, path.name)
            orig_text, n_ph = replay_text(orig_raw, rel_e)
            if rel_e:
                notes.append(f"- {path.name}: relative E without an M83 of its own (its start macro "
                             "sets it): replayed with an M83 first (original and outputs alike).")
            if n_ph:
                notes.append(f"- {path.name}: {n_ph} lines with unexpanded slicer placeholders "
                             "replayed without those words (original and outputs alike).")
            solved = {}

            def output_of(fw, v, label, cfg):
                # a dialect whose firmware times its own switches (klipper-gating) is solved for the
                # printer it is replayed on (--printer-config: the shaper's window, the module's
                # options); every other dialect once
                # (--stock-printer-config: every dialect so, as a user passing their printer.cfg)
                per_printer = fw in SCHEDULED or a.stock_printer_config
                key = (fw, v, label) if per_printer else (fw, v)
                if key not in solved:
                    extra = shlex.split(v)
                    if fw in SCHEDULED:
                        # the replay's printer runs the module: its lines whatever the file says
                        extra += ["--force-firmware", fw]
                    if per_printer:
                        cfg_path = work / f"printer.{re.sub(r'[^A-Za-z0-9]+', '_', label)}.cfg"
                        cfg_path.write_text(cfg)
                        extra += ["--printer-config", str(cfg_path)]
                    t0 = time.perf_counter()
                    try:
                        solved[key] = (*solve(path, fw, extra, work, tag_extra=label if per_printer else ""),
                                       time.perf_counter() - t0)
                    except ReplayError as exc:
                        solved[key] = exc
                return solved[key]
            for shaper in shapers:
                cfg = printer_config(shaper, gating, a.pressure_advance)
                pins = stepper_pins(cfg)
                label = shaper.label if shaper else "none"
                outputs = {(fw, v): output_of(fw, v, label, cfg) for fw in firmwares for v in variants}
                try:
                    orig = k.run(cfg, orig_text, pins)
                except ReplayError as exc:
                    for fw in firmwares:
                        for v in variants:
                            rows.append({"file": path.name, "firmware": fw, "solve": v or "default",
                                         "shaper": label, "error": f"original: {exc}"})
                    continue
                _progress(f"{path.name} [{label}] original: print {orig.print_s:.1f} s, "
                          f"klippy {orig.klippy_s:.1f} s, decode {orig.decode_s:.1f} s")
                for (fw, v), res in outputs.items():
                    base = {"file": path.name, "firmware": fw, "solve": v or "default", "shaper": label}
                    if isinstance(res, Exception):
                        rows.append({**base, "error": str(res)})
                        continue
                    out_path, report, solve_s = res
                    out_raw = read_gcode(out_path)
                    try:
                        out = k.run(cfg, replay_text(out_raw, rel_e)[0], pins)
                        stripped = k.run(cfg, replay_text(strip_gating_lines(out_raw, fw), rel_e)[0], pins)
                    except ReplayError as exc:
                        rows.append({**base, "error": str(exc)})
                        continue
                    row = {**base, **compare(orig, out, stripped, report, fw, orig_raw, out_raw),
                           "solve_s": solve_s, "unknown_commands": out.unknown,
                           "steppers": {kk: vv.as_dict() for kk, vv in out.steppers.items()}}
                    rows.append(row)
                    _progress(f"  {fw} {v or 'default'}: added {row['added_s']:+.2f} s, steps while off "
                              f"{row['steps_while_off']}, klippy {out.klippy_s:.1f} s")
            if a.json:
                # the rows so far, after each file: an interrupted run keeps them (``--from-json``)
                Path(a.json).write_text(json.dumps({"command": "python bench/klipper_replay.py " + " ".join(
                    shlex.quote(x) for x in sys.argv[1:]), "notes": notes, "rows": rows, "partial": True},
                    indent=1, default=_json_default))
    if not a.workdir:
        shutil.rmtree(work, ignore_errors=True)
    return rows, notes


def cmd_repeat(a) -> int:
    """Replay each file (unchanged) several times: Klipper's batch mode is not always
    repeatable (see docs/RESULTS.md), this measures by how much."""
    host = _host_or_exit(a)
    cfg = printer_config(parse_shaper(a.input_shaper), _gating_options(a), a.pressure_advance)
    pins = stepper_pins(cfg)
    print("| file | replays | end s (min) | spread s | distinct results | klippy s |")
    print("|---|---:|---:|---:|---:|---:|")
    with KlippyRunner(host, Path(a.module) if a.module else None) as k:
        for path in corpus_files(a.files):
            text = replay_text(read_gcode(path))[0]
            reps = [k.run(cfg, text, pins) for _ in range(a.times)]
            ends = [r.end_s for r in reps]
            print(f"| {path.name} | {a.times} | {min(ends):.3f} | {max(ends) - min(ends):.3f} | "
                  f"{len(set(ends))} | {np.mean([r.klippy_s for r in reps]):.1f} |", flush=True)
    return 0


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.integer, np.floating)):
        return o.item()
    return str(o)


def _progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _host_args(p):
    p.add_argument("--klipper", metavar="DIR", help=f"Klipper checkout (default ${ENV_KLIPPER})")
    p.add_argument("--python", metavar="PY", help=f"Python that runs klippy (default ${ENV_PYTHON})")
    p.add_argument("--dict", metavar="FILE", help=f"MCU data dictionary (default ${ENV_DICT}, "
                   "else DIR/out/klipper.dict)")
    p.add_argument("--input-shaper", default="none", metavar="SPEC",
                   help="none, TYPE:HZ (e.g. mzv:30) or TYPE_X:HZ:TYPE_Y:HZ; run: comma-separated variants")
    p.add_argument("--pressure-advance", type=float, metavar="S", help="extruder pressure_advance")
    p.add_argument("--module", metavar="PATH",
                   help="an extras module (gatesopt_gating.py) linked into a temporary copy of klippy; "
                        "adds a [gatesopt_gating] section")
    p.add_argument("--gating-option", action="append", metavar="KEY=VALUE",
                   help="an option of the [gatesopt_gating] section (with --module)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="solve corpus files with gatesopt and replay original and outputs")
    _host_args(r)
    r.add_argument("--files", help="comma-separated names or globs in ../shared/instances "
                   f"(default: {', '.join(DEFAULT_FILES)})")
    r.add_argument("--firmware", default="klipper", help="comma-separated gatesopt dialects")
    r.add_argument("--stock-printer-config", action="store_true",
                   help="solve every dialect with --printer-config the replay's printer.cfg (by "
                        "default only klipper-gating, whose module is on that printer)")
    r.add_argument("--solve-args", action="append", metavar="ARGS",
                   help="extra `gatesopt solve` options, one variant each (repeat; '' = default)")
    r.add_argument("--workdir", help="keep gatesopt's outputs here (default: a temporary folder)")
    r.add_argument("--json", metavar="FILE", help="all rows, with per-stepper details")
    r.add_argument("--from-json", metavar="FILE", help="no replay: the rows of an earlier --json")
    r.add_argument("--title", help="the docs section's heading: '## Klipper replay: TITLE'")
    r.add_argument("--write", nargs="?", const=str(RESULTS), metavar="MD",
                   help=f"put the table into MD (default {RESULTS.relative_to(REPO)})")
    r.set_defaults(func=cmd_run)
    p = sub.add_parser("replay", help="replay one G-code file and print its metrics (JSON)")
    _host_args(p)
    p.add_argument("file")
    p.add_argument("--parsedump", action="store_true", help="decode through klippy's parsedump.py text")
    p.set_defaults(func=cmd_replay)
    q = sub.add_parser("repeat", help="replay files unchanged several times: how repeatable is batch mode")
    _host_args(q)
    q.add_argument("--files")
    q.add_argument("--times", type=int, default=3)
    q.set_defaults(func=cmd_repeat)
    c = sub.add_parser("config", help="print the printer.cfg a replay uses")
    c.add_argument("--input-shaper", default="none")
    c.add_argument("--pressure-advance", type=float)
    c.add_argument("--module")
    c.add_argument("--gating-option", action="append")
    c.set_defaults(func=cmd_config)
    a = ap.parse_args(argv)
    try:
        return a.func(a)
    except (ReplayError, ValueError) as exc:
        raise SystemExit(f"klipper_replay: {exc}")


if __name__ == "__main__":
    sys.exit(main())
