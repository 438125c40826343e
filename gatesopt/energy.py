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
from .program import Kind, Program

SECTORS = ("X", "Y", "Z", "E", "heater", "fans", "idle")


_BITS = np.array([1, 2, 4, 8], np.uint8)        # enable pattern of a step = sum of its motors' bits


def enable_pattern(enable: np.ndarray) -> np.ndarray:
    """(n,) uint8 in 0..15: bit m set when motor m (X Y Z E) is enabled."""
    enable = np.asarray(enable, dtype=bool)
    out = enable[:, 0].astype(np.uint8)
    for m in range(1, 4):
        out |= enable[:, m].astype(np.uint8) << m
    return out


@dataclass(frozen=True, eq=False)
class PowerCoefficients:
    """Per-step power coefficients (see module docstring).

    Steps share a handful of *power classes* (travel, extrusion with or without the fan, dwell,
    ...): ``cls[i]`` is step i's class and the ``*_by_cls`` tables hold one row per class, so a
    print of a million steps carries one small int per step instead of nine floats. The per-step
    views (``base_w``, ``motor_w``, ...) are computed on access.
    """

    cls: np.ndarray                 # (n,) int32: power class of each step
    base_w_by_cls: np.ndarray       # (k,) power no gating decision changes
    motor_w_by_cls: np.ndarray      # (k, 4) power each motor draws while enabled
    xy_off_w_by_cls: np.ndarray     # (k,) added when X and Y are both off (0 under the linear assumption)
    heater_w_by_cls: np.ndarray     # (k,) share of base attributed to heaters (energy-sector diagram)
    fans_w_by_cls: np.ndarray       # (k,) share of base attributed to fans; idle = base - heater - fans

    @property
    def power_by_pattern_w(self) -> np.ndarray:
        """(k, 16) power of each class under each enable pattern (see ``enable_pattern``)."""
        bits = ((np.arange(16)[:, None] >> np.arange(4)) & 1).astype(float)      # (16, 4)
        both_xy_off = (np.arange(16) & 3) == 0
        return (self.base_w_by_cls[:, None] + self.motor_w_by_cls @ bits.T
                + self.xy_off_w_by_cls[:, None] * both_xy_off[None, :])

    @property
    def base_w(self) -> np.ndarray:
        return self.base_w_by_cls[self.cls]

    @property
    def motor_w(self) -> np.ndarray:
        return self.motor_w_by_cls[self.cls]

    @property
    def xy_off_w(self) -> np.ndarray:
        return self.xy_off_w_by_cls[self.cls]

    @property
    def heater_w(self) -> np.ndarray:
        return self.heater_w_by_cls[self.cls]

    @property
    def fans_w(self) -> np.ndarray:
        return self.fans_w_by_cls[self.cls]

    def take(self, rows: np.ndarray) -> "PowerCoefficients":
        """Coefficients for pieces of steps (a split step keeps its parent's coefficients)."""
        return dataclasses.replace(self, cls=self.cls[rows])


def step_power_w(coeffs: PowerCoefficients, enable: np.ndarray) -> np.ndarray:
    """P_i for each step given the (n, 4) motor-enable matrix:
    ``base_w + sum_m enable_m * motor_w_m + [not X and not Y] * xy_off_w`` (docs/energy-model.md)."""
    return coeffs.power_by_pattern_w[coeffs.cls, enable_pattern(enable)]


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


# power classes of the table profile: (kind class) x (fan off, fan on) for the motion classes
_T_TRAVEL, _T_EXTRUDE, _T_STALL, _T_DWELL, _T_WAIT, _T_HOME = 0, 2, 4, 6, 7, 8
_TABLE_CLASS_OF_KIND = np.array([
    _T_TRAVEL,      # TRAVEL
    _T_EXTRUDE,     # EXTRUDE
    _T_TRAVEL,      # RETRACT: no material deposited -> the G0-type power
    _T_TRAVEL,      # UNRETRACT
    _T_TRAVEL,      # Z_ONLY
    _T_TRAVEL,      # ARC: extruding arcs are moved to _T_EXTRUDE below
    _T_DWELL,       # DWELL
    _T_WAIT,        # WAIT
    _T_HOME,        # HOME
    _T_STALL,       # MOTOR: a firmware stall at an enable/disable line
], np.int32)


def _table_coefficients(p: dict, program: Program) -> PowerCoefficients:
    """Paper tables -> coefficients. Reproduces Table 2/4 exactly for all-on and one-XY-gated."""
    a = p["assumptions"]
    ctl = p.get("control", {})
    z_w, e_w, idle_w, fan_share_w = a["z_motor_w"], a["e_motor_w"], a["idle_w"], a["fan_w"]
    k = 9
    base = np.zeros(k)
    motor = np.zeros((k, 4))
    xy_off = np.zeros(k)
    heater = np.zeros(k)
    fans = np.zeros(k)

    def fill(c, cls):
        all_on, one_off = p[cls]["all_on_w"], p[cls]["one_xy_gated_w"]
        share = all_on - one_off                    # one XY motor's power (Table 4 vs Table 2)
        b = all_on - 2 * share - z_w - e_w          # what no motor decision changes
        for fan_on in (0, 1):
            base[c + fan_on] = b
            motor[c + fan_on] = (share, share, z_w, e_w)
            both = p[cls].get("both_xy_gated_w")
            if both is not None:                    # non-additive, measured
                xy_off[c + fan_on] = both - (all_on - 2 * share)
            # attribution of b: idle board, the fan when it runs, the heater gets the rest
            f = min(fan_share_w, max(b - idle_w, 0.0)) if fan_on else 0.0
            fans[c + fan_on] = f
            heater[c + fan_on] = max(b - idle_w - f, 0.0)

    fill(_T_TRAVEL, "travel")
    fill(_T_EXTRUDE, "extrude")
    fill(_T_STALL, a.get("stall_like", "extrude"))
    base[_T_DWELL] = ctl.get("G4", idle_w)
    # M109 and M190 waits: the heat-up power of Table 2's M109 (the UM2 Go has no heated bed)
    base[_T_WAIT] = ctl.get("M109", 31.19)
    heater[_T_WAIT] = base[_T_WAIT] - idle_w
    base[_T_HOME] = ctl.get("G28", 20.84)
    cls = _TABLE_CLASS_OF_KIND[program.kind]
    cls[program.extruding] = _T_EXTRUDE
    cls += ((program.fan > 0) & (cls < _T_DWELL)).astype(np.int32)
    return PowerCoefficients(cls, base, motor, xy_off, heater, fans)


def _component_coefficients(p: dict, program: Program) -> PowerCoefficients:
    """Component model: base + enabled motors + heaters at duty + fan at its duty."""
    fan_values, fan_idx = np.unique(program.fan, return_inverse=True)
    wait = (program.kind == Kind.WAIT).astype(np.int64)
    hot = (program.hotend_c > 0).astype(np.int64)
    bed = (program.bed_c > 0).astype(np.int64)
    motor_row = (program.kind == Kind.MOTOR).astype(np.int64)
    nstep = program.steps_motor().sum(axis=1).astype(np.int64)
    key = ((((fan_idx.astype(np.int64) * 2 + wait) * 2 + hot) * 2 + bed) * 2 + motor_row) * 5 + nstep
    keys, cls = np.unique(key, return_inverse=True)
    nstep_k, rest = keys % 5, keys // 5
    motor_k, rest = rest % 2, rest // 2
    bed_k, rest = rest % 2, rest // 2
    hot_k, rest = rest % 2, rest // 2
    wait_k, fan_k = rest % 2, fan_values[rest // 2].astype(float)
    heater = np.where(wait_k == 1, p["hotend_w"] + bed_k * p["bed_w"],   # heating at full duty
                      hot_k * p["hotend_w"] * p.get("hotend_hold_duty", 0.3)
                      + bed_k * p["bed_w"] * p.get("bed_hold_duty", 0.3)).astype(float)
    fans = fan_k * p["fan_w"]
    base = (p["base_w"] + heater + fans + nstep_k * p.get("moving_extra_w", 0.0)
            + motor_k * p.get("stall_w", 0.0))
    k = len(keys)
    motor = np.broadcast_to(np.asarray(p["motor_w"], float), (k, 4)).copy()
    return PowerCoefficients(cls.astype(np.int32), base, motor, np.zeros(k), heater, fans)


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
    energy_time_s: float | None = None   # the durations the energy integrates over, where they
                                         # are not ``time_s``'s (``gatesopt profile``: the paper's)

    @property
    def mean_power_w(self) -> float:
        t = self.time_s if self.energy_time_s is None else self.energy_time_s
        return self.energy_j / t if t > 0 else 0.0

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
    pattern = enable_pattern(enable)
    e = coeffs.power_by_pattern_w[coeffs.cls, pattern] * dur          # step_energy_j, one gather
    # time spent in each (class, enable pattern): every sector is a small table product of it
    k = len(coeffs.base_w_by_cls)
    t_cp = np.bincount(coeffs.cls * 16 + pattern, weights=dur, minlength=16 * k).reshape(k, 16)
    bits = ((np.arange(16)[:, None] >> np.arange(4)) & 1).astype(float)    # (16, 4)
    motor_j = ((t_cp @ bits) * coeffs.motor_w_by_cls).sum(axis=0)         # (4,)
    t_c = t_cp.sum(axis=1)
    sectors = {"X": float(motor_j[0]), "Y": float(motor_j[1]), "Z": float(motor_j[2]), "E": float(motor_j[3]),
               "heater": float(t_c @ coeffs.heater_w_by_cls), "fans": float(t_c @ coeffs.fans_w_by_cls)}
    total = float(e.sum())
    sectors["idle"] = total - sum(sectors.values())
    nk = len(Kind)
    kj = np.bincount(program.kind, weights=e, minlength=nk)
    ks = np.bincount(program.kind, weights=dur, minlength=nk)
    present = np.bincount(program.kind, minlength=nk) > 0
    by_kind_j = {Kind(i).name.lower(): float(kj[i]) for i in range(nk) if present[i]}
    by_kind_s = {Kind(i).name.lower(): float(ks[i]) for i in range(nk) if present[i]}
    nl = program.n_layers
    lay = program.layer.astype(np.int64) + 1           # layer -1 (before the first) -> bin 0
    layer_t = np.bincount(lay, weights=dur, minlength=nl + 1)[1:nl + 1]
    layer_e = np.bincount(lay, weights=e, minlength=nl + 1)[1:nl + 1]
    n_moves = int(np.count_nonzero(program.kind <= Kind.ARC))
    return EnergyReport(
        source=program.source, profile=prof.name, n_lines=program.n_lines, n_steps=program.n_steps,
        n_moves=n_moves, n_layers=program.n_layers, time_s=float(dur.sum()), energy_j=total,
        sectors_j=sectors, by_kind_j=by_kind_j, by_kind_s=by_kind_s, layer_time_s=layer_t,
        layer_energy_j=layer_e, layer_z_mm=program.layer_z_mm, step_energy_j=e,
        step_end_s=np.cumsum(dur), layer_method=program.layer_method, warnings=program.warnings,
    )
