"""The mean wind that drifts and turns: hub-height mean speed and direction as slow stochastic processes.

Between the turbulence (seconds to minutes, the Mann box of :mod:`~kite_rto.kite.wind_field`) and the weather
(hours to days) lies the spectral gap of van der Hoven's spectrum (van der Hoven 1957, "Power spectrum of
horizontal wind speed in the frequency range from 0.0007 to 900 cycles per hour", J. Meteorol. 14: peaks at a
period of ~4 days and ~1 min, a broad gap centred at 1-10 cycles per hour). The turbulence box holds the part
above the gap; this module adds the part below it, which over a flight of hours moves the mean wind:

* speed: the mean reference wind is ``w_ref0 (1 + speed_std X(t))``, ``X`` an Ornstein-Uhlenbeck process of unit
  variance and correlation time ``time_scale`` (a time scale below the gap's low-frequency edge: hours);
* direction: ``direction_std Y(t)`` (rad, from the ground frame's x towards y), ``Y`` an independent process of
  the same kind;
* an optional extreme direction change (EDC, IEC 61400-1 ed. 3, 6.3.2.4): ``theta_e = 4 arctan(sigma_1 / (V_hub
  (1 + 0.1 D / Lambda_1)))`` reached as ``0.5 theta_e (1 - cos(pi t / T))`` over ``T = 6 s``, starting at
  ``edc_time`` s, with ``D`` the kite's sweep (a rotor's diameter in the standard) and ``Lambda_1 = 42 m``.

Both processes start at 0 (the flight starts in the nominal wind) and are updated every ``update_period`` s with
the exact discretization ``X+ = a X + sqrt(1 - a^2) n``, ``a = exp(-update_period / time_scale)``, from their own
random stream: deterministic per seed. The amplitudes (``speed_std`` 0.10, ``direction_std`` 15 deg) are settings
of the scenario, not measured site statistics; the docs state them as such.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .params import ParameterError, check_range

__all__ = ["MeanWindSettings", "MeanWind", "edc_amplitude", "EDC_DURATION", "IEC_LAMBDA_1"]

EDC_DURATION = 6.0
"""IEC 61400-1 ed. 3 extreme direction change: duration T, s."""
IEC_LAMBDA_1 = 42.0
"""IEC 61400-1 ed. 3 turbulence scale parameter above 60 m, m."""
MIN_SPEED_FACTOR = 0.3
"""The mean speed never falls below this fraction of the nominal one (a calm is not a kite scenario)."""


def edc_amplitude(sigma_1: float, hub_wind: float, diameter: float) -> float:
    """IEC 61400-1 ed. 3 extreme direction change ``theta_e = 4 arctan(sigma_1 / (V_hub (1 + 0.1 D / Lambda_1)))``
    (rad) for ``sigma_1`` and ``hub_wind`` m/s and ``diameter`` D m."""
    return 4.0 * math.atan(sigma_1 / (hub_wind * (1.0 + 0.1 * diameter / IEC_LAMBDA_1)))


@dataclass(frozen=True)
class MeanWindSettings:
    """How the mean wind drifts (module docstring).

    Attributes:
        drift: the mean speed and direction drift (False: a stationary mean wind, the EDC still applies).
        speed_std: standard deviation of the mean speed, fraction of the nominal one (>= 0).
        direction_std: standard deviation of the mean direction, rad (>= 0).
        time_scale: correlation time of both processes, s (> 0).
        update_period: s between updates (> 0).
        edc_time: start of an extreme direction change, s (None: none).
        edc_sign: +1 (towards +y) or -1.
        edc_diameter: the kite's sweep D of the EDC formula, m (> 0).
    """

    drift: bool = False
    speed_std: float = 0.10
    direction_std: float = math.radians(15.0)
    time_scale: float = 7200.0
    update_period: float = 1.0
    edc_time: float | None = None
    edc_sign: int = 1
    edc_diameter: float = 100.0

    def __post_init__(self):
        n = type(self).__name__
        if not isinstance(self.drift, bool):
            raise ParameterError(f"{n}.drift = {self.drift!r}: expected True or False")
        check_range(n, "speed_std", self.speed_std, 0.0, 0.5)
        check_range(n, "direction_std", self.direction_std, 0.0, math.pi / 4)
        check_range(n, "time_scale", self.time_scale, 0.0, low_open=True)
        check_range(n, "update_period", self.update_period, 0.0, low_open=True)
        if self.edc_time is not None:
            check_range(n, "edc_time", self.edc_time, 0.0)
        if self.edc_sign not in (1, -1):
            raise ParameterError(f"{n}.edc_sign = {self.edc_sign!r}: expected +1 or -1")
        check_range(n, "edc_diameter", self.edc_diameter, 0.0, low_open=True)

    @property
    def changes(self) -> bool:
        """The mean wind is not constant (drift or an EDC)."""
        return self.drift or self.edc_time is not None


class MeanWind:
    """The mean wind's speed factor and direction over time (module docstring); deterministic per ``rng``.

    Args:
        settings: :class:`MeanWindSettings`.
        rng: the processes' own random stream.
        edc: the EDC's amplitude theta_e, rad (from :func:`edc_amplitude` for the plant's turbulence).

    Call :meth:`advance` with non-decreasing times, then read :attr:`speed_factor` and :attr:`direction`.
    """

    def __init__(self, settings: MeanWindSettings, rng: np.random.Generator, edc: float = 0.0):
        self.settings = settings
        self._x = self._y = 0.0
        self._next = settings.update_period if settings.drift else math.inf
        self._a = math.exp(-settings.update_period / settings.time_scale)
        self._b = math.sqrt(1.0 - self._a**2)
        self._rng = rng
        self._edc = settings.edc_sign * float(edc)
        self.t = 0.0
        self.speed_factor = 1.0
        self.direction = 0.0

    def advance(self, t: float) -> None:
        """Bring both processes (and the EDC) to time ``t`` (s)."""
        s = self.settings
        while t >= self._next - 1e-12:
            n1, n2 = self._rng.standard_normal(2)
            self._x = self._a * self._x + self._b * n1
            self._y = self._a * self._y + self._b * n2
            self._next += s.update_period
        self.t = t
        self.speed_factor = max(MIN_SPEED_FACTOR, 1.0 + s.speed_std * self._x)
        self.direction = s.direction_std * self._y + self._edc_at(t)

    def _edc_at(self, t: float) -> float:
        t0 = self.settings.edc_time
        if t0 is None or t <= t0:
            return 0.0
        if t >= t0 + EDC_DURATION:
            return self._edc
        return 0.5 * self._edc * (1.0 - math.cos(math.pi * (t - t0) / EDC_DURATION))
