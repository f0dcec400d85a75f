"""Wind: power-law shear (seed eq. 2.4.6) with turbulence on the reference wind, and a ground anemometer.

Turbulence (SPEC §2, Costello 2017 benchmark wind): the reference wind is ``w_ref(t) = w_ref0 + g(t)`` where the
gust ``g`` is first-order filtered white noise (an Ornstein-Uhlenbeck process) with time constant
``tau = L_W / w_ref0`` and standard deviation ``sigma = k_sigma w_ref0``, updated every ``update_period`` seconds
with the exact discretization ``g+ = a g + sigma sqrt(1 - a^2) n``, ``a = exp(-update_period / tau)``.

The anemometer at ``z_ref`` sees a gust correlated with the kite's (coefficient ``anemometer_correlation``) plus
its own white measurement noise. The default correlation 1 is SPEC §2's model (one gust process on ``w_ref``, which
the anemometer at ``z_ref`` measures); a correlation below 1 models an anemometer that sees a partly different
gust (a stress case: at 0.95 the normalized 4-lap mean tension scatters ~18x more, ``bench_normalization.py``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .params import check_range

__all__ = ["TurbulenceSettings", "Turbulence"]


@dataclass(frozen=True)
class TurbulenceSettings:
    """Turbulence and anemometer settings.

    Attributes:
        enabled: turbulence on (True) or a steady wind (False).
        length_scale: L_W, m (> 0); tau = L_W / w_ref.
        intensity: k_sigma, gust standard deviation over mean reference wind (>= 0).
        update_period: s between gust updates (> 0).
        anemometer_correlation: correlation of the anemometer's gust with the kite's, in [0, 1].
        anemometer_noise: white noise standard deviation of the anemometer, m/s (>= 0).
    """

    enabled: bool = True
    length_scale: float = 100.0
    intensity: float = 0.14
    update_period: float = 0.15
    anemometer_correlation: float = 1.0
    anemometer_noise: float = 0.1

    def __post_init__(self):
        n = type(self).__name__
        if not isinstance(self.enabled, bool):
            raise ValueError(f"{n}.enabled = {self.enabled!r}: expected True or False")
        check_range(n, "length_scale", self.length_scale, 0.0, low_open=True)
        check_range(n, "intensity", self.intensity, 0.0, 1.0)
        check_range(n, "update_period", self.update_period, 0.0, low_open=True)
        check_range(n, "anemometer_correlation", self.anemometer_correlation, 0.0, 1.0)
        check_range(n, "anemometer_noise", self.anemometer_noise, 0.0)


class Turbulence:
    """Gust process on the reference wind, seeded and reproducible.

    Args:
        settings: :class:`TurbulenceSettings`.
        w_ref: mean reference wind, m/s.
        rng: NumPy random generator owned by this object (pass a dedicated stream for reproducibility).
    """

    def __init__(self, settings: TurbulenceSettings, w_ref: float, rng: np.random.Generator):
        self.settings = settings
        self.w_ref0 = float(w_ref)
        self._rng = rng
        tau = settings.length_scale / self.w_ref0
        self._a = math.exp(-settings.update_period / tau)
        self._b = settings.intensity * self.w_ref0 * math.sqrt(1.0 - self._a**2)
        sigma = settings.intensity * self.w_ref0
        on = settings.enabled
        self.gust = float(rng.normal(0.0, sigma)) if on else 0.0          # kite's gust, m/s
        self._own = float(rng.normal(0.0, sigma)) if on else 0.0          # anemometer's uncorrelated part
        self._next_update = settings.update_period

    def advance(self, t: float) -> None:
        """Bring the gust process up to time ``t`` (s)."""
        if not self.settings.enabled:
            return
        while t >= self._next_update - 1e-12:
            n1, n2 = self._rng.standard_normal(2).tolist()
            self.gust = self._a * self.gust + self._b * n1
            self._own = self._a * self._own + self._b * n2
            self._next_update += self.settings.update_period

    def reference_wind(self) -> float:
        """Wind at z_ref seen by the kite's wind profile, m/s (never below 0.1 m/s)."""
        return max(self.w_ref0 + self.gust, 0.1)

    def anemometer(self) -> float:
        """Anemometer reading at z_ref, m/s: correlated gust plus measurement noise."""
        s = self.settings
        rho = s.anemometer_correlation
        gust = rho * self.gust + math.sqrt(1.0 - rho**2) * self._own
        noise = float(self._rng.normal(0.0, s.anemometer_noise)) if s.anemometer_noise > 0 else 0.0
        return max(self.w_ref0 + gust + noise, 0.0)
