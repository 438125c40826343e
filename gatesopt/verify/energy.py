"""Check 5, ``energy``: energy and time recomputed from the output's text with the one model
(``gatesopt.energy``, stalls from ``gatesopt.firmware``) against what the solver claimed."""
from __future__ import annotations

import numpy as np

from .. import firmware as fwmod
from ..energy import load_profile, step_energy_j
from ..planner import enable_price
from ..program import Kind, Program
from .finding import Finding
from .motor_lines import read_motor_rows
from .schedule import scheduled_energy

CLAIM_REL_TOL = 1e-6


def _file_enable(program: Program, original: Program | None = None) -> np.ndarray:
    """(n, 4) motor state as the slicer's file has it: the parsed state with the effect of every
    inserted disable undone (a motor held off by a gating line counts as on). ``original`` tells
    the file's own motor lines from inserted ones (``own_motor_rows``)."""
    en = np.asarray(program.enabled, bool).copy()
    rows = np.flatnonzero(program.kind == Kind.MOTOR)
    if not len(rows):
        return en
    parsed, on, mask, own = read_motor_rows(program, rows, original)
    inserted_off = ~on & ~own
    idx = np.arange(program.n_steps)
    for m in range(4):
        sel = parsed & (mask >> m & 1).astype(bool)
        if not sel.any():
            continue
        k = np.searchsorted(rows[sel], idx, "right") - 1
        held = (k >= 0) & inserted_off[sel][np.maximum(k, 0)]
        en[held, m] = True
    return en


def stall_s(program: Program, firmware, printer=None) -> np.ndarray:
    """``firmware.stall_durations`` with the per-move price of a dialect whose enable line is a
    stop (Klipper's ``ENABLE=1`` flush; ``planner.stop_restart_s``) or whose disable line is one
    (Marlin's ``M18`` drain, Klipper's ``ENABLE=0``), as the solver priced it."""
    fw = fwmod.get(firmware)
    price = None
    if fw.enable_is_stop or fw.disable_is_stop:
        price = enable_price(fw.planner.family if fw.planner is not None else None, printer)
    return fwmod.stall_durations(program, fw, enable_price=price, printer=printer)


def energy_of(program: Program, *, firmware="3dgates", profile="paper", duration_s=None,
              original: Program | None = None, scheduled=None, printer=None):
    """(energy J, time s, stall s) of ``program`` recomputed from its text with the one model.

    A firmware stall at a motor instruction is priced with the motors as the slicer's file has
    them (``_file_enable``; ``original`` tells the file's own motor lines from inserted ones): the
    whole printer keeps drawing power while the firmware drains its queue or dwells, and no gating
    credit is taken for it -- the convention of ``gatesopt.gating.problem`` (``stall_coeffs``
    priced with ``enable0``).

    ``scheduled``: for a firmware that times its own switches, the (line, motor) pairs as it
    carries them out (``schedule.scheduled_lines``): the motors are then off over those intervals
    only, not from an added line to the motor's next step as the parsed state has them.
    ``printer``: the printer's Klipper config (the planner limits of a per-move stall price)."""
    if scheduled is not None:
        stall = stall_s(program, firmware, printer)
        return (*scheduled_energy(program, scheduled, _file_enable(program, original), stall, profile=profile,
                                  duration_s=duration_s), float(stall.sum()))
    prof = load_profile(profile)
    coeffs = prof.coefficients(program)
    stall = stall_s(program, firmware, printer)
    dur = (program.duration_s if duration_s is None else np.asarray(duration_s, float)) + stall
    en = np.asarray(program.enabled, bool).copy()
    motor = program.kind == Kind.MOTOR
    if motor.any():
        en[motor] = _file_enable(program, original)[motor]
    e = step_energy_j(dur, coeffs, en)
    return float(e.sum()), float(dur.sum()), float(stall.sum())


def claimed_energy_time(claimed):
    """(energy J, time s) the solver claimed, either None where it said nothing; None for no
    claim. ``claimed``: a GatingSolution, a ``gatesopt solve --json`` report, or a pair."""
    if claimed is None:
        return None
    if isinstance(claimed, dict):
        # a `gatesopt solve --json` report: the solver's own numbers where present
        e = claimed.get("objective_j", claimed.get("energy_after_j", claimed.get("energy_j")))
        t = claimed.get("objective_time_s", claimed.get("time_after_s", claimed.get("time_s")))
        return e, t
    if isinstance(claimed, (tuple, list)):
        return claimed[0], claimed[1]
    return getattr(claimed, "energy_j", None), getattr(claimed, "time_after_s", getattr(claimed, "time_s", None))


def check_claim(claimed: tuple, energy_j: float, time_s: float, *,
                rel_tol: float = CLAIM_REL_TOL) -> list[Finding]:
    """The solver's ``claimed`` (energy J, time s) (``claimed_energy_time``; None: not claimed)
    against ``energy_j`` / ``time_s`` recomputed from the text (``energy_of``)."""
    out: list[Finding] = []
    ce, ct = claimed
    if ce is not None and abs(ce - energy_j) > rel_tol * max(abs(energy_j), 1e-12):
        out.append(Finding("energy", None, f"energy recomputed from the text {energy_j:.6f} J, "
                                           f"solver claimed {ce:.6f} J (rel. diff "
                                           f"{abs(ce - energy_j) / max(abs(energy_j), 1e-12):.2e})"))
    if ct is not None and abs(ct - time_s) > rel_tol * max(abs(time_s), 1e-12):
        out.append(Finding("energy", None, f"time recomputed from the text {time_s:.6f} s, "
                                           f"solver claimed {ct:.6f} s"))
    return out
