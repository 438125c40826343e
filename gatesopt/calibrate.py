"""Fit a component energy profile to a power-meter log of a real print.

The 3DGates paper built its model from a WattsUp meter (1 s samples) and validated the profiler
at 3.0 % error (Section 3.3.1, Fig. 4). ``calibrate`` does the same for any printer: it aligns a
log of (time, watts) samples with the print's own timeline, then fits the component model of
``gatesopt.energy`` (docs/energy-model.md) by bounded linear least squares:

    P(t) ≈ base_w + hotend_w·duty·[hotend on] + hotend_w·[heating] + bed_w·duty·[bed on]
           + bed_w·[bed heating] + fan_w·fan(t) + moving_extra_w·(motors stepping)
           + Σ_m motor_w[m]·enable_m(t)

Each regressor is averaged over the meter's sample intervals, so a 1 s meter and millisecond
moves meet at the meter's resolution. Columns the print cannot tell apart (a motor that is never
disabled is indistinguishable from the base power) are regularised towards a prior profile and
reported as not identifiable, rather than split arbitrarily.
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field

import numpy as np

from .energy import Profile, load_profile
from .errors import GatesoptError
from .program import Kind, Program

PARAMS = ("base_w", "hotend_w", "bed_w", "fan_w", "moving_extra_w",
          "motor_x_w", "motor_y_w", "motor_z_w", "motor_e_w")


class CalibrationError(GatesoptError):
    """A power log that cannot be used (unreadable, too short, not aligned with the print)."""


@dataclass(frozen=True)
class PowerLog:
    time_s: np.ndarray      # sample times, seconds from the log's first sample
    power_w: np.ndarray     # mean power over the interval ending at each sample
    source: str = "<log>"


@dataclass(frozen=True)
class Calibration:
    params: dict                     # fitted component parameters (W)
    identifiable: dict               # param -> bool
    offset_s: float                  # print start on the log's clock
    time_scale: float                # log seconds per model second
    rel_error: float                 # mean absolute error per sample / mean power
    energy_error: float              # |E_model - E_log| / E_log over the print
    n_samples: int
    profile_toml: str = field(repr=False)


# ------------------------------------------------------------------------------------------------
def read_power_log(path_or_text, source: str | None = None) -> PowerLog:
    """CSV with a time column (seconds, or ISO date-times) and a watts column; header optional."""
    if hasattr(path_or_text, "read"):
        text, name = path_or_text.read(), source or "<log>"
    elif isinstance(path_or_text, str) and "\n" in path_or_text:
        text, name = path_or_text, source or "<log>"
    else:
        name = source or str(path_or_text)
        try:
            with open(path_or_text, newline="") as f:
                text = f.read()
        except OSError as exc:
            raise CalibrationError(f"{name}: cannot read power log: {exc.strerror}") from None
        except UnicodeDecodeError:
            raise CalibrationError(f"{name}: not a power log: not text (a CSV of time, watts)") from None
    rows = list(csv.reader(io.StringIO(text)))
    times, watts = [], []
    for i, row in enumerate(rows, 1):
        if not row or row[0].lstrip().startswith("#"):
            continue
        if len(row) < 2:
            raise CalibrationError(f"{name}:{i}: need two columns (time, watts), got {row!r}")
        t_txt, w_txt = row[0].strip(), row[1].strip()
        try:
            w = float(w_txt)
        except ValueError:
            if i == 1 or not times:     # a header line
                continue
            raise CalibrationError(f"{name}:{i}: watts {w_txt!r} is not a number") from None
        try:
            t = float(t_txt)
        except ValueError:
            try:
                t = np.datetime64(t_txt.replace(" ", "T")).astype("datetime64[ms]").astype(float) / 1000.0
            except ValueError:
                raise CalibrationError(f"{name}:{i}: time {t_txt!r} is neither seconds nor a date-time") from None
        if not (np.isfinite(t) and np.isfinite(w)) or w < 0:
            raise CalibrationError(f"{name}:{i}: bad sample ({t_txt}, {w_txt})")
        times.append(t)
        watts.append(w)
    if len(times) < 10:
        raise CalibrationError(f"{name}: too short: {len(times)} samples (need at least 10)")
    t = np.asarray(times)
    if np.any(np.diff(t) <= 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise CalibrationError(f"{name}: sample times must increase (sample {k + 2})")
    return PowerLog(t - t[0], np.asarray(watts), name)


# ------------------------------------------------------------------------------------------------
def regressors(program: Program, duration_s: np.ndarray, prior: Profile) -> np.ndarray:
    """(n_steps, len(PARAMS)) power per unit parameter for each step (the model is linear)."""
    p = prior.params
    n = program.n_steps
    wait = program.kind == Kind.WAIT
    hot_on = (program.hotend_c > 0).astype(float)
    bed_on = (program.bed_c > 0).astype(float)
    X = np.zeros((n, len(PARAMS)))
    X[:, 0] = 1.0
    X[:, 1] = np.where(wait, 1.0, hot_on * p.get("hotend_hold_duty", 0.3))
    X[:, 2] = np.where(wait, bed_on, bed_on * p.get("bed_hold_duty", 0.3))
    X[:, 3] = program.fan
    X[:, 4] = program.steps_motor().sum(axis=1)
    X[:, 5:9] = program.enabled
    return X


def _integrator(step_end_s: np.ndarray, values: np.ndarray):
    """t -> integral from 0 to t of a piecewise-constant per-step signal (values: n x k)."""
    knots = np.concatenate(([0.0], step_end_s))
    cum = np.concatenate((np.zeros((1, values.shape[1])), np.cumsum(values * np.diff(knots)[:, None], 0)))

    def integral(t):
        t = np.clip(t, 0.0, knots[-1])
        j = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, len(step_end_s) - 1)
        return cum[j] + values[j] * (t - knots[j])[:, None]
    return integral


def _bin_average(integral, edges):
    """Mean of the signal over each [edges[k], edges[k+1])."""
    width = np.maximum(np.diff(edges), 1e-12)
    return (integral(edges[1:]) - integral(edges[:-1])) / width[:, None]


def fit(program: Program, log: PowerLog, *, prior: str | Profile = "component_example",
        duration_s: np.ndarray | None = None, offset_s: float | None = None,
        ridge: float = 1e-3) -> Calibration:
    """Align ``log`` with the print and fit the component parameters."""
    prior = load_profile(prior)
    if prior.kind != "component":
        raise CalibrationError(f"prior profile {prior.name!r} must be a component profile")
    dur = program.duration_s if duration_s is None else np.asarray(duration_s, float)
    step_end = np.cumsum(dur)
    total = float(step_end[-1])
    span = float(log.time_s[-1])
    if span < 0.5 * total:
        raise CalibrationError(f"{log.source}: too short: the log covers {span:.0f} s, the print takes "
                               f"{total:.0f} s under the time model (need at least half)")
    R = regressors(program, dur, prior)
    x0 = np.array([prior.params["base_w"], prior.params["hotend_w"], prior.params["bed_w"],
                   prior.params["fan_w"], prior.params.get("moving_extra_w", 0.0), *prior.params["motor_w"]])
    # a first guess of the power curve, to find where the print sits on the log's clock
    guess = _integrator(step_end, (R @ x0)[:, None])
    edges_log = np.concatenate(([log.time_s[0] - (log.time_s[1] - log.time_s[0])], log.time_s))
    best = (-np.inf, 0.0, 1.0)
    scales = (1.0,) if offset_s is not None else np.linspace(0.8, 1.4, 31)
    offsets = [offset_s] if offset_s is not None else None
    for scale in scales:
        cand = offsets if offsets is not None else np.arange(-0.0, max(span - total * scale, 0.0) + 1e-9,
                                                              max((span - total * scale) / 200.0, 1.0))
        for off in cand:
            model_edges = (edges_log - off) / scale
            inside = (model_edges[:-1] >= 0) & (model_edges[1:] <= total)
            if inside.sum() < 10:
                continue
            pred = _bin_average(guess, model_edges)[:, 0]
            a, b = pred[inside], log.power_w[inside]
            if a.std() == 0 or b.std() == 0:
                score = -np.abs(a - b).mean()
            else:
                score = np.corrcoef(a, b)[0, 1] * inside.mean()
            if score > best[0]:
                best = (score, float(off), float(scale))
    score, off, scale = best
    if not np.isfinite(score):
        raise CalibrationError(f"{log.source}: cannot align the log with the print (no overlap)")
    model_edges = (edges_log - off) / scale
    inside = (model_edges[:-1] >= 0) & (model_edges[1:] <= total)
    A = _bin_average(_integrator(step_end, R), model_edges)[inside]
    y = log.power_w[inside]
    if np.corrcoef(A @ x0, y)[0, 1] < 0.3 if (A @ x0).std() > 0 and y.std() > 0 else False:
        raise CalibrationError(f"{log.source}: the log does not match the print's power pattern "
                               "(best correlation below 0.3): is it the log of this print?")
    # identifiability: a column that is (nearly) a multiple of the constant column cannot be fitted
    # at all (kept at the prior by a stiff ridge); columns equal to each other (X and Y disabled on
    # the same line) are fitted as a sum, split so that their difference stays the prior's
    fixed, ident = {}, {}
    for k, name in enumerate(PARAMS):
        col = A[:, k]
        fixed[name] = bool(k > 0 and col.std() <= 1e-3 * max(abs(col).max(), 1e-12))
    for k, name in enumerate(PARAMS):
        twin = any(j != k and not fixed[PARAMS[j]] and np.allclose(A[:, k], A[:, j], atol=1e-9)
                   for j in range(1, len(PARAMS)))
        ident[name] = not fixed[name] and not (k > 0 and twin)
    # min ||A x - y||^2 + sum_k lam_k^2 (x_k - x0_k)^2 subject to x >= 0
    col_rms = np.sqrt((A ** 2).mean(axis=0))
    lam = np.sqrt(len(y)) * np.maximum(col_rms, 1e-6) * np.array([1e3 if fixed[nm] else ridge for nm in PARAMS])
    # imported here: scipy.optimize takes ~0.5 s to import, and every `gatesopt` command loads
    # this module when the CLI registers its subcommands
    from scipy.optimize import lsq_linear
    res = lsq_linear(np.vstack([A, np.diag(lam)]), np.concatenate([y, lam * x0]), bounds=(0.0, np.inf))
    x = res.x
    pred = A @ x
    rel_error = float(np.abs(pred - y).mean() / max(y.mean(), 1e-12))
    energy_error = float(abs(pred.sum() - y.sum()) / max(y.sum(), 1e-12))
    params = dict(zip(PARAMS, x.tolist()))
    toml = _profile_toml(params, prior, rel_error, log.source, program.source)
    return Calibration(params, ident, off, scale, rel_error, energy_error, int(inside.sum()), toml)


def _profile_toml(params: dict, prior: Profile, rel_error: float, log_name: str, gcode_name: str) -> str:
    p = prior.params
    t = prior.time
    return "\n".join([
        f"# Fitted by `gatesopt calibrate` from {gcode_name} and the power log {log_name}.",
        f"# Mean absolute error per sample: {100 * rel_error:.1f} % of the mean power.",
        'name = "calibrated"',
        'kind = "component"',
        f'description = "fitted from {log_name}"',
        f"base_w = {params['base_w']:.4f}",
        "motor_w = [" + ", ".join(f"{params[k]:.4f}" for k in ("motor_x_w", "motor_y_w", "motor_z_w", "motor_e_w")) + "]",
        f"moving_extra_w = {params['moving_extra_w']:.4f}",
        f"hotend_w = {params['hotend_w']:.4f}",
        f"hotend_hold_duty = {p.get('hotend_hold_duty', 0.3)}",
        f"bed_w = {params['bed_w']:.4f}",
        f"bed_hold_duty = {p.get('bed_hold_duty', 0.3)}",
        f"fan_w = {params['fan_w']:.4f}",
        f"stall_w = {p.get('stall_w', 0.0)}",
        "",
        "[time]",
        f"hotend_heat_c_per_s = {t.hotend_heat_c_per_s}",
        f"bed_heat_c_per_s = {t.bed_heat_c_per_s}",
        f"ambient_c = {t.ambient_c}",
        f"home_s = {t.home_s}",
        "",
    ])


def synthesize_log(program: Program, profile: str | Profile, *, sample_s: float = 1.0, noise_w: float = 0.0,
                   offset_s: float = 0.0, time_scale: float = 1.0, tail_s: float = 30.0, seed: int = 0,
                   duration_s: np.ndarray | None = None) -> PowerLog:
    """A power log as a meter would record ``program`` printed under ``profile``: the print starts
    ``offset_s`` into the log, runs ``time_scale`` times the model's time, idles at the base power
    before and after, and each sample is the mean power over its interval plus Gaussian noise."""
    from .energy import step_power_w
    prof = load_profile(profile)
    dur = program.duration_s if duration_s is None else np.asarray(duration_s, float)
    power = step_power_w(prof.coefficients(program), program.enabled)
    step_end = np.cumsum(dur)
    total = float(step_end[-1]) * time_scale
    n = int(np.ceil((offset_s + total + tail_s) / sample_s))
    edges = np.arange(n + 1) * sample_s
    integral = _integrator(step_end, power[:, None])
    idle = float(prof.params.get("base_w", 0.0))
    model_edges = np.clip((edges - offset_s) / time_scale, 0.0, step_end[-1])
    during = (integral(model_edges[1:]) - integral(model_edges[:-1]))[:, 0] * time_scale
    outside = sample_s - np.diff(np.clip(edges, offset_s, offset_s + total))
    watts = (during + idle * outside) / sample_s
    watts = watts + np.random.default_rng(seed).normal(0.0, noise_w, n)
    return PowerLog(edges[1:] - edges[1], np.maximum(watts, 0.0), "<synthetic>")


def write_power_log(log: PowerLog, path) -> None:
    with open(path, "w", newline="") as f:
        f.write("time_s,watts\n")
        for t, w in zip(log.time_s, log.power_w):
            f.write(f"{t:.3f},{w:.3f}\n")
