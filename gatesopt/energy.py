"""Energy model and profiler: the one model every solver and the verifier share.

3DGates (Chen et al., ASPLOS'17) Section 3.2: the energy of instruction i is E_i = P_i * T_i
(Eq. 2), and of the print the sum over instructions (Eq. 3). Here P_i is written as

    P_i = base_w[i] + sum_m enable[i, m] * motor_w[i, m] + (not X and not Y) * xy_off_w[i]

so that a power-gating decision (``enable``, n x 4 booleans, X Y Z E) enters linearly, with one
non-additive term for the case that both XY motors are off (the paper measures only one gated).
A ``Profile`` turns a Program into these coefficients; ``step_energy_j`` is the single function
that turns coefficients, durations and an enable matrix into energy. Solvers call it on their
candidates, the verifier on the re-parsed output.

Profiles are TOML files (``gatesopt/profiles/*.toml``): ``kind = "table"`` reproduces the paper's
Tables 2 and 4 exactly; ``kind = "component"`` is base + per-motor + heaters + fan for users who
measured their own printer.
"""
from __future__ import annotations

import dataclasses
import functools
import importlib.resources
import os
import tomllib
from dataclasses import dataclass, field

import numpy as np

from .errors import ProfileError
from .program import Kind, Program, X, Y

SECTORS = ("X", "Y", "Z", "E", "heater", "fans", "idle")


@dataclass(frozen=True, eq=False)
class PowerCoefficients:
    """Per-step power coefficients (see module docstring). All arrays have one row per step."""

    base_w: np.ndarray      # (n,) power no gating decision changes
    motor_w: np.ndarray     # (n, 4) power each motor draws while enabled
    xy_off_w: np.ndarray    # (n,) added when X and Y are both off (0 under the linear assumption)
    heater_w: np.ndarray    # (n,) share of base_w attributed to heaters (energy-sector diagram)
    fans_w: np.ndarray      # (n,) share of base_w attributed to fans; idle = base - heater - fans

    def take(self, rows: np.ndarray) -> "PowerCoefficients":
        """Coefficients for pieces of steps (a split step keeps its parent's coefficients)."""
        return PowerCoefficients(self.base_w[rows], self.motor_w[rows], self.xy_off_w[rows],
                                 self.heater_w[rows], self.fans_w[rows])


def step_power_w(coeffs: PowerCoefficients, enable: np.ndarray) -> np.ndarray:
    """P_i for each step given the (n, 4) motor-enable matrix."""
    enable = np.asarray(enable, dtype=bool)
    both_xy_off = ~enable[:, X] & ~enable[:, Y]
    return coeffs.base_w + (coeffs.motor_w * enable).sum(axis=1) + both_xy_off * coeffs.xy_off_w


def step_energy_j(duration_s: np.ndarray, coeffs: PowerCoefficients, enable: np.ndarray) -> np.ndarray:
    """E_i = P_i * T_i (3DGates Eq. 2), per step. The one energy function of the library."""
    return step_power_w(coeffs, enable) * np.asarray(duration_s, dtype=float)


# ------------------------------------------------------------------------------------------------
# Profiles
@dataclass(frozen=True)
class TimeAssumptions:
    """Durations the paper's T = L/F model cannot give (named assumptions, see profile TOML)."""

    hotend_heat_c_per_s: float = 2.0
    bed_heat_c_per_s: float = 0.5
    ambient_c: float = 25.0
    home_s: float = 5.0


@dataclass(frozen=True)
class Profile:
    """A named energy profile loaded from TOML."""

    name: str
    kind: str                       # "table" or "component"
    params: dict = field(repr=False)
    time: TimeAssumptions = TimeAssumptions()
    path: str = ""

    # -- coefficients --------------------------------------------------------------------------
    def coefficients(self, program: Program) -> PowerCoefficients:
        if self.kind == "table":
            return _table_coefficients(self.params, program)
        if self.kind == "component":
            return _component_coefficients(self.params, program)
        raise ProfileError(f"{self.path or self.name}: unknown profile kind {self.kind!r}")

    def motor_power_w(self) -> np.ndarray:
        """Representative per-motor power (travel class / holding), for reports."""
        if self.kind == "table":
            t = self.params["travel"]
            a = self.params["assumptions"]
            share = t["all_on_w"] - t["one_xy_gated_w"]
            return np.array([share, share, a["z_motor_w"], a["e_motor_w"]])
        return np.asarray(self.params["motor_w"], dtype=float)


def _require(d: dict, key: str, where: str):
    if key not in d:
        raise ProfileError(f"{where}: missing key {key!r}")
    return d[key]


def load_profile(name_or_path: "str | os.PathLike | Profile | None" = None) -> Profile:
    """Load a profile by name (shipped: ``paper``, ``component_example``) or from a TOML path."""
    if name_or_path is None:
        name_or_path = "paper"
    if isinstance(name_or_path, Profile):
        return name_or_path
    s = str(name_or_path)
    if not os.path.exists(s):
        return _load_shipped(s)
    return _load_profile_file(s)


@functools.lru_cache(maxsize=None)
def _load_shipped(name: str) -> Profile:
    return _load_profile_file(name)


def _load_profile_file(s: str) -> Profile:
    if os.path.exists(s):
        path = s
        with open(s, "rb") as f:
            raw = f.read()
    else:
        res = importlib.resources.files("gatesopt.profiles").joinpath(f"{s}.toml")
        if not res.is_file():
            shipped = sorted(p.name[:-5] for p in importlib.resources.files("gatesopt.profiles").iterdir()
                             if p.name.endswith(".toml"))
            raise ProfileError(f"unknown energy profile {s!r}: not a file, and not one of {shipped}")
        path = str(res)
        raw = res.read_bytes()
    try:
        params = tomllib.loads(raw.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ProfileError(f"{path}: not a valid TOML profile: {exc}") from None
    kind = _require(params, "kind", path)
    t = params.get("time", {})
    time = TimeAssumptions(**{k: float(v) for k, v in t.items() if k in TimeAssumptions.__dataclass_fields__})
    prof = Profile(name=params.get("name", os.path.basename(path)), kind=kind, params=params, time=time, path=path)
    if kind == "table":
        for sec in ("travel", "extrude", "assumptions"):
            _require(params, sec, path)
    elif kind == "component":
        for key in ("base_w", "motor_w", "hotend_w", "bed_w", "fan_w"):
            _require(params, key, path)
        if len(params["motor_w"]) != 4:
            raise ProfileError(f"{path}: motor_w needs 4 values (X Y Z E)")
    else:
        raise ProfileError(f"{path}: kind must be 'table' or 'component', not {kind!r}")
    return prof


def _classes(program: Program):
    kind = program.kind
    extruding = program.extruding
    moving = np.isin(kind, (Kind.TRAVEL, Kind.EXTRUDE, Kind.RETRACT, Kind.UNRETRACT, Kind.Z_ONLY, Kind.ARC))
    travel = moving & ~extruding
    return extruding, travel


def _table_coefficients(p: dict, program: Program) -> PowerCoefficients:
    """Paper tables -> coefficients. Reproduces Table 2/4 exactly for all-on and one-XY-gated."""
    n = program.n_steps
    a = p["assumptions"]
    ctl = p.get("control", {})
    z_w, e_w, idle_w, fan_share_w = a["z_motor_w"], a["e_motor_w"], a["idle_w"], a["fan_w"]
    if a.get("both_xy_gated", "linear") != "linear":
        # a measured number: P(both XY off) given explicitly for each class
        pass
    base = np.zeros(n)
    motor = np.zeros((n, 4))
    xy_off = np.zeros(n)
    heater = np.zeros(n)
    fans = np.zeros(n)
    extruding, travel = _classes(program)

    def fill(mask, cls):
        all_on, one_off = p[cls]["all_on_w"], p[cls]["one_xy_gated_w"]
        share = all_on - one_off                    # one XY motor's power (Table 4 vs Table 2)
        b = all_on - 2 * share - z_w - e_w          # what no motor decision changes
        base[mask] = b
        motor[mask] = (share, share, z_w, e_w)
        both = p[cls].get("both_xy_gated_w")
        if both is not None:                        # non-additive, measured
            xy_off[mask] = both - (all_on - 2 * share)
        # sector attribution of b: idle board, fan (when running), heater gets the rest
        f = np.where(program.fan[mask] > 0, min(fan_share_w, max(b - idle_w, 0.0)), 0.0)
        fans[mask] = f
        heater[mask] = np.maximum(b - idle_w - f, 0.0)

    fill(extruding, "extrude")
    fill(travel, "travel")
    stall_cls = a.get("stall_like", "extrude")
    fill(program.kind == Kind.MOTOR, stall_cls)
    kind = program.kind
    dwell = kind == Kind.DWELL
    base[dwell] = ctl.get("G4", idle_w)
    wait = kind == Kind.WAIT
    # M109 (hotend) vs M190 (bed): the parser marks bed waits with bed_c set by that line; we
    # cannot tell them apart from the row alone, so both use the heat-up powers below.
    wait_w = ctl.get("M109", 31.19)
    base[wait] = wait_w
    heater[wait] = wait_w - idle_w
    home = kind == Kind.HOME
    base[home] = ctl.get("G28", 20.84)
    return PowerCoefficients(base, motor, xy_off, heater, fans)


def _component_coefficients(p: dict, program: Program) -> PowerCoefficients:
    """Component model: base + enabled motors + heaters at duty + fan at its duty."""
    n = program.n_steps
    hot_on = program.hotend_c > 0
    bed_on = program.bed_c > 0
    heater = (hot_on * p["hotend_w"] * p.get("hotend_hold_duty", 0.3)
              + bed_on * p["bed_w"] * p.get("bed_hold_duty", 0.3)).astype(float)
    wait = program.kind == Kind.WAIT
    heater[wait] = p["hotend_w"] + bed_on[wait] * p["bed_w"]      # heating at full duty
    fans = (program.fan * p["fan_w"]).astype(float)
    stepping = program.steps_motor().sum(axis=1)
    base = p["base_w"] + heater + fans + stepping * p.get("moving_extra_w", 0.0)
    base = base + (program.kind == Kind.MOTOR) * p.get("stall_w", 0.0)
    motor = np.broadcast_to(np.asarray(p["motor_w"], float), (n, 4)).copy()
    return PowerCoefficients(base, motor, np.zeros(n), heater, fans)


# ------------------------------------------------------------------------------------------------
# Profiler
@dataclass(frozen=True, eq=False)
class EnergyReport:
    """What ``profile`` found. Times in s, energies in J."""

    source: str
    profile: str
    n_lines: int
    n_steps: int
    n_moves: int
    n_layers: int
    time_s: float
    energy_j: float
    sectors_j: dict          # SECTORS -> J (the paper's Fig. 5)
    by_kind_j: dict          # Kind name -> J
    by_kind_s: dict          # Kind name -> s
    layer_time_s: np.ndarray = field(repr=False)
    layer_energy_j: np.ndarray = field(repr=False)
    layer_z_mm: np.ndarray = field(repr=False)
    step_energy_j: np.ndarray = field(repr=False)     # per step, for plots (Fig. 4)
    step_end_s: np.ndarray = field(repr=False)        # cumulative time at the end of each step
    layer_method: str = ""
    warnings: tuple = ()

    @property
    def mean_power_w(self) -> float:
        return self.energy_j / self.time_s if self.time_s > 0 else 0.0

    def to_dict(self, per_layer: bool = False) -> dict:
        d = {
            "source": self.source, "profile": self.profile, "lines": self.n_lines,
            "steps": self.n_steps, "moves": self.n_moves, "layers": self.n_layers,
            "layer_method": self.layer_method, "time_s": self.time_s, "energy_j": self.energy_j,
            "energy_wh": self.energy_j / 3600.0, "mean_power_w": self.mean_power_w,
            "sectors_j": self.sectors_j, "by_kind_j": self.by_kind_j, "by_kind_s": self.by_kind_s,
            "warnings": list(self.warnings),
        }
        if per_layer:
            d["per_layer"] = [
                {"layer": i, "z_mm": float(z), "time_s": float(t), "energy_j": float(e)}
                for i, (z, t, e) in enumerate(zip(self.layer_z_mm, self.layer_time_s, self.layer_energy_j))
            ]
        return d


def default_enable(program: Program) -> np.ndarray:
    """The enable matrix the file itself implies (all motors on for plain slicer output)."""
    return program.enabled


def profile(program: Program, profile: Profile | str | None = None, *, enable: np.ndarray | None = None,
            duration_s: np.ndarray | None = None) -> EnergyReport:
    """Energy and time of ``program`` under ``profile`` (default: the paper's).

    ``enable`` (n x 4) defaults to the enable state the file's own instructions imply;
    ``duration_s`` defaults to the paper's time model (``program.duration_s``).
    """
    prof = load_profile(profile)
    coeffs = prof.coefficients(program)
    enable = default_enable(program) if enable is None else np.asarray(enable, bool)
    dur = program.duration_s if duration_s is None else np.asarray(duration_s, float)
    e = step_energy_j(dur, coeffs, enable)
    motors = coeffs.motor_w * enable * dur[:, None]
    both_off = (~enable[:, X] & ~enable[:, Y]) * coeffs.xy_off_w * dur
    sectors = {
        "X": float(motors[:, 0].sum()), "Y": float(motors[:, 1].sum()),
        "Z": float(motors[:, 2].sum()), "E": float(motors[:, 3].sum()),
        "heater": float((coeffs.heater_w * dur).sum()),
        "fans": float((coeffs.fans_w * dur).sum()),
    }
    sectors["idle"] = float(((coeffs.base_w - coeffs.heater_w - coeffs.fans_w) * dur).sum() + both_off.sum())
    by_kind_j, by_kind_s = {}, {}
    for k in Kind:
        m = program.kind == k
        if m.any():
            by_kind_j[k.name.lower()] = float(e[m].sum())
            by_kind_s[k.name.lower()] = float(dur[m].sum())
    nl = max(program.n_layers, 0)
    lay = program.layer
    valid = lay >= 0
    layer_t = np.bincount(lay[valid], weights=dur[valid], minlength=nl)[:nl] if nl else np.zeros(0)
    layer_e = np.bincount(lay[valid], weights=e[valid], minlength=nl)[:nl] if nl else np.zeros(0)
    n_moves = int(np.isin(program.kind, (Kind.TRAVEL, Kind.EXTRUDE, Kind.RETRACT, Kind.UNRETRACT,
                                         Kind.Z_ONLY, Kind.ARC)).sum())
    return EnergyReport(
        source=program.source, profile=prof.name, n_lines=program.n_lines, n_steps=program.n_steps,
        n_moves=n_moves, n_layers=program.n_layers, time_s=float(dur.sum()), energy_j=float(e.sum()),
        sectors_j=sectors, by_kind_j=by_kind_j, by_kind_s=by_kind_s, layer_time_s=layer_t,
        layer_energy_j=layer_e, layer_z_mm=program.layer_z_mm, step_energy_j=e,
        step_end_s=np.cumsum(dur), layer_method=program.layer_method, warnings=program.warnings,
    )
