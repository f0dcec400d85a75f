"""Wind: the interface the plant asks each sample (:class:`WindModel`) and the uniform gust (:class:`UniformGust`).

The plant's wind profile is the power law of seed eq. 2.4.6, ``w(z) = w_ref (z / z_ref)^a``. A wind model tells the
plant, once per sample, which reference wind ``w_ref`` (m/s at ``z_ref``) puts the kite in the wind it meets at its
own position, and what the ground-station anemometer at ``(0, 0, z_ref)`` reads.

Uniform gust (SPEC §2, Costello 2017 benchmark wind): the reference wind is ``w_ref(t) = w_ref0 + g(t)`` where the
gust ``g`` is first-order filtered white noise (an Ornstein-Uhlenbeck process) with time constant
``tau = L_W / w_ref0`` and standard deviation ``sigma = k_sigma w_ref0``, updated every ``update_period`` seconds
with the exact discretization ``g+ = a g + sigma sqrt(1 - a^2) n``, ``a = exp(-update_period / tau)``. One gust
for the whole field, wherever the kite is.

The anemometer at ``z_ref`` sees a gust correlated with the kite's (coefficient ``anemometer_correlation``) plus
its own white measurement noise. The default correlation 1 is SPEC §2's model (one gust process on ``w_ref``, which
the anemometer at ``z_ref`` measures); a correlation below 1 models an anemometer that sees a partly different
gust (a stress case: at 0.95 the normalized 4-lap mean tension scatters ~18x more, ``bench_normalization.py``).
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from .params import check_range

__all__ = ["TurbulenceSettings", "WindModel", "UniformGust", "NormalBlocks", "MIN_REFERENCE_WIND"]

MIN_REFERENCE_WIND = 0.1
"""Lowest reference wind handed to the kite model, m/s (a gust never stops the wind completely)."""


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


class WindModel(ABC):
    """What the plant asks the wind once per sample, in this order: :meth:`advance` to the sample's time, then
    :meth:`kite_reference_wind` at the kite's position (or, for a wind that :attr:`turns`, :meth:`kite_wind`), then
    :meth:`anemometer` and :meth:`vane` for the measurements."""

    turns = False
    """The wind at the kite changes direction (the plant then asks :meth:`kite_wind`)."""

    def kite_wind(self, position: tuple) -> tuple:
        """``(speed m/s, direction rad, tilt rad)`` of the wind at ``position`` (m, ground frame); models that
        :attr:`turn <turns>` implement it."""
        raise NotImplementedError(f"{type(self).__name__} keeps its direction: ask kite_reference_wind")

    def vane(self) -> float:
        """Wind vane reading at ``(0, 0, z_ref)``, rad from the ground frame's x towards y (0 for a wind that never
        turns)."""
        return 0.0

    @abstractmethod
    def advance(self, t: float) -> None:
        """Bring the wind up to time ``t`` (s); called with non-decreasing times."""

    @abstractmethod
    def kite_reference_wind(self, position: tuple) -> float:
        """Reference wind (m/s at ``z_ref``, >= :data:`MIN_REFERENCE_WIND`) whose power-law profile gives the
        wind at ``position = (x, y, z)``, m in the anchor frame (x downwind, z up), at the current time."""

    @abstractmethod
    def anemometer(self) -> float:
        """Anemometer reading at ``(0, 0, z_ref)`` at the current time, m/s (>= 0), measurement noise included."""


class NormalBlocks:
    """Standard normal draws from ``rng``, taken from the generator in blocks of ``size``.

    A NumPy ``Generator`` yields the same sequence whether drawn one by one or as an array, so the values (and
    their order) are those of successive ``rng.standard_normal()`` calls, without one NumPy call per draw.
    """

    def __init__(self, rng: np.random.Generator, size: int = 256):
        self._rng = rng
        self._size = size
        self._block: list = []
        self._index = 0

    def next(self) -> float:
        """The next standard normal draw."""
        i = self._index
        if i >= len(self._block):
            self._block = self._rng.standard_normal(self._size).tolist()
            i = 0
        self._index = i + 1
        return self._block[i]


class UniformGust(WindModel):
    """One gust process on the reference wind, the same everywhere; seeded and reproducible.

    Args:
        settings: :class:`TurbulenceSettings`.
        w_ref: mean reference wind, m/s.
        rng: NumPy random generator owned by this object (pass a dedicated stream for reproducibility).

    The initial gusts are drawn with ``rng.normal``, every later normal from :class:`NormalBlocks` of the same
    generator: two per update (kite's gust, anemometer's own part), one per anemometer reading when it is noisy.
    """

    def __init__(self, settings: TurbulenceSettings, w_ref: float, rng: np.random.Generator):
        self.settings = settings
        self.w_ref0 = float(w_ref)
        tau = settings.length_scale / self.w_ref0
        self._a = math.exp(-settings.update_period / tau)
        self._b = settings.intensity * self.w_ref0 * math.sqrt(1.0 - self._a**2)
        sigma = settings.intensity * self.w_ref0
        on = settings.enabled
        self.gust = float(rng.normal(0.0, sigma)) if on else 0.0          # kite's gust, m/s
        self._own = float(rng.normal(0.0, sigma)) if on else 0.0          # anemometer's uncorrelated part
        self._next_update = settings.update_period if on else math.inf
        self._period = settings.update_period
        rho = settings.anemometer_correlation
        self._rho = rho
        self._rho_c = math.sqrt(1.0 - rho**2)
        self._noise_std = settings.anemometer_noise
        self._normals = NormalBlocks(rng)

    def advance(self, t: float) -> None:
        """Bring the gust process up to time ``t`` (s)."""
        if t < self._next_update - 1e-12:
            return
        a, b, normal = self._a, self._b, self._normals.next
        while t >= self._next_update - 1e-12:
            n1 = normal()
            n2 = normal()
            self.gust = a * self.gust + b * n1
            self._own = a * self._own + b * n2
            self._next_update += self._period

    def kite_reference_wind(self, position: tuple) -> float:
        """``w_ref0 + gust`` wherever the kite is, m/s (never below :data:`MIN_REFERENCE_WIND`)."""
        w = self.w_ref0 + self.gust
        return MIN_REFERENCE_WIND if MIN_REFERENCE_WIND > w else w      # max(w, 0.1), NaN included

    def anemometer(self) -> float:
        """Anemometer reading at z_ref, m/s: correlated gust plus measurement noise."""
        gust = self._rho * self.gust + self._rho_c * self._own
        if self._noise_std > 0:
            z = self._normals                   # inlined z.next(): this runs every sample
            i = z._index
            if i >= len(z._block):
                z._block = z._rng.standard_normal(z._size).tolist()
                i = 0
            z._index = i + 1
            noise = 0.0 + self._noise_std * z._block[i]      # what Generator.normal(0.0, std) computes
        else:
            noise = 0.0
        w = self.w_ref0 + gust + noise
        return 0.0 if 0.0 > w else w            # max(w, 0.0), NaN included
