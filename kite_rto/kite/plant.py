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
_isfinite = math.isfinite


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
        turbulence: :class:`~kite_rto.kite.wind.TurbulenceSettings`.
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
        """The same kite with no turbulence and no measurement noise (the turbulence settings are reset to
        their defaults, which have no effect when disabled, so equal kites compare equal)."""
        return replace(self, turbulence=TurbulenceSettings(enabled=False, anemometer_noise=0.0),
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


_new = object.__new__


def _measurement(t, theta, phi, psi, theta_dot, phi_dot, psi_dot, tension, position, wind_ref, delta, crashes,
                 step) -> Measurement:
    """Build a :class:`Measurement` without the frozen dataclass's per-field ``object.__setattr__`` (3-4x faster).

    The result is an ordinary ``Measurement`` (same fields, ``==``, ``hash``, ``repr``, ``replace``).
    """
    m = _new(Measurement)
    m.__dict__.update(t=t, theta=theta, phi=phi, psi=psi, theta_dot=theta_dot, phi_dot=phi_dot, psi_dot=psi_dot,
                      tension=tension, position=position, wind_ref=wind_ref, delta=delta, crashes=crashes,
                      step=step)
    return m


class _BlockTurbulence(Turbulence):
    """:class:`~kite_rto.kite.wind.Turbulence` with the per-sample cost of its random draws removed.

    Same random stream, same draws in the same order, same floating-point operations, hence bit-for-bit the same
    gusts and anemometer readings; the normals are only drawn from the generator in blocks (a NumPy ``Generator``
    yields the same sequence whether drawn one by one or as an array) instead of one NumPy call per draw.
    ``benchmarks/bench_plant.py`` checks the equivalence against the base class.
    """

    _BLOCK = 256

    def __init__(self, settings: TurbulenceSettings, w_ref: float, rng: np.random.Generator):
        super().__init__(settings, w_ref, rng)
        rho = settings.anemometer_correlation
        self._rho = rho
        self._rho_c = math.sqrt(1.0 - rho**2)
        self._noise_std = settings.anemometer_noise
        self._period = settings.update_period
        self._z: list = []
        self._zi = 0

    def _normal(self) -> float:
        zi = self._zi
        if zi >= len(self._z):
            self._z = self._rng.standard_normal(self._BLOCK).tolist()
            zi = 0
        self._zi = zi + 1
        return self._z[zi]

    def advance(self, t: float) -> None:
        if not self.settings.enabled:
            return
        a, b = self._a, self._b
        while t >= self._next_update - 1e-12:
            n1 = self._normal()
            n2 = self._normal()
            self.gust = a * self.gust + b * n1
            self._own = a * self._own + b * n2
            self._next_update += self._period

    def anemometer(self) -> float:
        gust = self._rho * self.gust + self._rho_c * self._own
        if self._noise_std > 0:
            zi = self._zi                       # inlined _normal()
            if zi >= len(self._z):
                self._z = self._rng.standard_normal(self._BLOCK).tolist()
                zi = 0
            self._zi = zi + 1
            noise = 0.0 + self._noise_std * self._z[zi]      # what Generator.normal(0.0, std) computes
        else:
            noise = 0.0
        w = self.w_ref0 + gust + noise
        return 0.0 if 0.0 > w else w            # max(w, 0.0), NaN included


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
        self.turbulence = _BlockTurbulence(self.config.turbulence, self.config.params.w_ref,
                                           np.random.default_rng(gust_ss))
        self._noise_rng = np.random.default_rng(noise_ss)
        self._p = self.config.params.as_vector()
        self._i_wref = KiteParams.names().index("w_ref")
        self._h = self.dt / self.config.substeps
        self._delay = deque([0.0] * round(self.config.dead_time / self.dt))
        self._max_change = self.config.rate_limit * self.dt
        self._substeps = range(self.config.substeps)
        nz = self.config.noise
        self._noise_std = (nz.angle, nz.rate, nz.tension)
        self._step_py = self.model.step_py
        self.state = list(self.config.launch_state)
        self.applied_delta = 0.0
        self.t = 0.0
        self.k = 0
        # Time of sample k is k * dt_ns * 1e-9 s: the same float a ROS node computes from the sample's stamp (integer
        # ns), so that the nodes and the pure runner see identical times.
        self._dt_ns = round(self.dt * 1e9)
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
        # Hot path (tens of thousands of calls per simulated hour): locals, no per-call NumPy, no helper calls.
        d = float(delta)
        if d != d:
            d = 0.0
        elif d < -1.0:
            d = -1.0
        elif d > 1.0:
            d = 1.0
        delay = self._delay
        if delay:
            delay.append(d)
            d = delay.popleft()
        mc = self._max_change
        change = d - self.applied_delta
        if change < -mc:
            change = -mc
        elif change > mc:
            change = mc
        self.applied_delta += change
        self.k += 1
        t = self.t = self.k * self._dt_ns * 1e-9
        turb = self.turbulence
        if t >= turb._next_update - 1e-12:
            turb.advance(t)
        w = turb.w_ref0 + turb.gust
        p = self._p
        p[self._i_wref] = 0.1 if 0.1 > w else w         # Turbulence.reference_wind(): max(w, 0.1)
        x = self.state
        ad, h, step_py = self.applied_delta, self._h, self._step_py
        for _ in self._substeps:
            x, out = step_py(x, ad, p, h)
        self.state, self._out = x, out
        if not (out[1] > 0.0 and all(map(_isfinite, x)) and all(map(_isfinite, out))):
            self._relaunch()
        m = self._last = self._measure()
        return m

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
        ni = self._ni                                   # inlined _draw()
        if ni >= len(self._noise):
            self._noise = self._noise_rng.standard_normal((1024, 7)).tolist()
            ni = 0
        self._ni = ni + 1
        e0, e1, e2, e3, e4, e5, e6 = self._noise[ni]
        x, out = self.state, self._out
        sa, sr, st = self._noise_std
        return _measurement(self.t, x[0] + sa * e0, x[1] + sa * e1, x[2] + sa * e2,
                            out[6] + sr * e3, out[7] + sr * e4, out[8] + sr * e5,
                            out[0] * (1.0 + st * e6), (out[3], out[4], out[5]),
                            self.turbulence.anemometer(), self.applied_delta, self.crashes, self.k)
