"""The simulated 'real' kite: the Erhard model plus everything that makes a real kite differ from it.

Mismatch against the nominal model (SPEC §2): its own parameter values (E, g_s, shear, ...), glide loss when
steering (E = E0 - c_E delta^2), steering dead time and rate limit (``actuator.py``), turbulence (a uniform gust,
``wind.py``, or a 3-D field the kite and the anemometer sample at their own positions, ``wind_field.py``),
measurement noise. Fixed-step RK4 integration of the shared CasADi model (evaluated through its pure-Python
translation). A crash (altitude <= 0, theta <= 0 or a non-finite state) is counted and followed by a relaunch from
the launch state; no NaN ever leaves. theta <= 0 is the kite on the ground downwind of the anchor (z = r sin theta
cos phi = 0 there for every phi): a dive through that point can leave theta slightly negative and phi beyond pi with
a positive altitude, a state every node rejects.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from operator import itemgetter

import numpy as np

from .actuator import Actuator
from .mean_wind import MeanWind, MeanWindSettings, edc_amplitude
from .model import MIN_WIND_HEIGHT, STEP_OUTPUT_NAMES, shared_model
from .params import KiteParams, ParameterError, check_range
from .wind import MIN_REFERENCE_WIND, TurbulenceSettings, UniformGust, WindModel
from .wind_field import FieldWind, MannBox, WindFieldSettings
from .wind_frame import rotate_motion, rotate_state, rotate_vector, transpose, wind_rotation

__all__ = ["PlantConfig", "NoiseSettings", "Measurement", "KitePlant", "PLANT_PARAMS", "WIND_MODELS",
           "DEFAULT_WIND_MODEL"]

PLANT_PARAMS = KiteParams(E=4.6, c_E=2.0, g_s=0.035, shear=0.20)
"""Default 'real kite': lower glide ratio, glide loss when steering, weaker steering, stronger shear (SPEC §2)."""

WIND_MODELS = ("uniform", "field")
"""``PlantConfig.wind_model`` choices: one gust on the whole wind (:class:`~kite_rto.kite.wind.UniformGust`) or the
3-D turbulent field (:class:`~kite_rto.kite.wind_field.FieldWind`)."""
DEFAULT_WIND_MODEL = "field"
"""The plant's wind model unless configured otherwise."""

_isfinite = math.isfinite
_MEASURED_OUTPUTS = ("tension", "x", "y", "z", "theta_dot", "phi_dot", "psi_dot")
_measured = itemgetter(*(STEP_OUTPUT_NAMES.index(n) for n in _MEASURED_OUTPUTS))
"""``step_py`` outputs -> the tuple :data:`_MEASURED_OUTPUTS` (one C call, by name)."""
_ALTITUDE = STEP_OUTPUT_NAMES.index("altitude")
_POSITION = STEP_OUTPUT_NAMES.index("x")              # x, y, z follow
_RATES = STEP_OUTPUT_NAMES.index("theta_dot")         # theta_dot, phi_dot, psi_dot follow


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
        turbulence: :class:`~kite_rto.kite.wind.TurbulenceSettings` (with ``wind_model = "field"`` only its
            ``enabled`` and ``anemometer_noise`` apply).
        noise: :class:`NoiseSettings`.
        launch_state: (theta, phi, psi) in rad after start and after every crash.
        wind_model: one of :data:`WIND_MODELS`; turbulence disabled means a steady wind with either.
        wind_field: :class:`~kite_rto.kite.wind_field.WindFieldSettings` of the ``"field"`` model.
        mean_wind: :class:`~kite_rto.kite.mean_wind.MeanWindSettings`: how the mean wind drifts and turns (a
            changing mean wind needs the ``"field"`` model with turbulence on).
    """

    params: KiteParams = PLANT_PARAMS
    dt: float = 0.02
    substeps: int = 1
    dead_time: float = 0.25
    rate_limit: float = 5.0
    turbulence: TurbulenceSettings = field(default_factory=TurbulenceSettings)
    noise: NoiseSettings = field(default_factory=NoiseSettings)
    launch_state: tuple = (math.radians(30.0), 0.0, 0.0)
    wind_model: str = DEFAULT_WIND_MODEL
    wind_field: WindFieldSettings = field(default_factory=WindFieldSettings)
    mean_wind: MeanWindSettings = field(default_factory=MeanWindSettings)

    def __post_init__(self):
        n = type(self).__name__
        if self.wind_model not in WIND_MODELS:
            raise ParameterError(f"{n}.wind_model = {self.wind_model!r}: expected one of {', '.join(WIND_MODELS)}")
        if self.mean_wind.changes and not (self.wind_model == "field" and self.turbulence.enabled):
            raise ParameterError(f"{n}.mean_wind = {self.mean_wind!r}: a changing mean wind needs wind_model "
                                 f"'field' with turbulence enabled (got {self.wind_model!r}, turbulence "
                                 f"{'on' if self.turbulence.enabled else 'off'})")
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
        """The same kite with no turbulence and no measurement noise: a steady wind, the same whatever the wind
        model (reset to ``"uniform"``, and the field settings to their defaults, so equal kites compare equal)."""
        return replace(self, turbulence=TurbulenceSettings(enabled=False, anemometer_noise=0.0),
                       noise=NoiseSettings(0.0, 0.0, 0.0), wind_model="uniform",
                       wind_field=WindFieldSettings(), mean_wind=MeanWindSettings())

    def make_wind(self, seed: int, rng: np.random.Generator, mean_rng: np.random.Generator | None = None
                  ) -> WindModel:
        """The :class:`~kite_rto.kite.wind.WindModel` this configuration describes, for plant seed ``seed`` (the
        field's box seed), the wind's own random stream ``rng`` and the mean wind's ``mean_rng``."""
        if self.wind_model == "field" and self.turbulence.enabled:
            fs = self.wind_field
            box = MannBox(fs, fs.sigma(self.params), seed)
            mean = None
            if self.mean_wind.changes:
                edc = edc_amplitude(fs.sigma(self.params), fs.hub_wind(self.params), self.mean_wind.edc_diameter)
                mean = MeanWind(self.mean_wind, mean_rng if mean_rng is not None else np.random.default_rng(seed), edc)
            return FieldWind(box, self.params, self.turbulence.anemometer_noise, rng, fs.components, mean,
                             fs.vane_noise)
        return UniformGust(self.turbulence, self.params.w_ref, rng)


@dataclass(frozen=True)
class Measurement:
    """What the ground station measures at one sample (noise included).

    t s; theta, phi, psi rad; theta_dot, phi_dot, psi_dot rad/s; tension N; position (x, y, z) m in the anchor
    frame; wind_ref m/s (anemometer at z_ref); delta: steering currently applied at the kite (after dead time and
    rate limit), normalized; crashes: crash count since start; step: sample index; wind_direction: wind vane at
    z_ref, rad from the ground frame's x towards y (0 for a wind that never turns).
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
    wind_direction: float = 0.0

    @property
    def altitude(self) -> float:
        """z, m."""
        return self.position[2]


_new = object.__new__


def _measurement(t, theta, phi, psi, theta_dot, phi_dot, psi_dot, tension, position, wind_ref, delta, crashes,
                 step, wind_direction=0.0) -> Measurement:
    """Build a :class:`Measurement` without the frozen dataclass's per-field ``object.__setattr__`` (3-4x faster).

    The result is an ordinary ``Measurement`` (same fields, ``==``, ``hash``, ``repr``, ``replace``).
    """
    m = _new(Measurement)
    m.__dict__.update(t=t, theta=theta, phi=phi, psi=psi, theta_dot=theta_dot, phi_dot=phi_dot, psi_dot=psi_dot,
                      tension=tension, position=position, wind_ref=wind_ref, delta=delta, crashes=crashes,
                      step=step, wind_direction=wind_direction)
    return m


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
        gust_ss, noise_ss, mean_ss = np.random.SeedSequence(self.seed).spawn(3)   # the first two as with spawn(2)
        self.wind = self.config.make_wind(self.seed, np.random.default_rng(gust_ss), np.random.default_rng(mean_ss))
        self._turns = self.wind.turns
        kp = self.config.params
        self._r, self._z_ref, self._shear = kp.r, kp.z_ref, kp.shear
        self._noise_rng = np.random.default_rng(noise_ss)
        self._p = self.config.params.as_vector()
        self._i_wref = KiteParams.names().index("w_ref")
        self._h = self.dt / self.config.substeps
        self.actuator = Actuator(self.config.dead_time, self.config.rate_limit, self.dt)
        self._push = self.actuator.push
        self._substeps = range(self.config.substeps)
        nz = self.config.noise
        self._noise_std = (nz.angle, nz.rate, nz.tension)
        self._step_py = self.model.step_py
        self.state = list(self.config.launch_state)
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

    @property
    def kite_wind(self) -> float:
        """The reference wind the kite flew in during the last step, m/s at ``z_ref`` (the truth: the wind at the
        kite is ``kite_wind (z / z_ref)^shear``; not a measurement, for benchmarks and tests)."""
        return self._p[self._i_wref]

    def step(self, delta: float) -> Measurement:
        """Send steering command ``delta`` (clipped to [-1, 1]; NaN counts as 0) and advance one sample."""
        # Hot path (tens of thousands of calls per simulated hour): locals, no per-call NumPy, three calls (actuator,
        # wind advance, wind at the kite).
        d = float(delta)
        if d != d:
            d = 0.0
        elif d < -1.0:
            d = -1.0
        elif d > 1.0:
            d = 1.0
        ad = self._push(d)
        self.k += 1
        t = self.t = self.k * self._dt_ns * 1e-9
        wind = self.wind
        wind.advance(t)
        if self._turns:
            x, out = self._step_in_wind_frame(ad)
        else:
            p = self._p
            p[self._i_wref] = wind.kite_reference_wind(self._last.position)     # at the step's start position
            x = self.state
            h, step_py = self._h, self._step_py
            for _ in self._substeps:
                x, out = step_py(x, ad, p, h)
        self.state, self._out = x, out
        # one finiteness test for all values: a sum is NaN or infinite iff a term is (or beyond 1e308, not a kite)
        if not (out[_ALTITUDE] > 0.0 and x[0] > 0.0 and _isfinite(sum(x) + sum(out))):
            self._relaunch()
        m = self._last = self._measure()
        return m

    def _step_in_wind_frame(self, ad: float) -> tuple:
        """One sample in a wind that turns: the state (ground frame) turned into the frame of the wind at the kite
        (:mod:`~kite_rto.kite.wind_frame`), the model integrated there with the reference wind whose profile gives
        that wind at the kite's height in that frame, and the state, position and rates turned back."""
        speed, direction, tilt = self.wind.kite_wind(self._last.position)     # at the step's start position
        rot = wind_rotation(direction, tilt)
        back = transpose(rot)
        xf = rotate_state(self.state, rot)
        zf = self._r * math.sin(xf[0]) * math.cos(xf[1])
        w_ref = speed * (self._z_ref / max(zf, MIN_WIND_HEIGHT)) ** self._shear
        p = self._p
        p[self._i_wref] = max(w_ref, MIN_REFERENCE_WIND)
        h, step_py = self._h, self._step_py
        for _ in self._substeps:
            xf, out = step_py(xf, ad, p, h)
        out = list(out)
        x, out[_RATES:_RATES + 3] = rotate_motion(xf, out[_RATES:_RATES + 3], back)
        i = _POSITION
        out[i:i + 3] = rotate_vector(back, out[i:i + 3])
        out[_ALTITUDE] = out[i + 2]
        return x, out

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
        self.actuator.reset()
        self._out = self._evaluate()

    def _evaluate(self) -> list:
        return self.model.step_py(self.state, self.actuator.applied, self._p, 0.0)[1]

    def _measure(self) -> Measurement:
        ni = self._ni
        if ni >= len(self._noise):
            self._noise = self._noise_rng.standard_normal((1024, 7)).tolist()
            ni = 0
        self._ni = ni + 1
        e0, e1, e2, e3, e4, e5, e6 = self._noise[ni]
        x = self.state
        tension, px, py, pz, theta_dot, phi_dot, psi_dot = _measured(self._out)
        sa, sr, st = self._noise_std
        return _measurement(self.t, x[0] + sa * e0, x[1] + sa * e1, x[2] + sa * e2,
                            theta_dot + sr * e3, phi_dot + sr * e4, psi_dot + sr * e5,
                            tension * (1.0 + st * e6), (px, py, pz),
                            self.wind.anemometer(), self.actuator.applied, self.crashes, self.k,
                            self.wind.vane() if self._turns else 0.0)
