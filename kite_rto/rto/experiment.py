"""Plant experiments: hold setpoints ``c``, let the transient die out, average whole laps (SPEC §4).

An :class:`ExperimentEvaluator` is fed one plant :class:`~kite_rto.kite.plant.Measurement` at a time (from the
plant directly in the pure runner, from topics in the ROS optimizer node). It detects laps with
:class:`~kite_rto.flight.laps.LapDetector`, drops the laps flown while the kite settles on the new path, and
once ``n_laps`` whole laps are in returns an :class:`ExperimentOutcome` in the units of the kite
``ModelProblem``: cost = minus the mean line tension in kN, constraint = ``h_min`` minus the minimum altitude
over the averaged laps, in m.

Turbulence normalization: the tension of a lap scales with the dynamic pressure ``~ w^2``, so a gusty lap is
worth more than a calm one with the same path. Each lap contributes its tension coefficient
``C_T = mean tension / mean(w^2)`` scaled back to a reference wind, ``C_T * w_scale^2``: the tension the lap would
have given in that wind. ``ExperimentSpec.wind_source`` chooses ``w`` and ``w_scale``
(:mod:`~kite_rto.rto.wind_source`: none, the anemometer at ``z_ref``, the anemometer delayed by the transport
lag, or the wind observer at the kite; ``benchmarks/bench_normalization.py`` measures the scatter of each).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..flight.laps import LapCrossing, LapDetector, LapStats
from ..kite.params import KiteParams, check_range
from ..kite.plant import DEFAULT_WIND_MODEL
from .experiment_end import CRASHED, TIMED_OUT, ExperimentEnd
from .wind_source import WIND_SOURCES, make_wind_source

__all__ = ["H_MIN", "ExperimentSpec", "ExperimentOutcome", "ExperimentEvaluator", "PlantFlight", "DEFAULT_WIND_SOURCES",
           "default_wind_source"]

H_MIN = 100.0
"""The default minimum altitude of the kite, m (do-mpc's kite MPC: 80-120 m); every default h_min is this one."""

DEFAULT_WIND_SOURCES = {"uniform": "anemometer", "field": "observer_profile"}
"""The experiment's wind source for each plant wind model (``PlantConfig.wind_model``), chosen by
``benchmarks/bench_normalization.py``: with the uniform gust the anemometer measures the kite's own gust; in the
3-D field the observer at the kite scatters least (docs/benchmarks.md, "Realistic wind"), and its profile form
scatters as little without bending the cost between paths (``benchmarks/bench_normalization_bias.py``)."""


def default_wind_source(wind_model: str = DEFAULT_WIND_MODEL) -> str:
    """The default :attr:`ExperimentSpec.wind_source` for a plant with ``wind_model``."""
    try:
        return DEFAULT_WIND_SOURCES[wind_model]
    except KeyError:
        raise ValueError(f"wind model {wind_model!r}: expected one of {', '.join(DEFAULT_WIND_SOURCES)}") from None


@dataclass(frozen=True)
class ExperimentSpec:
    """How one experiment at fixed setpoints is measured.

    Attributes:
        settle_time: s after the setpoint change during which no lap may start (covers the controller's
            setpoint blend, 10 s by default), >= 0.
        settle_laps: whole laps dropped after ``settle_time`` (transient of the kite on the new path), >= 0.
        n_laps: whole laps averaged, >= 1.
        max_duration: s; if fewer than ``n_laps`` laps are in by then, the experiment ends with what it has
            (``timed_out``; invalid with no lap at all), > 0.
        h_min: minimum altitude of the constraint, m.
        w_nominal: nominal reference wind the normalized tension is scaled to, m/s (the model's ``w_ref``).
        normalize: False: raw lap tensions whatever ``wind_source`` says (kept for older settings:
            ``normalize=False`` is ``wind_source="none"``).
        wind_source: the wind the lap tension is normalized by, one of
            :data:`~kite_rto.rto.wind_source.WIND_SOURCES` (default: :func:`default_wind_source` of the plant's
            default wind model).
    """

    settle_time: float = 10.0
    settle_laps: int = 1
    n_laps: int = 4
    max_duration: float = 300.0
    h_min: float = H_MIN
    w_nominal: float = KiteParams().w_ref
    normalize: bool = True
    wind_source: str = default_wind_source()

    def __post_init__(self):
        n = type(self).__name__
        check_range(n, "settle_time", self.settle_time, 0.0)
        for f, lo in (("settle_laps", 0), ("n_laps", 1)):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise ValueError(f"{n}.{f} = {v!r}: expected an integer >= {lo}")
        check_range(n, "max_duration", self.max_duration, 0.0, low_open=True)
        check_range(n, "h_min", self.h_min, 0.0)
        check_range(n, "w_nominal", self.w_nominal, 0.0, low_open=True)
        if not isinstance(self.normalize, bool):
            raise ValueError(f"{n}.normalize = {self.normalize!r}: expected True or False")
        if self.wind_source not in WIND_SOURCES:
            raise ValueError(f"{n}.wind_source = {self.wind_source!r}: expected one of {', '.join(WIND_SOURCES)}")

    @property
    def source(self) -> str:
        """The wind source in effect: ``"none"`` when ``normalize`` is False, else :attr:`wind_source`."""
        return self.wind_source if self.normalize else "none"


@dataclass
class ExperimentOutcome:
    """Result of one experiment (units of the kite ``ModelProblem``).

    Attributes:
        c: setpoints flown (rad), or None if not given to :meth:`ExperimentEvaluator.start`.
        cost: minus the mean (normalized) line tension, kN.
        constraint: ``h_min`` minus the minimum altitude over the averaged laps, m.
        cost_std, constraint_std: standard errors (std over laps / sqrt(n)); NaN with a single lap.
        n_laps: laps averaged.
        mean_tension_kn: raw mean lap tension, kN (not normalized).
        min_altitude: m.
        crashed: the kite crashed during the experiment (the outcome is then invalid).
        timed_out: ``max_duration`` elapsed before ``n_laps`` laps were in.
        valid: usable by the optimizer; the caller repeats invalid experiments.
        t_start, t_end: s, setpoint change and end of the experiment (flight time used).
        laps: the averaged :class:`LapStats`.
    """

    c: np.ndarray | None
    cost: float
    constraint: float
    cost_std: float
    constraint_std: float
    n_laps: int
    mean_tension_kn: float
    min_altitude: float
    crashed: bool
    timed_out: bool
    valid: bool
    t_start: float
    t_end: float
    laps: list = field(default_factory=list)

    @property
    def duration(self) -> float:
        """Flight time of the experiment, s."""
        return self.t_end - self.t_start

    @property
    def tension_kn(self) -> float:
        """Mean (normalized if the spec says so) tension, kN: ``-cost``."""
        return -self.cost


def _stderr(v: np.ndarray) -> float:
    return float(np.std(v, ddof=1) / math.sqrt(v.size)) if v.size > 1 else math.nan


class ExperimentEvaluator:
    """Measures one experiment after another from a stream of plant measurements.

    Call :meth:`start` when the setpoints change (with the time of the latest measurement), then
    :meth:`update` with every measurement; it returns the :class:`ExperimentOutcome` once, when the
    experiment is complete, crashed or timed out, and None otherwise (and after that, until the next start).

    Args:
        spec: :class:`ExperimentSpec`.
        laps: a :class:`LapDetector` (a default one if None); it is reset at every start and crash.
        model_params: the model's :class:`KiteParams` (the wind sources' shear, z_ref, tether length).

    Every measurement, also between experiments, goes to the wind source (:attr:`wind`): the observer and the
    transport lag need the flight's history. ``wind_source="observer"`` needs measurements with ``theta_dot`` and
    ``phi_dot`` (rad/s).
    """

    def __init__(self, spec: ExperimentSpec | None = None, laps: LapDetector | None = None,
                 model_params: KiteParams | None = None):
        self.spec = spec or ExperimentSpec()
        self.wind = make_wind_source(self.spec.source, self.spec.w_nominal, model_params)
        self.wind_estimate = math.nan     # the source's reference wind at z_ref for the last measurement, m/s
        self.laps = laps or LapDetector()
        self.c = None
        self.n_laps = self.spec.n_laps
        self.max_duration = self.spec.max_duration
        self.t_start = math.nan
        self.active = False
        self.end = None                   # the experiment's ExperimentEnd (from start on)
        self._kept: list[LapStats] = []

    def start(self, t: float, c=None, n_laps: int | None = None) -> None:
        """Begin an experiment at time ``t`` (s), the moment setpoints ``c`` (rad, optional) are applied; it averages
        ``n_laps`` whole laps (default the spec's), with ``max_duration`` scaled by ``n_laps`` over the spec's."""
        if n_laps is None:
            n_laps = self.spec.n_laps
        if isinstance(n_laps, bool) or not isinstance(n_laps, (int, np.integer)) or n_laps < 1:
            raise ValueError(f"ExperimentEvaluator.start: n_laps = {n_laps!r}: expected an integer >= 1")
        self.n_laps = int(n_laps)
        self.max_duration = self.spec.max_duration * max(1.0, self.n_laps / self.spec.n_laps)
        self.c = None if c is None else np.asarray(c, dtype=float).copy()
        self.t_start = float(t)
        self.active = True
        sp, d = self.spec, self.laps
        self.end = ExperimentEnd(self.t_start, self.n_laps, sp.settle_time, sp.settle_laps, self.max_duration,
                                 LapCrossing(d.hysteresis, d.min_duration, d.max_duration))
        self._kept = []
        self.laps.reset()

    def update(self, m, cross_track: float = math.nan) -> ExperimentOutcome | None:
        """Add one measurement (``t, theta, phi, tension, position, wind_ref, crashes``; for the observer also
        ``psi, theta_dot, phi_dot``)."""
        w = self.wind_estimate = self.wind.update(m)
        if not self.active:
            return None
        ended = self.end.update(m.t, m.phi, m.crashes)
        if ended == CRASHED:
            return self._finish(m.t, crashed=True)
        lap = self.laps.update(m.t, m.theta, m.phi, m.tension, m.position[2], cross_track, w)
        if self.end.kept:
            self._kept.append(lap)
        if ended is not None:
            return self._finish(m.t, timed_out=ended == TIMED_OUT)
        return None

    def _finish(self, t: float, crashed: bool = False, timed_out: bool = False) -> ExperimentOutcome:
        self.active = False
        sp, laps = self.spec, list(self._kept)
        n = len(laps)
        if n:
            raw = np.array([lap.mean_tension for lap in laps]) / 1000.0
            norm = np.array([lap.tension_coefficient for lap in laps]) * self.wind.scale() ** 2 / 1000.0
            tension = norm if self.wind.normalizes and np.all(np.isfinite(norm)) else raw
            z = np.array([lap.min_altitude for lap in laps])
            cost, cost_std = -float(np.mean(tension)), _stderr(tension)
            z_min = float(np.min(z))
            constraint, constraint_std = sp.h_min - z_min, _stderr(z)
            raw_mean = float(np.mean(raw))
        else:
            cost = constraint = cost_std = constraint_std = raw_mean = z_min = math.nan
        return ExperimentOutcome(
            c=self.c, cost=cost, constraint=constraint, cost_std=cost_std, constraint_std=constraint_std,
            n_laps=n, mean_tension_kn=raw_mean, min_altitude=z_min, crashed=crashed, timed_out=timed_out,
            valid=(not crashed) and n >= 1, t_start=self.t_start, t_end=float(t), laps=laps)


class PlantFlight:
    """A simulated kite flying continuously under the path controller; :meth:`fly` runs one experiment.

    Used by the baselines and the oracle (GMA itself goes through ``RTOSession``). Setpoint changes are
    applied with :meth:`PathController.set_setpoints`; crashed experiments are repeated.

    Args:
        plant_config: :class:`~kite_rto.kite.plant.PlantConfig`.
        seed: plant seed.
        spec: :class:`ExperimentSpec`.
        c0: setpoints flown from launch (rad); default: the first ``fly`` request.
        controller_settings: :class:`~kite_rto.flight.controller.ControllerSettings`.
    """

    def __init__(self, plant_config=None, seed: int = 0, spec: ExperimentSpec | None = None, c0=None,
                 controller_settings=None):
        self.plant_config, self.seed = plant_config, seed
        self.spec = spec or ExperimentSpec()
        self.controller_settings = controller_settings
        self.evaluator = ExperimentEvaluator(self.spec)
        self.plant = self.controller = None
        self.experiments: list[ExperimentOutcome] = []
        if c0 is not None:
            self._launch(c0)

    def _launch(self, c) -> None:
        from ..flight.closed_loop import make_closed_loop
        from ..flight.path import Setpoints
        self.plant, self.controller = make_closed_loop(Setpoints.from_array(c), self.plant_config, self.seed,
                                                       self.controller_settings)

    @property
    def t(self) -> float:
        """Flight time so far, s."""
        return 0.0 if self.plant is None else self.plant.t

    def fly(self, c, max_repeats: int = 3) -> ExperimentOutcome:
        """Apply setpoints ``c`` (rad) and return the outcome of the experiment (repeated after a crash)."""
        from ..flight.path import Setpoints
        c = np.asarray(c, dtype=float)
        if self.plant is None:
            self._launch(c)
        else:
            self.controller.set_setpoints(Setpoints.from_array(c))
        plant, ctl = self.plant, self.controller
        m = plant.measure()
        for _ in range(max_repeats + 1):
            self.evaluator.start(m.t, c)
            out = None
            while out is None:
                m = plant.step(ctl.command(m))
                out = self.evaluator.update(m, ctl.status.cross_track)
            if out.valid:
                break
        self.experiments.append(out)
        return out
