"""Input shapers: the standard shaper definitions and the step-generation window they give a stepper.

An input shaper replaces one commanded motion by a sum of copies of it, each scaled by an amplitude
A_i > 0 (sum 1) and delayed by T_i. The definitions here are the standard ones from the vibration
control literature, written for this module:

- ZV and ZVD: Singer & Seering, "Preshaping command inputs to reduce system vibration", ASME J.
  Dyn. Sys. Meas. Control 112 (1990): zero vibration at the frequency (and its derivative);
- MZV: the "modified ZV" of three pulses over 3/4 of the damped period (amplitudes
  1 - 1/sqrt 2, sqrt 2 - 1, 1 - 1/sqrt 2 before damping);
- EI, 2-hump EI, 3-hump EI: Singhose, Seering & Singer, "Residual vibration reduction using
  vector diagrams to generate shaping inputs", ASME J. Mech. Design 116 (1994), and Singhose,
  Porter, Tuttle & Singer, "Vibration reduction using multi-hump input shapers", ASME J. Dyn. Sys.
  Meas. Control 119 (1997): the extra-insensitive shapers at 5 % vibration tolerance, their pulse
  times and amplitudes as cubic fits in the damping ratio.

Klipper's input shaper (klippy/extras/input_shaper.py with the definitions of its shaper_defs.py)
uses these definitions and *time-centres* the pulses (chelper/kin_shaper.c ``init_shaper`` and
``shift_pulses``): the pulses are reversed in time and shifted so that their amplitude-weighted mean
time is 0, which keeps a constant-speed motion where it was. A stepper's steps for a move that
starts at t0 and ends at t1 are then generated over [t0 - pre, t1 + post] (``itersolve``'s
``gen_steps_pre_active`` / ``_post_active``, set by ``shaper_note_generation_time``), with

    c = sum(A_i T_i) / sum(A_i),   pre = c - T_0 = c,   post = T_last - c

(``window_s``). A stepper active on several shaped axes (corexy: X and Y) takes the larger of each.

Units: frequencies in Hz, times in seconds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import GatesoptError

#: the damping ratio a shaper assumes where none is given (Klipper's ``damping_ratio_x/y`` default)
DEFAULT_DAMPING_RATIO = 0.1
#: EI shapers: the residual vibration tolerated at the design frequency (5 %)
EI_VIBRATION_TOLERANCE = 0.05


class ShaperError(GatesoptError, ValueError):
    """An unknown shaper type or impossible parameters."""


@dataclass(frozen=True)
class Shaper:
    """Pulses of one shaper: amplitudes (any positive scale) and times (s, increasing from 0)."""

    name: str
    amplitudes: tuple[float, ...]
    times_s: tuple[float, ...]

    def window_s(self) -> tuple[float, float]:
        """(pre, post): how long before a move's start its steps may begin and after its end they
        may go on, once the pulses are time-centred (module docstring)."""
        if not self.amplitudes:
            return 0.0, 0.0
        total = sum(self.amplitudes)
        centre = sum(a * t for a, t in zip(self.amplitudes, self.times_s)) / total
        return centre - self.times_s[0], self.times_s[-1] - centre


def _damped_period(freq_hz: float, zeta: float) -> float:
    return 1.0 / (freq_hz * math.sqrt(1.0 - zeta * zeta))


def _zv(freq_hz, zeta):
    k = math.exp(-zeta * math.pi / math.sqrt(1.0 - zeta * zeta))
    td = _damped_period(freq_hz, zeta)
    return (1.0, k), (0.0, 0.5 * td)


def _zvd(freq_hz, zeta):
    k = math.exp(-zeta * math.pi / math.sqrt(1.0 - zeta * zeta))
    td = _damped_period(freq_hz, zeta)
    return (1.0, 2.0 * k, k * k), (0.0, 0.5 * td, td)


def _mzv(freq_hz, zeta):
    # three pulses over 3/4 of the damped period; the damping scales each later pulse by K
    k = math.exp(-0.75 * zeta * math.pi / math.sqrt(1.0 - zeta * zeta))
    td = _damped_period(freq_hz, zeta)
    outer = 1.0 - 1.0 / math.sqrt(2.0)
    return (outer, (math.sqrt(2.0) - 1.0) * k, outer * k * k), (0.0, 0.375 * td, 0.75 * td)


def _ei(freq_hz, zeta):
    v = EI_VIBRATION_TOLERANCE
    td = _damped_period(freq_hz, zeta)
    a1 = 0.24968 + 0.24961 * v + (0.80008 + 1.23328 * v + (0.49599 + 3.17316 * v) * zeta) * zeta
    a3 = 0.25149 + 0.21474 * v + (-0.83249 + 1.41498 * v + (0.85181 - 4.90094 * v) * zeta) * zeta
    t2 = 0.4999 + ((0.46159 + 8.57843 * v) * v
                   + ((4.26169 - 108.644 * v) * v + (1.75601 + 336.989 * v) * v * zeta) * zeta) * zeta
    return (a1, 1.0 - a1 - a3, a3), (0.0, t2 * td, td)


# Multi-hump EI shapers at 5 % tolerance (Singhose et al. 1997): per pulse, its time in units of
# the undamped period 1/f and its amplitude, each a cubic in the damping ratio (c0, c1, c2, c3)
_HUMP_EI = {
    "2hump_ei": (
        ((0.0, 0.0, 0.0, 0.0), (0.16054, 0.76699, 2.26560, -1.22750)),
        ((0.49890, 0.16270, -0.54262, 6.16180), (0.33911, 0.45081, -2.58080, 1.73650)),
        ((0.99748, 0.18382, -1.58270, 8.17120), (0.34089, -0.61533, -0.68765, 0.42261)),
        ((1.49920, -0.09297, -0.28338, 1.85710), (0.15997, -0.60246, 1.00280, -0.93145)),
    ),
    "3hump_ei": (
        ((0.0, 0.0, 0.0, 0.0), (0.11275, 0.76632, 3.29160, -1.44380)),
        ((0.49974, 0.23834, 0.44559, 12.4720), (0.23698, 0.61164, -2.57850, 4.85220)),
        ((0.99849, 0.29808, -2.36460, 23.3990), (0.30008, -0.19062, -2.14560, 0.13744)),
        ((1.49870, 0.10306, -2.01390, 17.0320), (0.23775, -0.73297, 0.46885, -2.08650)),
        ((1.99960, -0.28231, 0.61536, 5.40450), (0.11244, -0.45439, 0.96382, -1.46000)),
    ),
}


def _cubic(c, x):
    return c[0] + x * (c[1] + x * (c[2] + x * c[3]))


def _hump_ei(name):
    def make(freq_hz, zeta):
        rows = _HUMP_EI[name]
        return (tuple(_cubic(a, zeta) for _, a in rows),
                tuple(_cubic(t, zeta) / freq_hz for t, _ in rows))
    return make


#: shaper name -> (definition, largest damping ratio it is defined for)
SHAPERS = {
    "zv": (_zv, 0.99), "mzv": (_mzv, 0.99), "zvd": (_zvd, 0.99), "ei": (_ei, 0.4),
    "2hump_ei": (_hump_ei("2hump_ei"), 0.3), "3hump_ei": (_hump_ei("3hump_ei"), 0.2),
}


def shaper(name: str, freq_hz: float, damping_ratio: float = DEFAULT_DAMPING_RATIO) -> Shaper:
    """The shaper ``name`` (``zv``, ``mzv``, ``zvd``, ``ei``, ``2hump_ei``, ``3hump_ei``; any case)
    at ``freq_hz``; a frequency of 0 is no shaping (no pulses, an empty window)."""
    key = str(name).strip().lower()
    if key not in SHAPERS:
        raise ShaperError(f"unknown input shaper {name!r} (known: {', '.join(SHAPERS)}; "
                          "parameterised shapers such as 'mzv(n=4)' are not modelled)")
    make, max_zeta = SHAPERS[key]
    if not (math.isfinite(freq_hz) and freq_hz >= 0):
        raise ShaperError(f"input shaper {key}: frequency must be >= 0 Hz, not {freq_hz}")
    if not (0.0 <= damping_ratio <= max_zeta):
        raise ShaperError(f"input shaper {key}: damping ratio must be in [0, {max_zeta}], not {damping_ratio}")
    if freq_hz == 0:
        return Shaper(key, (), ())
    a, t = make(float(freq_hz), float(damping_ratio))
    return Shaper(key, tuple(float(x) for x in a), tuple(float(x) for x in t))
