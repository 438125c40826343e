"""The figures every report gives of a print, one of each, each named with its model, the same in
``solve``, ``order``, ``batch``, ``compare``, the HTML report and the library's results:

print time (``print_time_s``)
    The planner model (``gatesopt.planner``: trapezoidal velocity profiles, junction speeds, the
    machine limits the file sets; a line that drains the firmware's queue, Marlin's ``M18``,
    Klipper's ``SET_STEPPER_ENABLE``, brings the head to rest) plus the firmware's dwells
    (``firmware.stall_durations``: Klipper's 2 x 0.1 s and restarts; Marlin's full stop is the
    planner's already). A gated output and its original are timed by the dialect's planner rules
    and, given, the printer's config (``--printer-config``: its limits, its shaper's restarts), as
    the gating problem prices the lines. Measured against the slicers' own estimates it is within a few per cent
    (PrusaSlicer files +3..+9 %, Cura's -15..+7 %, docs/RESULTS.md "Time model"), where the
    paper's T = L / F is 20-27 % under PrusaSlicer's. It is the one print time a report shows.
    The paper's T = L / F (3DGates Eq. 2) stays what the *energy* model integrates over (the
    3DGates power tables were fitted on it, and the solver's budgets are shares of it): reports
    name it "paper time" where they give it at all (``PAPER_TIME_WORDS``).
travel (``travel``)
    Measured on the parsed file as it is printed (``ordering.travel_stats``): every
    non-extruding XY move from the first layer on, its count, and retractions. Never the
    curve-ordering solver's model travel (straight links between curve ends, the origin first),
    which the ordering's own report names ``model_travel_*_mm``.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .. import firmware as fwmod
from ..energy import profile
from ..ordering.travel_stats import travel_stats
from ..limits import machine_limits
from ..planner import durations
from ..program import Kind, Program
from ..verify.energy import stall_s
from .printer import file_firmware as printer_file_firmware

#: the model of the print time the reports give, and how they say it
PRINT_TIME_MODEL = "planner"
PRINT_TIME_WORDS = "planner model: acceleration, junction speeds, firmware stops"
#: the time the energy model integrates over (and the solver's time budget is a share of)
PAPER_TIME_WORDS = "paper time T = L/F"
ENERGY_WORDS = "3DGates model over the paper's T = L/F times, firmware stalls included"
#: what "travel" is in every report
TRAVEL_WORDS = "measured on the file: non-extruding XY moves from the first layer"


def _no_stall(program: Program, row: int) -> float:
    return 0.0      # the planner's durations already stop the head at a queue-draining line


def _no_enable_stop(program: Program, rows):
    return [0.0] * len(rows)    # the same for an enable line that stops (Klipper): its restart stays


def print_time_s(program: Program, firmware: str = "3dgates",
                 planned_s: np.ndarray | None = None, printer=None, family: str | None = None) -> float:
    """The print time of ``program`` under the planner model, firmware dwells included (module
    docstring): every step of the file, heat-up waits and homing at their profile durations.
    ``planned_s``: ``planner.plan(program).duration_s``, where the caller has it (the time
    guard planned the file already). ``printer``: the printer's Klipper config
    (``--printer-config``): its limits plan the moves (``limits.machine_limits``, the firmware's
    planner rules) and its input shaper's step window prices each flush's restart
    (``Firmware.enable_fixed_s``: 28.6 ms at mzv 30 Hz where 2 ms without), as the gating problem
    prices them; without it the file's limits and the dialect's defaults. ``family``: the planner
    rules to plan by (``GatingOptions.planner_family``, as the gating problem and the verifier
    plan a dialect's output; None: the file's own, ``limits.default_family``, or Klipper's with a
    printer config)."""
    if planned_s is not None:
        planned = planned_s
    elif printer is None and family is None:
        planned = durations(program, "planner")
    else:
        # the dialect's own planner rules, as the gating problem and the verifier plan it: a
        # stock klipper output of a PrusaSlicer file is planned by Klipper's rules, not by the
        # Marlin rules its flavor names (which made real_prusa233_multi's output 2.4 s shorter
        # than its original, its 63 gates priced 10.44 s where Klipper took 14.06 s)
        planned = durations(program, "planner", machine_limits(program, family=family, printer=printer))
    stall = fwmod.stall_durations(program, firmware, planner=_no_stall, enable_price=_no_enable_stop,
                                  printer=printer)
    return float(planned.sum() + stall.sum())


def stalls_s(program: Program, firmware: str, time_model: str) -> np.ndarray:
    """Per-step firmware stall seconds of ``program``'s own motor lines in ``firmware``, on top of
    ``time_model``'s durations: "planner", what its durations leave out (Klipper's dwells; a
    queue drain is in them already), as ``print_time_s`` counts; "paper", every stall as the
    verifier and the energy model price it (``verify.energy.stall_s``: Marlin's stop priced per move)."""
    if time_model == "planner":
        return fwmod.stall_durations(program, firmware, planner=_no_stall, enable_price=_no_enable_stop)
    return stall_s(program, firmware)


def stall_enable(program: Program, stall: np.ndarray) -> np.ndarray:
    """The motors' state during each step, every motor on during a stall at a motor line: the
    whole printer keeps drawing power while the firmware drains its queue or dwells, no gating
    credit taken for it -- the convention of the verifier and the gating problem
    (``verify.energy.energy_of``, which holds on the motors the rewrite's own lines switched off;
    a file's own line that stalls with a motor off is the one case priced differently)."""
    en = np.asarray(program.enabled, bool).copy()
    en[(stall > 0) & (program.kind == Kind.MOTOR)] = True
    return en


def profile_report(program: Program, prof, time_model: str, energy_time_model: str,
                   firmware: str = "3dgates", limits=None) -> tuple:
    """The report of ``program``: energy over ``energy_time_model``'s durations, times (total, by
    kind, per layer, the plot's time axis) under ``time_model``'s; and those durations. The
    stalls of the file's motor lines in ``firmware`` (the dialect its printer runs,
    ``figures.file_firmware``) count in both, as ``solve`` and ``verify`` count them
    (``stalls_s``): a gated output profiles to the energy and print time its run reported.
    ``limits``: the planner's (default: ``machine_limits`` of the program; a piece of a file read
    in pieces gets the file's, ``limits.PieceLimits``). ``gatesopt profile``'s report, whole or
    streamed."""
    shown = durations(program, model=time_model, limits=limits) + stalls_s(program, firmware,
                                                                             time_model)
    stall = stalls_s(program, firmware, energy_time_model)
    under = shown if energy_time_model == time_model else durations(program, model=energy_time_model,
                                                                         limits=limits) + stall
    en = stall_enable(program, stall)
    report = profile(program, prof, duration_s=under, enable=en)
    if energy_time_model != time_model:
        rt = profile(program, prof, duration_s=shown, enable=en)
        report = dataclasses.replace(report, time_s=rt.time_s, by_kind_s=rt.by_kind_s,
                                     layer_time_s=rt.layer_time_s, step_end_s=rt.step_end_s,
                                     energy_time_s=float(np.sum(under)))
    return report, shown


def travel(program: Program) -> dict:
    """``travel_mm``, ``travels``, ``retractions`` of the file as printed (``travel_stats``)."""
    t = travel_stats(program)
    return {"travel_mm": t["travel_mm"], "travels": t["travels"], "retractions": t["retractions"],
            "wipes": t["wipes"]}


def pct(after: float, before: float) -> float:
    return 100.0 * (after / before - 1.0) if before else 0.0


def file_firmware(program: Program) -> str:
    """The dialect the file's own printer runs (``printer.file_firmware``: what ``solve`` would
    write for it), "3dgates" where gatesopt writes nothing for it: the firmware a file's print
    time is figured under when no gating chose one (``order``, ``solve --no-gating``), so that
    every command gives one print time for one file."""
    return printer_file_firmware(program)[1]


def print_times(original: Program, output: Program, firmware: str, gated: bool, printer=None) -> tuple:
    """(before s, after s): the print times (planner model, ``print_time_s``) of a rewrite as
    ``solve`` reports them: a gated output (``gated``: it has motor lines the rewrite added) and
    its original by ``firmware``'s planner rules and the printer's config, as gating priced them;
    else both by the file's own (``figures`` without a firmware). What ``verify`` reports beside
    the paper's time."""
    if not gated:
        f = file_firmware(original)
        return print_time_s(original, f), print_time_s(output, f)
    fw = fwmod.get(firmware)
    family = fw.planner.family if fw.planner else None
    return (print_time_s(original, firmware, printer=printer, family=family),
            print_time_s(output, firmware, printer=printer, family=family))


def figures(before: Program, after: Program, firmware: str | None = None,
            before_s: float | None = None, planned_s: tuple = (None, None), printer=None,
            family: str | None = None) -> dict:
    """The report keys of both files: ``print_time_before_s`` / ``_after_s`` / ``_change_pct``
    with ``print_time_model``, and ``travel_before_mm`` / ``_after_mm`` / ``_change_pct``,
    ``travels_*``, ``retractions_*``. ``firmware``: the dialect the output's motor lines are in
    (None: the file's own, ``file_firmware``); ``before_s``: ``before``'s print time in that
    firmware where the caller has it already; ``planned_s``: both files' per-step planner
    durations where the caller has them (``print_time_s``; None: planned here); ``printer``,
    ``family``: the printer's Klipper config and the planner rules both are timed on
    (``print_time_s``)."""
    firmware = firmware or file_firmware(before)
    tb = print_time_s(before, firmware, planned_s[0], printer, family) if before_s is None else float(before_s)
    ta = print_time_s(after, firmware, planned_s[1], printer, family)
    mb, ma = travel(before), travel(after)
    return {
        "print_time_before_s": tb, "print_time_after_s": ta, "print_time_change_pct": pct(ta, tb),
        "print_time_model": PRINT_TIME_MODEL,
        "travel_before_mm": mb["travel_mm"], "travel_after_mm": ma["travel_mm"],
        "travel_change_pct": pct(ma["travel_mm"], mb["travel_mm"]),
        "travels_before": mb["travels"], "travels_after": ma["travels"],
        "retractions_before": mb["retractions"], "retractions_after": ma["retractions"],
        "wipes_before": mb["wipes"], "wipes_after": ma["wipes"],
    }


def figure_notes(fig: dict, saving_pct: float | None = None, gated: bool = True) -> list[str]:
    """What the figures of a re-ordered run say that its numbers alone do not: fewer or more wipes
    than the slicer's (a rebuilt travel wipes where it retracts and can: ``ordering.wipes``), and,
    where nothing was gated, why the energy can grow while the print time falls (two time
    models)."""
    notes = []
    lost = fig.get("wipes_before", 0) - fig.get("wipes_after", 0)
    if lost > 0:
        notes.append(f"{lost:,} fewer wipes than the slicer's {fig['wipes_before']:,}: a rebuilt "
                     "travel wipes where it retracts, as the slicer does (except out of a loop "
                     "left at another seam); a travel the re-ordering made short enough not to "
                     "retract does not wipe; --no-order keeps them all")
    elif lost < 0:
        notes.append(f"{-lost:,} more wipes than the slicer's {fig['wipes_before']:,}: a rebuilt "
                     "travel that retracts wipes as the slicer wipes after most of its "
                     "retractions (ordering.wipes.WIPING_SHARE), also where the slicer's own "
                     "travel there retracted without one; --no-order keeps the slicer's")
    if (not gated and saving_pct is not None and saving_pct < 0
            and fig["print_time_after_s"] < fig["print_time_before_s"]):
        notes.append(f"nothing gated: the energy change ({-saving_pct:.2f} % more) is the "
                     "re-ordering's, under the 3DGates model's T = L/F times, where the travel it "
                     f"rebuilt is {fig['travel_change_pct']:+.1f} %; the planner model's print time "
                     f"is {fig['print_time_change_pct']:+.1f} %")
    return notes
