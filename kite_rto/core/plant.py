"""The simulated 'real' kite: the Erhard model plus everything that makes a real kite differ from it.

Mismatch against the nominal model (SPEC §2): its own parameter values (E, g_s, shear, ...), glide loss when
steering (E = E0 - c_E delta^2), steering dead time and rate limit, turbulence, measurement noise. Fixed-step RK4
integration of the shared CasADi model (evaluated through its pure-Python translation). A crash (altitude
<= 0 or a non-finite state) is counted and followed by a relaunch from the launch state; no NaN ever leaves.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from .model import KiteModel
from .params import KiteParams, ParameterError, check_range
from .wind import Turbulence, TurbulenceSettings

__all__ = ["PlantConfig", "NoiseSettings", "Measurement", "KitePlant", "PLANT_PARAMS"]

PLANT_PARAMS = KiteParams(E=4.6, c_E=2.0, g_s=0.035, shear=0.20)
"""Default 'real kite': lower glide ratio, glide loss when steering, weaker steering, stronger shear (SPEC §2)."""

_MODEL = None


def shared_model() -> KiteModel:
    """One :class:`KiteModel` per process (building it compiles the CasADi graphs once)."""
    global _MODEL
    if _MODEL is None:
        _MODEL = KiteModel()
    return _MODEL


@dataclass(frozen=True)
class NoiseSettings:
    """White measurement noise, standard deviations.

    Attributes:
        angle: on theta, phi, psi, rad (>= 0).
        rate: on their time derivatives, rad/s (>= 0).
        tension: relative noise on the line tension (>= 0; 0.01 = 1 %).
    """

    angle: float = math.radians(0.1)
    rate: float = 0.005
    tension: float = 0.01

    def __post_init__(self):
        for f in ("angle", "rate", "tension"):
            check_range(type(self).__name__, f, getattr(self, f), 0.0)


@dataclass(frozen=True)
class PlantConfig:
    """Configuration of the simulated kite.

    Attributes:
        params: the real kite's parameters (:data:`PLANT_PARAMS` by default; the model uses ``KiteParams()``).
        dt: sample time, s: one call of :meth:`KitePlant.step` advances this much (> 0, <= 0.1).
        substeps: RK4 steps per sample (>= 1).
        dead_time: steering dead time, s (>= 0; rounded to whole samples).
        rate_limit: steering rate limit, 1/s of normalized delta (> 0).
        turbulence: :class:`~kite_rto.core.wind.TurbulenceSettings`.
        noise: :class:`NoiseSettings`.
        launch_state: (theta, phi, psi) in rad after start and after every crash.
    """

    params: KiteParams = PLANT_PARAMS
    dt: float = 0.02
    substeps: int = 1
    dead_time: float = 0.25
    rate_limit: float = 5.0
    turbulence: TurbulenceSettings = field(default_factory=TurbulenceSettings)
    noise: NoiseSettings = field(default_factory=NoiseSettings)
    launch_state: tuple = (math.radians(30.0), 0.0, 0.0)

    def __post_init__(self):
        n = type(self).__name__
        check_range(n, "dt", self.dt, 0.0, 0.1, low_open=True)
        if isinstance(self.substeps, bool) or not isinstance(self.substeps, int) or self.substeps < 1:
            raise ParameterError(f"{n}.substeps = {self.substeps!r}: expected an integer >= 1")
        check_range(n, "dead_time", self.dead_time, 0.0, 5.0)
        check_range(n, "rate_limit", self.rate_limit, 0.0, low_open=True)
        if len(self.launch_state) != 3:
            raise ParameterError(f"{n}.launch_state = {self.launch_state!r}: expected (theta, phi, psi)")
        theta, phi, psi = self.launch_state
        check_range(n, "launch_state[theta]", theta, 0.0, math.pi / 2, low_open=True, high_open=True)
        check_range(n, "launch_state[phi]", phi, -math.pi / 2, math.pi / 2, low_open=True, high_open=True)
        check_range(n, "launch_state[psi]", psi, -math.pi, math.pi)

    def without_disturbances(self) -> "PlantConfig":
        """The same kite with no turbulence and no measurement noise."""
        return replace(self, turbulence=replace(self.turbulence, enabled=False, anemometer_noise=0.0),
                       noise=NoiseSettings(0.0, 0.0, 0.0))


@dataclass(frozen=True)
class Measurement:
    """What the ground station measures at one sample (noise included).

    t s; theta, phi, psi rad; theta_dot, phi_dot, psi_dot rad/s; tension N; position (x, y, z) m in the anchor
    frame; wind_ref m/s (anemometer at z_ref); delta: steering currently applied at the kite (after dead time and
    rate limit), normalized; crashes: crash count since start; step: sample index.
    """

    t: float
    theta: float
    phi: float
    psi: float
    theta_dot: float
    phi_dot: float
    psi_dot: float
    tension: float
    position: tuple
    wind_ref: float
    delta: float
    crashes: int
    step: int

    @property
    def altitude(self) -> float:
        """z, m."""
        return self.position[2]


class KitePlant:
    """Fixed-step simulation of the real kite.

    Args:
        config: :class:`PlantConfig`.
        seed: seed of all random streams (turbulence and noise use separate streams).
    """

    def __init__(self, config: PlantConfig | None = None, seed: int = 0):
        self.config = config or PlantConfig()
        self.seed = int(seed)
        self.model = shared_model()
        self.dt = self.config.dt
        gust_ss, noise_ss = np.random.SeedSequence(self.seed).spawn(2)
        self.turbulence = Turbulence(self.config.turbulence, self.config.params.w_ref,
                                     np.random.default_rng(gust_ss))
        self._noise_rng = np.random.default_rng(noise_ss)
        self._p = self.config.params.as_vector()
        self._i_wref = KiteParams.names().index("w_ref")
        self._h = self.dt / self.config.substeps
        self._delay = deque([0.0] * round(self.config.dead_time / self.dt))
        self.state = list(self.config.launch_state)
        self.applied_delta = 0.0
        self.t = 0.0
        self.k = 0
        self.crashes = 0
        self._noise: list = []
        self._ni = 0
        self._out = self._evaluate()
        self._last = self._measure()

    # ---------------------------------------------------------------- public
    def measure(self) -> Measurement:
        """The latest measurement (the one returned by the last :meth:`step`)."""
        return self._last

    def step(self, delta: float) -> Measurement:
        """Send steering command ``delta`` (clipped to [-1, 1]; NaN counts as 0) and advance one sample."""
        d = float(delta)
        d = 0.0 if d != d else min(max(d, -1.0), 1.0)
        if self._delay:
            self._delay.append(d)
            d = self._delay.popleft()
        max_change = self.config.rate_limit * self.dt
        self.applied_delta += min(max(d - self.applied_delta, -max_change), max_change)
        self.k += 1
        self.t = self.k * self.dt
        self.turbulence.advance(self.t)
        self._p[self._i_wref] = self.turbulence.reference_wind()
        x = self.state
        for _ in range(self.config.substeps):
            x, out = self.model.step_py(x, self.applied_delta, self._p, self._h)
        self.state, self._out = x, out
        if not (out[1] > 0.0 and all(map(math.isfinite, x)) and all(map(math.isfinite, out))):
            self._relaunch()
        self._last = self._measure()
        return self._last

    def reset(self) -> Measurement:
        """Relaunch from the launch state (crash count and time are kept)."""
        self._relaunch(count=False)
        self._last = self._measure()
        return self._last

    # --------------------------------------------------------------- private
    def _relaunch(self, count: bool = True) -> None:
        if count:
            self.crashes += 1
        self.state = list(self.config.launch_state)
        self.applied_delta = 0.0
        self._delay = deque([0.0] * len(self._delay))
        self._out = self._evaluate()

    def _evaluate(self) -> list:
        return self.model.step_py(self.state, self.applied_delta, self._p, 0.0)[1]

    def _draw(self) -> list:
        if self._ni >= len(self._noise):
            self._noise = self._noise_rng.standard_normal((1024, 7)).tolist()
            self._ni = 0
        self._ni += 1
        return self._noise[self._ni - 1]

    def _measure(self) -> Measurement:
        nz = self.config.noise
        e = self._draw()
        x, out = self.state, self._out
        sa, sr = nz.angle, nz.rate
        return Measurement(
            t=self.t, theta=x[0] + sa * e[0], phi=x[1] + sa * e[1], psi=x[2] + sa * e[2],
            theta_dot=out[6] + sr * e[3], phi_dot=out[7] + sr * e[4], psi_dot=out[8] + sr * e[5],
            tension=out[0] * (1.0 + nz.tension * e[6]), position=(out[3], out[4], out[5]),
            wind_ref=self.turbulence.anemometer(), delta=self.applied_delta, crashes=self.crashes, step=self.k)
