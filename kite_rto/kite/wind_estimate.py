"""The wind at the kite, estimated from the kite's own measured motion (an observer on the model's kinematics).

In the Erhard model (SPEC §2) the kite's angular velocity is the apparent-wind flight along its heading plus a
downwind drift: with ``w_ap = w E cos(theta)``,

    r theta'            = w_ap cos(psi) - w sin(theta)
    r sin(theta) phi'   = -w_ap sin(psi)

Projected on the normal of the heading, ``n = (sin psi, cos psi)``, the ``w_ap`` term vanishes:

    y = -r (theta' sin(psi) + phi' sin(theta) cos(psi)) = w sin(theta) sin(psi) = h w

one linear measurement of the wind speed ``w`` at the kite per sample, **free of the glide ratio**: neither the
plant's E (4.6 against the model's 5) nor its glide loss when steering (``E - c_E delta^2``) enters, and neither
does the steering gain. ``h = sin(theta) sin(psi)`` is large in crosswind flight (psi near +-90 deg) and zero
when the kite flies straight up or down, where the drift is along the heading and not observable. The observer
is recursive least squares with exponential forgetting (time constant ``tau``):
``S_hy <- f S_hy + h y``, ``S_hh <- f S_hh + h^2``, ``w = S_hy / S_hh``, ``f = exp(-dt / tau)`` (a steady-state
Kalman filter of a random-walk wind).

Why not the line tension: ``T = 1/2 rho A w^2 (E + 1) sqrt(E^2 + 1) cos^2(theta)`` gives ``w`` only through the
glide ratio the kite actually flies with, which depends on the path (glide loss grows with steering). A wind
inferred from the tension with the model's E (:func:`tension_wind`, kept for comparison) absorbs exactly the
path-dependent part of the tension that the optimizer is trying to measure; normalizing by it flattens the
cost. ``bench_normalization.py`` measures both.

For the tension coefficient the wind at the kite is brought to ``z_ref`` with the model's shear exponent
(:meth:`WindObserver.reference_wind`). The plant's own exponent differs (0.20 against 0.15): the estimate at
z_ref is ``(z / z_ref)^0.05`` too high (~15 % at 180 m), so a tension normalized to the nominal wind is the
tension in the *model's* wind profile, ~25 % below the plant's (``bench_normalization.py``: bias -154 kN at
586 kN). The factor is nearly the same for every path (it varies as ``z^-0.1``, ~1.5 % in w between 150 and
200 m), so it rescales cost and gradient alike and moves a stationary point only through that residual.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .model import MIN_WIND_HEIGHT, STEP_OUTPUT_NAMES, KiteModel
from .params import KiteParams, check_range

__all__ = ["WindObserverSettings", "WindObserver", "drift_measurement", "tension_wind"]

_TENSION = STEP_OUTPUT_NAMES.index("tension")


def drift_measurement(theta: float, psi: float, theta_dot: float, phi_dot: float, r: float) -> tuple:
    """``(y, h)`` with ``y = h w`` (see the module docstring): y in m/s, h dimensionless; angles rad, rates rad/s,
    tether length r m."""
    st, sp = math.sin(theta), math.sin(psi)
    return -r * (theta_dot * sp + phi_dot * st * math.cos(psi)), st * sp


def tension_wind(model: KiteModel, params: KiteParams, theta: float, phi: float, tension: float) -> float:
    """The wind at the kite (m/s) that makes the model's tension at ``(theta, phi, psi = 0, delta = 0)`` equal the
    measured ``tension`` (N): ``T`` scales with ``w^2``, so ``w = sqrt(T / T(w = 1))``. Uses the model's E."""
    z = params.r * math.sin(theta) * math.cos(phi)
    p = params.as_vector()
    p[KiteParams.names().index("w_ref")] = (params.z_ref / max(z, MIN_WIND_HEIGHT)) ** params.shear   # w = 1 at z
    unit = model.step_py([theta, phi, 0.0], 0.0, p, 0.0)[1][_TENSION]
    return math.sqrt(max(tension, 0.0) / unit)


@dataclass(frozen=True)
class WindObserverSettings:
    """Settings of :class:`WindObserver`.

    Attributes:
        time_constant: forgetting time constant tau, s (> 0): shorter follows gusts faster, longer averages
            more measurement noise.
        min_information: the estimate is held until the weighted sum of ``h^2`` exceeds this (> 0).
    """

    time_constant: float = 2.0
    min_information: float = 5.0

    def __post_init__(self):
        n = type(self).__name__
        check_range(n, "time_constant", self.time_constant, 0.0, low_open=True)
        check_range(n, "min_information", self.min_information, 0.0, low_open=True)


class WindObserver:
    """Recursive estimate of the wind at the kite from measured theta, psi, theta', phi' (module docstring).

    Args:
        params: the model's :class:`KiteParams` (tether length r, z_ref and shear for :meth:`reference_wind`).
        dt: sample time, s; None: the time between consecutive measurements (their ``t``, s).
        settings: :class:`WindObserverSettings`.
        initial: wind reported before enough information has come in, m/s (at the kite).

    Call :meth:`update` once per sample with a measurement (attributes ``theta, psi, theta_dot, phi_dot``, and
    ``t`` when ``dt`` is None).
    """

    def __init__(self, params: KiteParams, dt: float | None, settings: WindObserverSettings | None = None,
                 initial: float = math.nan):
        self.params = params
        self.settings = settings or WindObserverSettings()
        self._forget = None if dt is None else math.exp(-dt / self.settings.time_constant)
        self._t = None
        self._shy = 0.0
        self._shh = 0.0
        self.wind = float(initial)
        """Current estimate of the wind speed at the kite, m/s."""

    def update(self, m) -> float:
        """Add one measurement; returns the estimate of the wind at the kite, m/s."""
        y, h = drift_measurement(m.theta, m.psi, m.theta_dot, m.phi_dot, self.params.r)
        return self.fit(y, h, m.t if self._forget is None else None)

    def fit(self, y: float, g: float, t: float | None = None) -> float:
        """One step of the recursive least squares of ``y = w g`` with exponential forgetting (``time_constant``;
        over ``dt``, or over the time since the previous call's ``t`` s when ``dt`` is None); ``w`` is updated
        once the weighted sum of ``g^2`` reaches ``min_information``. Returns ``w`` (units of ``y / g``).
        :meth:`update` calls it with the drift measurement ``y = h w``; other regressors (a wind profile) reuse it."""
        f = self._forget
        if f is None:                   # forgetting over the time since the previous measurement
            prev, self._t = self._t, t
            f = 1.0 if prev is None else math.exp(-(t - prev) / self.settings.time_constant)
        self._shy = f * self._shy + g * y
        self._shh = f * self._shh + g * g
        if self._shh >= self.settings.min_information:
            self.wind = self._shy / self._shh
        return self.wind

    def observe(self, m) -> float:
        """:meth:`update` with measurement ``m`` (also ``position``), then the estimate at z_ref, m/s: what a
        tension normalization uses in place of the anemometer's ``wind_ref``."""
        self.update(m)
        return self.reference_wind(m.position[2])

    def reference_wind(self, altitude: float) -> float:
        """The estimate brought to ``z_ref`` through the model's power law, m/s (kite at ``altitude`` m)."""
        p = self.params
        return self.wind / (max(altitude, MIN_WIND_HEIGHT) / p.z_ref) ** p.shear

    def reset(self) -> None:
        """Forget all information (e.g. after a crash)."""
        self._shy = self._shh = 0.0
        self._t = None
