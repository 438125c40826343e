"""Replay G-code with GATESOPT_GATE lines through Klipper's own host (klippy batch mode) with
integrations/klipper/gatesopt_gating.py installed, and check the decoded MCU stream.

A throwaway-quality helper for the Klipper module (issue 34) until the emitter exists: it inserts
``GATESOPT_GATE`` lines into real slicer G-code wherever X or Y goes idle (after the last move
that changes X before a motion line that does not, and the same for Y), replays the file with
and without the lines, with and without an input shaper, and reports what the MCU would see:

- steps sent while the stepper's enable pin is off (must be 0);
- start-ahead (pin on -> first step) and end-late (last step -> pin off) minima of the module's
  pin changes (Klipper's own first enable and final disable left out);
- planned print time with and without the lines (every step time of every stepper compared);
- intervals gated and skipped (GATESOPT_GATING_STATUS at the end of the file).

Klipper is taken from GATESOPT_KLIPPER (a Klipper3d/klipper checkout), run with
GATESOPT_KLIPPY_PYTHON, against the MCU data dictionary GATESOPT_KLIPPER_DICT (defaults: this
machine's /work/klipper, /work/klippy-env/bin/python, /work/klipper/out/klipper.dict).

    python bench/klipper_gating.py ../shared/instances/real_slic3r131_stars.gcode \\
        ../shared/instances/slic3r13_torus_3dhoney20_acp.gcode
"""
from __future__ import annotations

import argparse
import gzip
import os
import re
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MODULE = ROOT / "integrations" / "klipper" / "gatesopt_gating.py"
CLOCK_FREQ_HZ = 16_000_000  # the atmega2560 test MCU of the data dictionary

# name: (step_pin, dir_pin, enable_pin); '!' = active-low enable, as on step-stick drivers
STEPPER_PINS = {"stepper_x": ("PF0", "PF1", "!PD7"), "stepper_y": ("PF6", "!PF7", "!PF2"),
                "stepper_z": ("PL3", "PL1", "!PK0"), "extruder": ("PA4", "PA6", "!PA2")}

PRINTER_CFG = """\
# gatesopt bench printer (cartesian, i3-class limits) on Klipper's atmega2560 test MCU.
[mcu]
serial: /dev/null

[printer]
kinematics: cartesian
max_velocity: 300
max_accel: 3000
max_z_velocity: 5
max_z_accel: 100
square_corner_velocity: 5.0

[stepper_x]
step_pin: PF0
dir_pin: PF1
enable_pin: !PD7
microsteps: 16
rotation_distance: 40
endstop_pin: ^PE5
position_endstop: 0
position_min: -20
position_max: 320
homing_speed: 50

[stepper_y]
step_pin: PF6
dir_pin: !PF7
enable_pin: !PF2
microsteps: 16
rotation_distance: 40
endstop_pin: ^PJ1
position_endstop: 0
position_min: -20
position_max: 320
homing_speed: 50

[stepper_z]
step_pin: PL3
dir_pin: PL1
enable_pin: !PK0
microsteps: 16
rotation_distance: 8
endstop_pin: ^PD3
position_endstop: 0
position_min: -2
position_max: 320
homing_speed: 5

[extruder]
step_pin: PA4
dir_pin: PA6
enable_pin: !PA2
microsteps: 16
rotation_distance: 34.406
nozzle_diameter: 0.400
filament_diameter: 1.750
max_extrude_cross_section: 50
max_extrude_only_distance: 1000
heater_pin: PB4
sensor_type: EPCOS 100K B57560G104F
sensor_pin: PK5
control: pid
pid_Kp: 21.5
pid_Ki: 1.06
pid_Kd: 108
min_temp: 0
max_temp: 300

[heater_bed]
heater_pin: PH5
sensor_type: EPCOS 100K B57560G104F
sensor_pin: PK6
control: watermark
min_temp: 0
max_temp: 130

[fan]
pin: PH6

[gcode_arcs]
resolution: 1.0
"""
SHAPER_CFG = "\n[input_shaper]\nshaper_type: mzv\nshaper_freq_x: 30\nshaper_freq_y: 30\n"
GATING_CFG = "\n[gatesopt_gating]\nsteppers: stepper_x, stepper_y\n"


def klipper_setup() -> tuple[Path, Path, Path] | None:
    """(checkout, klippy python, data dictionary) from the environment, or None when absent."""
    checkout = Path(os.environ.get("GATESOPT_KLIPPER", "/work/klipper"))
    python = Path(os.environ.get("GATESOPT_KLIPPY_PYTHON", "/work/klippy-env/bin/python"))
    mcu_dict = Path(os.environ.get("GATESOPT_KLIPPER_DICT", str(checkout / "out" / "klipper.dict")))
    if not ((checkout / "klippy" / "klippy.py").exists() and python.exists() and mcu_dict.exists()):
        return None
    return checkout, python, mcu_dict


def prepare_klippy(checkout: Path, workdir: Path, module: Path = MODULE) -> Path:
    """A copy of the checkout's klippy/ in workdir with the module in extras/ (a copy, not the
    link a user makes: a run must not see the module change under it)."""
    dst = workdir / "klippy"
    if not dst.exists():
        shutil.copytree(checkout / "klippy", dst, ignore=shutil.ignore_patterns("*.pyc", "__pycache__"))
    target = dst / "extras" / "gatesopt_gating.py"
    if target.exists() or target.is_symlink():
        target.unlink()
    shutil.copy(module, target)
    return dst


@dataclass
class Replay:
    steps: dict = field(default_factory=dict)    # stepper name -> sorted step clocks (int64)
    enable: dict = field(default_factory=dict)   # stepper name -> [(clock, enabled)]
    log: str = ""
    responses: str = ""   # G-code responses (from the log)


def run_klippy(klippy: Path, python: Path, mcu_dict: Path, cfg_text: str, gcode_text: str,
               workdir: Path, tag: str, attempts: int = 3) -> Replay:
    """Replay once; again when the MCU stream looks cut short. klippy ends every batch run
    with motor_off (every enable pin switched off after the last step); on this loaded machine
    an output file has been seen to end seconds early once in a few dozen runs."""
    for _ in range(attempts):
        rep = _run_klippy_once(klippy, python, mcu_dict, cfg_text, gcode_text, workdir, tag)
        if all(ev and not ev[-1][1] and (len(rep.steps.get(n, ())) == 0 or ev[-1][0] >= rep.steps[n][-1])
               for n, ev in rep.enable.items()):
            return rep
        print(f"note: klippy output for {tag} cut short; replaying again", file=sys.stderr)
    raise RuntimeError(f"klippy's output for {tag} ends before its final motor_off in {attempts} runs")


def _run_klippy_once(klippy: Path, python: Path, mcu_dict: Path, cfg_text: str, gcode_text: str,
                     workdir: Path, tag: str) -> Replay:
    cfg, gcode = workdir / f"{tag}.cfg", workdir / f"{tag}.gcode"
    serial, log = workdir / f"{tag}.serial", workdir / f"{tag}.log"
    cfg.write_text(cfg_text)
    gcode.write_text(gcode_text)
    for old in (serial, log):
        if old.exists():
            old.unlink()   # klippy appends to an existing log
    run = subprocess.run([str(python), str(klippy / "klippy.py"), str(cfg), "-i", str(gcode),
                          "-o", str(serial), "-v", "-d", str(mcu_dict), "-l", str(log)],
                         capture_output=True, text=True, timeout=3600)
    log_text = log.read_text() if log.exists() else ""
    if run.returncode != 0:
        raise RuntimeError(f"klippy failed ({run.returncode}):\n{run.stderr[-3000:]}\n{log_text[-3000:]}")
    dump = subprocess.run([str(python), str(klippy / "parsedump.py"), str(mcu_dict), str(serial)],
                          capture_output=True, text=True, check=True).stdout
    rep = decode(dump, cfg_text)
    rep.log = log_text
    rep.responses = log_text   # respond_info lines are logged too
    return rep


def _unwrap(clock32: int, ref: int) -> int:
    """The 64-bit clock equal to clock32 modulo 2**32 nearest to ref."""
    diff = (clock32 - ref) & 0xFFFFFFFF
    if diff >= 1 << 31:
        diff -= 1 << 32
    return ref + diff


def decode(dump: str, cfg_text: str) -> Replay:
    """Step clocks and enable-pin changes per stepper from parsedump.py's text."""
    pins = {}
    for name, (step, _d, en) in STEPPER_PINS.items():
        if f"[{name}]" in cfg_text:
            pins[name] = (step, en.lstrip("!"), en.startswith("!"))
    step_oid, en_oid, inverted = {}, {}, {}
    last, pending_reset, chunks = {}, {}, {}
    events = {}
    ref = 0
    field_re = re.compile(r"(\w+)=(\S+)")
    for line in dump.splitlines():
        cmd, _, rest = line.partition(" ")
        if cmd not in ("config_stepper", "config_digital_out", "queue_step", "reset_step_clock",
                       "queue_digital_out"):
            continue
        f = dict(field_re.findall(rest))
        oid = int(f["oid"])
        if cmd == "config_stepper":
            for name, (step, _en, _inv) in pins.items():
                if f["step_pin"] == step:
                    step_oid[oid] = name
                    last[oid], chunks[oid] = 0, []
        elif cmd == "config_digital_out":
            for name, (_step, en, inv) in pins.items():
                if f["pin"] == en:
                    en_oid[oid], inverted[oid] = name, inv
                    events[name] = []
        elif cmd == "reset_step_clock" and oid in step_oid:
            pending_reset[oid] = int(f["clock"])
        elif cmd == "queue_step" and oid in step_oid:
            interval, count, add = int(f["interval"]), int(f["count"]), int(f["add"])
            if oid in pending_reset:
                first = _unwrap((pending_reset.pop(oid) + interval) & 0xFFFFFFFF, ref)
                base = first - interval
            else:
                base = last[oid]
            k = np.arange(1, count + 1, dtype=np.int64)
            clocks = base + k * interval + add * (k - 1) * k // 2
            chunks[oid].append(clocks)
            last[oid] = int(clocks[-1])
            ref = max(ref, last[oid])
        elif cmd == "queue_digital_out" and oid in en_oid:
            clock = _unwrap(int(f["clock"]), ref)
            ref = max(ref, clock)
            level = int(f["on_ticks"]) != 0
            events[en_oid[oid]].append((clock, level != inverted[oid]))
    rep = Replay()
    for oid, name in step_oid.items():
        rep.steps[name] = np.sort(np.concatenate(chunks[oid])) if chunks[oid] else np.zeros(0, np.int64)
    for name, ev in events.items():
        rep.enable[name] = sorted(ev)
    return rep


def pin_queue_metrics(rep: Replay, name: str, slots: int) -> dict:
    """The pin's queue_digital_out messages as the MCU takes them: ``ordered`` (clocks increasing:
    its queue is FIFO, src/gpiocmds.c) and ``lead_min_s``, the least time from a change to the
    change ``slots`` back -- the lead each message has when serialqueue releases it at its minclock
    (the change that many back: the module's PinQueue, or Klipper's set_digital for one slot);
    None with no such pair."""
    clocks = np.array([c for c, _ in rep.enable.get(name, [])], dtype=np.int64)
    lead = clocks[slots:] - clocks[:-slots] if len(clocks) > slots else np.zeros(0, np.int64)
    return {"changes": len(clocks), "ordered": bool(np.all(np.diff(clocks) > 0)),
            "lead_min_s": float(lead.min()) / CLOCK_FREQ_HZ if len(lead) else None}


def pin_metrics(rep: Replay, name: str) -> dict:
    """Steps while off, and start-ahead / end-late minima (s) of the pin changes between the
    first enable and the last disable (Klipper's own)."""
    steps = rep.steps.get(name, np.zeros(0, np.int64))
    ev = rep.enable.get(name, [])
    clocks = np.array([c for c, _ in ev], dtype=np.int64)
    states = np.array([s for _, s in ev], dtype=bool)
    if len(steps) == 0 or len(ev) == 0:
        return {"steps": len(steps), "steps_while_off": int(len(steps)) if len(ev) == 0 else 0,
                "steps_before_first_enable": 0, "offs": 0, "start_ahead_min_s": None, "end_late_min_s": None, "off_time_s": 0.0}
    idx = np.searchsorted(clocks, steps, side="right") - 1
    on_at_step = np.where(idx >= 0, states[np.maximum(idx, 0)], False)
    # Klipper's own auto-enable at the first move comes after the first shaped steps (the stock
    # behaviour issue 34 measured): those steps are counted apart from the module's window
    before_first = int(np.count_nonzero(idx < 0))
    while_off = int(np.count_nonzero(~on_at_step)) - before_first
    start_ahead, end_late, off_time = [], [], 0.0
    # module changes: every change after the first "on" and before the last "off"
    changes = [(c, s) for i, (c, s) in enumerate(ev) if i == 0 or s != ev[i - 1][1]]
    first_on = next((i for i, (_, s) in enumerate(changes) if s), None)
    last_off = max((i for i, (_, s) in enumerate(changes) if not s), default=None)
    offs = 0
    for i, (c, s) in enumerate(changes):
        if first_on is None or i <= first_on or (last_off is not None and i >= last_off and not s):
            continue
        if s:   # on: next step after it
            j = np.searchsorted(steps, c, side="left")
            if j < len(steps):
                start_ahead.append((steps[j] - c) / CLOCK_FREQ_HZ)
            prev_off = changes[i - 1][0]
            off_time += (c - prev_off) / CLOCK_FREQ_HZ
        else:   # off: last step before it
            offs += 1
            j = np.searchsorted(steps, c, side="right") - 1
            if j >= 0:
                end_late.append((c - steps[j]) / CLOCK_FREQ_HZ)
    return {"steps": int(len(steps)), "steps_while_off": while_off,
            "steps_before_first_enable": before_first, "offs": offs,
            "start_ahead_min_s": min(start_ahead) if start_ahead else None,
            "end_late_min_s": min(end_late) if end_late else None, "off_time_s": off_time}


def planned_time_diff_s(a: Replay, b: Replay) -> float:
    """Largest difference (s) between the step times of two replays of the same moves; inf
    when the step counts differ."""
    worst = 0.0
    for name in a.steps:
        sa, sb = a.steps[name], b.steps.get(name, np.zeros(0, np.int64))
        if len(sa) != len(sb):
            return float("inf")
        if len(sa):
            worst = max(worst, float(np.max(np.abs(sa - sb))) / CLOCK_FREQ_HZ)
    return worst


def last_step_s(rep: Replay) -> float:
    return max(float(s[-1]) for s in rep.steps.values() if len(s)) / CLOCK_FREQ_HZ


_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")


def insert_gate_lines(text: str, axes: dict | None = None) -> tuple[str, int]:
    """Insert ``GATESOPT_GATE STEPPERS=...`` after the last motion line that changes an axis
    before a motion line that does not (axes: G-code letter -> stepper name; default X and Y).
    G2/G3 and G28 count as changing X and Y. Returns the text and the number of lines added."""
    axes = axes or {"X": "stepper_x", "Y": "stepper_y"}
    lines = text.splitlines(keepends=True)
    pos = {a: None for a in axes}
    relative = False
    motion = []   # (line index, set of axes changed)
    for i, raw in enumerate(lines):
        code = raw.split(";", 1)[0].strip().upper()
        if not code:
            continue
        words = dict((k, float(v)) for k, v in _WORD.findall(code[1:] if code[0] in "GM" else ""))
        head = code.split()[0]
        if head == "G90":
            relative = False
        elif head == "G91":
            relative = True
        elif head == "G92":
            for a in axes:
                if a in words:
                    pos[a] = words[a]
        elif head in ("G28",):
            for a in axes:
                pos[a] = None
            motion.append((i, set(axes)))
        elif head in ("G2", "G3", "G02", "G03"):
            for a in axes:
                if a in words:
                    pos[a] = (pos[a] or 0.0) + words[a] if relative else words[a]
            motion.append((i, set(axes)))
        elif head in ("G0", "G1", "G00", "G01"):
            changed = set()
            for a in axes:
                if a in words:
                    new = (pos[a] or 0.0) + words[a] if relative else words[a]
                    if pos[a] is None or abs(new - pos[a]) > 1e-9:
                        changed.add(a)
                    pos[a] = new
            if changed or any(k in words for k in "XYZE"):
                motion.append((i, changed))
    after = {}
    for (i, ch), (_j, nxt) in zip(motion, motion[1:]):
        for a in sorted(ch - nxt):
            after.setdefault(i, []).append(axes[a])
    out, added = [], 0
    for i, raw in enumerate(lines):
        out.append(raw if raw.endswith("\n") else raw + "\n")
        if i in after:
            out.append("GATESOPT_GATE STEPPERS=%s\n" % ",".join(after[i]))
            added += 1
    return "".join(out), added


STATUS_RE = re.compile(r"(stepper_\w+): (enabled|disabled); gated (\d+); off ([\d.]+) s; skipped ([a-z_ \d]+);")


def gating_status(rep: Replay) -> dict:
    """The module's GATESOPT_GATING_STATUS answer (the last one in the replay's output)."""
    out = {}
    for m in STATUS_RE.finditer(rep.responses):
        words = m.group(5).split()
        skipped = {} if words == ["none"] else {r: int(n) for r, n in zip(words[::2], words[1::2])}
        out[m.group(1)] = {"gated": int(m.group(3)), "off_time_s": float(m.group(4)), "skipped": skipped}
    return out


def read_gcode(path: Path) -> str:
    raw = path.read_bytes()
    return (gzip.decompress(raw) if path.name.endswith(".gz") else raw).decode("utf-8", "replace")


def replay_file(path: Path, workdir: Path, klippy: Path, python: Path, mcu_dict: Path) -> list[dict]:
    text = read_gcode(path)
    gated_text, added = insert_gate_lines(text)
    gated_text += "GATESOPT_GATING_STATUS\n"
    rows = []
    for shaper in (False, True):
        cfg = PRINTER_CFG + (SHAPER_CFG if shaper else "")
        base = run_klippy(klippy, python, mcu_dict, cfg, text, workdir, "base")
        unknown = run_klippy(klippy, python, mcu_dict, cfg, gated_text, workdir, "unknown")
        gated = run_klippy(klippy, python, mcu_dict, cfg + GATING_CFG, gated_text, workdir, "gated")
        status = gating_status(gated)
        # base vs the same lines unknown to Klipper: what the extra lines alone do to batch-mode
        # timing; unknown vs module: what the module does
        row = {"file": path.name, "shaper": "mzv 30 Hz" if shaper else "none", "lines": added,
               "planned_s": last_step_s(base), "lines_diff_s": planned_time_diff_s(base, unknown),
               "planned_diff_s": planned_time_diff_s(unknown, gated)}
        for name in ("stepper_x", "stepper_y"):
            m = pin_metrics(gated, name)
            st = status.get(name, {})
            row[name] = dict(m, gated=st.get("gated"), skipped=st.get("skipped"))
        rows.append(row)
    return rows


def _fmt(v, scale=1e3):
    return "-" if v is None else "%.3f" % (v * scale)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--module", type=Path, default=MODULE,
                    help="the module file to install (default: integrations/klipper/gatesopt_gating.py)")
    args = ap.parse_args(argv)
    setup = klipper_setup()
    if setup is None:
        print("no Klipper checkout (set GATESOPT_KLIPPER, GATESOPT_KLIPPY_PYTHON, GATESOPT_KLIPPER_DICT)")
        return 2
    checkout, python, mcu_dict = setup
    with tempfile.TemporaryDirectory(prefix="gatesopt-kmod-") as tmp:
        work = Path(tmp)
        klippy = prepare_klippy(checkout, work, args.module)
        print("| file | shaper | lines | planned s | lines alone us | module us | stepper | steps while off |"
              " (before Klipper's first enable) | offs | gated | skipped | start-ahead min ms |"
              " end-late min ms | off s |")
        print("|" + "---|" * 15)
        for path in args.files:
            for row in replay_file(path, work, klippy, python, mcu_dict):
                for name in ("stepper_x", "stepper_y"):
                    m = row[name]
                    sk = ", ".join(f"{k} {v}" for k, v in sorted((m["skipped"] or {}).items()))
                    print(f"| {row['file']} | {row['shaper']} | {row['lines']} | {row['planned_s']:.3f} |"
                          f" {row['lines_diff_s'] * 1e6:.3f} | {row['planned_diff_s'] * 1e6:.3f} | {name} |"
                          f" {m['steps_while_off']} |"
                          f" {m['steps_before_first_enable']} |"
                          f" {m['offs']} | {m['gated']} | {sk or '-'} | {_fmt(m['start_ahead_min_s'])} |"
                          f" {_fmt(m['end_late_min_s'])} | {m['off_time_s']:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
