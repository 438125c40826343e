"""Why gatesopt does not gate X/Y on corexy printers, in Klipper's own host (gatesopt/kinematics.py).

    python bench/klipper_corexy.py [--files A,B] [--write docs/RESULTS.md]

For each corpus file named (default: the Voron files real_prusa240_m486_arcwelder and
real_superslicer2356_arcwelder), the stock ``klipper`` output gatesopt writes when told the printer
is cartesian (``--printer-config`` bench/klipper/printer.cfg, with the same input shaper as the
replay; ``--no-order --rotate none``: X/Y gated per axis, what gatesopt wrote for every Voron and
Creality K1 file before it read the kinematics) is replayed in klippy on that printer.cfg twice:
as written (cartesian) and with ``kinematics: corexy`` (the file's printer), with no shaper and
with mzv at 30 Hz. The rows count the steps the MCU was told to send to a stepper while gatesopt's
lines held its enable pin off (``StepperReplay.gated_steps_while_off``: a driver switched off does
not take them: a layer shift). Klipper host from $GATESOPT_KLIPPER / $GATESOPT_KLIPPY_PYTHON /
$GATESOPT_KLIPPER_DICT, as bench/klipper_replay.py.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import klipper_replay as kr  # bench/klipper_replay.py
from _markdown import publish  # bench/_markdown.py

ROOT = Path(__file__).resolve().parents[1]
INSTANCES = ROOT.parent / "shared" / "instances"
FILES = "real_prusa240_m486_arcwelder.gcode,real_superslicer2356_arcwelder.gcode"
HEADING = "## Klipper replay: X/Y gating on a corexy printer"


def gatesopt_exe() -> list[str]:
    exe = Path(sys.executable).parent / "gatesopt"
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "gatesopt"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--files", default=FILES)
    ap.add_argument("--write", metavar="MD")
    a = ap.parse_args()
    runner = kr.KlippyRunner(kr.find_host())
    base = kr.BASE_CONFIG.read_text()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for name in a.files.split(","):
            for spec in ("none", "mzv:30"):
                shaper = kr.parse_shaper(spec)
                cart = work / "printer.cfg"
                cart.write_text(kr.printer_config(shaper, base=base))
                out = work / "gated.gcode"
                subprocess.run([*gatesopt_exe(), "solve", str(INSTANCES / name), "-o", str(out), "--force",
                                "--no-order", "--rotate", "none", "--printer-config", str(cart)],
                               check=True, capture_output=True)
                text = out.read_text()
                gcode, _ = kr.replay_text(text)
                for kin in ("cartesian", "corexy"):
                    cfg = kr.printer_config(shaper, base=base.replace("kinematics: cartesian",
                                                                      f"kinematics: {kin}"))
                    rep = runner.run(cfg, gcode)
                    steps = {n: s.gated_steps_while_off for n, s in rep.steppers.items()}
                    gated = {n: s.gated for n, s in rep.steppers.items() if s.gated}
                    rows.append((name, "none" if shaper is None else "mzv 30 Hz", text.count("SET_STEPPER_ENABLE"),
                                 kin, gated, steps))
                    print(*rows[-1], sep="\t", flush=True)
    md = [HEADING, "", "Command: `python bench/klipper_corexy.py --write docs/RESULTS.md` (klippy batch mode, "
          "Klipper 84104bb, the printer of bench/klipper/printer.cfg with its kinematics as in the row).", "",
          "| file | shaper | SET_STEPPER_ENABLE lines | replayed as | gated intervals | steps while the pin was off |",
          "|---|---|---:|---|---|---|"]
    for name, shaper, lines, kin, gated, steps in rows:
        off = ", ".join(f"{n} {v}" for n, v in steps.items() if v) or "0"
        md.append(f"| {name} | {shaper} | {lines} | {kin} | "
                  f"{', '.join(f'{n} {v}' for n, v in gated.items()) or '-'} | {off} |")
    publish("\n".join(md) + "\n", a.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
