"""The kite as a GMA problem: settings, the GMA builder, the per-sample session and the pure runner.

* :class:`KiteRTOSettings` — experiment, gradient and GMA tuning for the kite (defaults measured, see below).
* :func:`make_kite_gma` — a :class:`~kite_rto.gma.GMA` on :func:`~kite_rto.rto.ocp.kite_model_problem`
  in shape coordinates ``x = (theta_0, A_phi, aspect)`` over a :class:`~kite_rto.flight.path.ShapeBox` (every
  point of it is trackable; the trackable set is a curved band in setpoints), started at the model-only
  optimum. GMA's records hold ``x``; everything this module hands out (``RTOSession.c``, iterates,
  experiment logs) is setpoints ``c = (theta_0, A_phi, A_theta)``, rad (:func:`setpoints_from_shape`).
* :class:`RTOSession` — the per-sample logic shared by the pure runner and the ROS optimizer node:
  ``session.start(t)`` gives the first setpoints, then ``session.on_measurement(m)`` for every plant
  measurement returns new setpoints to apply (or None). It feeds an
  :class:`~kite_rto.rto.experiment.ExperimentEvaluator`, repeats crashed experiments and calls GMA's
  ``next_request`` / ``submit``.
* :func:`run_kite_rto` — one :class:`KitePlant` + :class:`PathController` flying continuously, the session
  changing the setpoints; returns an :class:`RTOResult` with every :class:`IterationRecord`.

Tuning (``benchmarks/bench_rto.py``, ``benchmarks/bench_normalization.py``): after the tension-coefficient
normalization a 4-lap experiment's mean scatters by ~1.4 kN, far less than the differences over the
finite-difference steps (half the box width). GMA therefore takes full steps (filter gain 1) inside a trust
region of 0.7 box widths, and measures plant derivatives only along the two privileged directions of
:mod:`~kite_rto.rto.directions` (directional modifier adaptation): theta_0 stays at its robustly active bound, so
an iteration is 3 experiments instead of 4. The altitude constraint's plant gradient comes from half-box secants
of a non-smooth function (the lap's minimum altitude), and after a step it can be off by several metres: a
back-off of 6 m let every iterate from k = 1 pass the judge on 18 of 20 seeds, 4 m on 7 (``benchmarks/bench_rto.py
--backoff``; the README has the numbers).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np

from ..gma import (GMA, DirectionalGradient, ExperimentResult, FiniteDifferenceGradient, GMASettings,
                   LeastSquaresGradient)
from ..flight.closed_loop import make_closed_loop
from ..flight.controller import ControllerSettings
from .experiment import ExperimentEvaluator, ExperimentOutcome, ExperimentSpec
from .directions import ModelUncertainty, kite_privileged_directions
from .ocp import KiteOCPSettings, kite_model_problem
from ..kite.params import KiteParams
from ..flight.path import Setpoints, ShapeBox, setpoints_from_shape, shape_from_setpoints
from ..kite.plant import PlantConfig

__all__ = ["KiteRTOSettings", "kite_problem", "kite_directions", "make_kite_gma", "RTOSession", "ExperimentLog",
           "RTOResult", "run_kite_rto", "model_only_optimum"]

_GRADIENTS = ("directional", "forward", "central", "least_squares")


@dataclass(frozen=True)
class KiteRTOSettings:
    """Tuning of GMA on the kite.

    Attributes:
        experiment: :class:`ExperimentSpec` of every experiment (nominal and perturbations).
        box: the optimizer's :class:`ShapeBox` (shape coordinates); every point of it tracks.
        gradient: ``"directional"`` (DMA: forward differences along ``n_directions`` privileged directions,
            the model's gradient elsewhere), ``"forward"`` / ``"central"`` finite differences in every shape
            coordinate, or ``"least_squares"`` over past points with forward differences as fallback.
        fd_step: finite-difference step per shape coordinate, relative to the box width, in (0, 1]; for
            ``"directional"`` the first value is the step along each privileged direction (box widths).
        n_directions: privileged directions of ``"directional"`` (1 or 2 on the kite: theta_0 is held at a
            robustly active bound).
        uncertainty: the model-parameter deviations that define the privileged directions.
        filter_gain: GMA input filter K, in (0, 1].
        modifier_filter: GMA's first-order filter on the gradient modifiers, in (0, 1] (1 = none).
        trust_radius: initial GMA trust radius (relative to the box width), > 0.
        trust_radius_min: lower limit of the adapted trust radius (relative), > 0.
        backoff: constraint back-off, m (>= 0).
        max_repeats: times a crashed/invalid experiment is repeated before it is submitted as measured
            (NaN-free) or, with no lap at all, the run stops (>= 0).
        c0: initial setpoints (theta_0, A_phi, A_theta), rad; None = the model-only optimum.
    """

    experiment: ExperimentSpec = field(default_factory=lambda: ExperimentSpec(n_laps=4))
    box: ShapeBox = field(default_factory=ShapeBox)
    gradient: str = "directional"
    fd_step: tuple = (0.5, 0.5, 0.5)
    n_directions: int = 2
    uncertainty: ModelUncertainty = field(default_factory=ModelUncertainty)
    filter_gain: float = 1.0
    modifier_filter: float = 1.0
    trust_radius: float = 0.7
    trust_radius_min: float = 0.05
    backoff: float = 6.0
    max_repeats: int = 3
    c0: tuple | None = None

    def __post_init__(self):
        n = type(self).__name__
        if self.gradient not in _GRADIENTS:
            raise ValueError(f"{n}.gradient = {self.gradient!r}: expected one of {_GRADIENTS}")
        steps = np.atleast_1d(np.asarray(self.fd_step, dtype=float))
        if steps.size not in (1, 3) or not np.all((steps > 0) & (steps <= 1)):
            raise ValueError(f"{n}.fd_step = {self.fd_step!r}: expected 1 or 3 values in (0, 1]")
        for f in ("filter_gain", "modifier_filter"):
            if not 0 < getattr(self, f) <= 1:
                raise ValueError(f"{n}.{f} = {getattr(self, f)!r}: expected a value in (0, 1]")
        for f in ("trust_radius", "trust_radius_min"):
            if not getattr(self, f) > 0:
                raise ValueError(f"{n}.{f} = {getattr(self, f)!r}: expected a value > 0")
        if not self.backoff >= 0:
            raise ValueError(f"{n}.backoff = {self.backoff!r}: expected a value >= 0")
        if isinstance(self.n_directions, bool) or self.n_directions not in (1, 2, 3):
            raise ValueError(f"{n}.n_directions = {self.n_directions!r}: expected 1, 2 or 3")
        if isinstance(self.max_repeats, bool) or not isinstance(self.max_repeats, int) or self.max_repeats < 0:
            raise ValueError(f"{n}.max_repeats = {self.max_repeats!r}: expected an integer >= 0")

    def gma_settings(self) -> GMASettings:
        """The :class:`GMASettings` these settings stand for (settle/averaging hints in s and laps)."""
        sp = self.experiment
        return GMASettings(filter_gain=self.filter_gain, modifier_filter=self.modifier_filter,
                           trust_radius=self.trust_radius,
                           trust_radius_min=min(self.trust_radius_min, self.trust_radius),
                           backoff=self.backoff, settle_time=sp.settle_time, averaging=float(sp.n_laps),
                           tol_c=1e-3)

    def experiments_per_iteration(self) -> int:
        """Nominal + perturbation experiments of one iteration (least squares: when it falls back)."""
        n = {"directional": self.n_directions, "central": 6}.get(self.gradient, 3)
        return 1 + n

    def gradient_estimator(self, directions=None):
        """The plant-gradient strategy (absolute steps, rad); ``"directional"`` needs the privileged
        ``directions`` (3, r) in shape coordinates (:func:`make_kite_gma` computes them)."""
        width = self.box.upper() - self.box.lower()
        steps = np.broadcast_to(np.asarray(self.fd_step, dtype=float), (3,)) * width
        if self.gradient == "directional":
            if directions is None:
                raise ValueError("KiteRTOSettings.gradient_estimator: 'directional' needs the privileged directions")
            return DirectionalGradient(directions, step=float(np.ravel(self.fd_step)[0]), reuse=False)
        if self.gradient == "least_squares":
            return LeastSquaresGradient(FiniteDifferenceGradient(steps), radius=2.0 * steps, window=8)
        return FiniteDifferenceGradient(steps, self.gradient)


@lru_cache(maxsize=4)
def kite_problem(box: ShapeBox = ShapeBox(), model_params: KiteParams = KiteParams(),
                 ocp: KiteOCPSettings = KiteOCPSettings()):
    """The kite lap OCP in shape coordinates on ``box`` (cached per process: building it takes seconds)."""
    return kite_model_problem(model_params, ocp, c_lb=box.lower(), c_ub=box.upper(),
                              c_guess=0.5 * (box.lower() + box.upper()), name="kite_lap", shape=True)


@lru_cache(maxsize=4)
def _model_optimum_cached(box, model_params, ocp) -> tuple:
    from .ocp_solve import solve_model_optimum
    pr = kite_problem(box, model_params, ocp)
    sol = solve_model_optimum(pr)
    x = np.clip(sol.c, box.lower(), box.upper())
    i = pr.equalities.numel() + pr.inner_constraints.numel()
    nu = np.maximum(sol.lam_g[i:i + pr.n_g], 0.0)        # multipliers of g(u) <= 0 at the model optimum
    return (tuple(setpoints_from_shape(x).tolist()), sol.mean_tension_kn, sol.min_altitude, tuple(x.tolist()),
            tuple(nu.tolist()))


def model_only_optimum(box: ShapeBox = ShapeBox(), model_params: KiteParams = KiteParams(),
                       ocp: KiteOCPSettings = KiteOCPSettings()) -> tuple:
    """``(c setpoints rad (3,), model mean tension kN, model min altitude m)`` of the model's own optimum in
    ``box``."""
    c, t, z, _, _ = _model_optimum_cached(box, model_params, ocp)
    return np.array(c), t, z


def kite_directions(settings: KiteRTOSettings, model_params: KiteParams = KiteParams(),
                    ocp: KiteOCPSettings = KiteOCPSettings()):
    """The :class:`~kite_rto.gma.PrivilegedDirections` of ``settings`` (shape coordinates), computed at the
    model optimum in ``settings.box`` (cached per process; 10.6 s the first time in `benchmarks/bench_ocp.py`)."""
    _, _, _, x_opt, nu = _model_optimum_cached(settings.box, model_params, ocp)
    return kite_privileged_directions(settings.box, x_opt, nu, model_params, ocp, settings.uncertainty,
                                      settings.n_directions)


def make_kite_gma(settings: KiteRTOSettings | None = None, model_params: KiteParams | None = None,
                  ocp: KiteOCPSettings | None = None, c0=None, history=None) -> GMA:
    """A :class:`GMA` on the kite lap model in shape coordinates, started at setpoints ``c0`` (rad; default:
    settings.c0, else the model optimum).

    ``ocp.h_min`` must equal ``settings.experiment.h_min`` (the plant's and the model's constraint agree).
    """
    settings = settings or KiteRTOSettings()
    model_params = model_params or KiteParams()
    ocp = ocp or KiteOCPSettings(h_min=settings.experiment.h_min)
    if abs(ocp.h_min - settings.experiment.h_min) > 1e-9:
        raise ValueError(f"make_kite_gma: KiteOCPSettings.h_min = {ocp.h_min!r} differs from "
                         f"ExperimentSpec.h_min = {settings.experiment.h_min!r}")
    problem = kite_problem(settings.box, model_params, ocp)
    if c0 is None:
        c0 = settings.c0 if settings.c0 is not None else model_only_optimum(settings.box, model_params, ocp)[0]
    x0 = np.clip(shape_from_setpoints(c0), settings.box.lower(), settings.box.upper())
    directions = kite_directions(settings, model_params, ocp).directions if settings.gradient == "directional" \
        else None
    return GMA(problem, settings.gma_settings(), settings.gradient_estimator(directions), c0=x0, history=history)


@dataclass
class ExperimentLog:
    """One finished experiment: GMA's request id, the setpoints, the outcome submitted, repeats needed."""

    request_id: str
    c: np.ndarray
    outcome: ExperimentOutcome
    repeats: int


def _result(request_id: str, out: ExperimentOutcome) -> ExperimentResult:
    std = lambda v: None if not math.isfinite(v) else float(v)  # noqa: E731
    cs, gs = std(out.cost_std), std(out.constraint_std)
    return ExperimentResult(request_id, float(out.cost), np.array([out.constraint]), cs,
                            None if gs is None else np.array([gs]),
                            {"n_laps": out.n_laps, "t_start": out.t_start, "t_end": out.t_end,
                             "mean_tension_kn": out.mean_tension_kn, "timed_out": out.timed_out})


class RTOSession:
    """Per-sample GMA driver: measurements in, setpoints out (shared by the pure runner and the ROS node).

    Args:
        gma: a :class:`GMA` (e.g. from :func:`make_kite_gma`).
        spec: the :class:`ExperimentSpec` of every experiment.
        max_repeats: repetitions of an invalid experiment (crash, no lap) before giving up on it.
    """

    def __init__(self, gma: GMA, spec: ExperimentSpec | None = None, max_repeats: int = 3):
        self.gma = gma
        self.evaluator = ExperimentEvaluator(spec or ExperimentSpec())
        self.max_repeats = int(max_repeats)
        self.request = None
        self.repeats = 0
        self.experiments: list[ExperimentLog] = []
        self.record_times: list[float] = []   # flight time (s) at which each IterationRecord completed
        self.failed = ""                       # reason if the session had to stop

    @property
    def records(self):
        return self.gma.records

    @property
    def c(self) -> np.ndarray | None:
        """Setpoints ``(theta_0, A_phi, A_theta)`` of the experiment in progress (rad)."""
        return None if self.request is None else setpoints_from_shape(self.request.c)

    def start(self, t: float) -> np.ndarray:
        """Begin (or resume) with GMA's next request at time ``t`` s; returns the setpoints to apply."""
        self.request = self.gma.next_request()
        self.repeats = 0
        self.evaluator.start(t, self.c)
        return self.c

    def on_measurement(self, m) -> np.ndarray | None:
        """Feed one plant measurement; returns new setpoints (rad, (3,)) when they must change, else None.

        A crashed experiment is repeated (the same setpoints are returned again, restarting the settling).
        """
        if self.request is None or self.failed:
            return None
        out = self.evaluator.update(m)
        if out is None:
            return None
        if not out.valid and self.repeats < self.max_repeats:
            self.repeats += 1
            self.evaluator.start(m.t, self.c)
            return self.c
        if not out.valid:
            self.failed = f"experiment {self.request.request_id} invalid after {self.repeats} repeats"
            return None
        self.experiments.append(ExperimentLog(self.request.request_id, self.c, out, self.repeats))
        rec = self.gma.submit(_result(self.request.request_id, out))
        if rec is not None:
            self.record_times.append(float(m.t))
        return self.start(m.t)


@dataclass
class RTOResult:
    """Outcome of :func:`run_kite_rto`.

    Attributes:
        records: every :class:`IterationRecord`.
        experiments: every :class:`ExperimentLog`.
        iterates: setpoints c_0, c_1, ..., c_K (rad), shape (K + 1, 3); c_{k+1} = setpoints_from_shape(records[k].c_next).
        iterate_times: flight time (s) at which each iterate became available (0 for c_0).
        flight_time: total simulated flight time, s.
        crashes: plant crashes during the run.
        seed, failed: plant seed; reason if the run stopped early ("" otherwise).
        history: GMA's :class:`History` (JSON-serializable).
    """

    records: list
    experiments: list
    iterates: np.ndarray
    iterate_times: np.ndarray
    flight_time: float
    crashes: int
    seed: int
    failed: str
    history: object


def run_kite_rto(plant_config: PlantConfig | None = None, seed: int = 0, n_iter: int = 10,
                 settings: KiteRTOSettings | None = None, gma: GMA | None = None,
                 controller_settings: ControllerSettings | None = None,
                 max_flight_time: float = math.inf) -> RTOResult:
    """Fly GMA on one continuously flying simulated kite for ``n_iter`` iterations (pure, no ROS).

    Args:
        plant_config: the real kite (:class:`PlantConfig` defaults: turbulence and noise on).
        seed: plant seed (turbulence and noise); same seed, same setpoint sequence.
        n_iter: GMA iterations to complete.
        settings: :class:`KiteRTOSettings`.
        gma: a fresh GMA to use (default :func:`make_kite_gma` of ``settings``).
        controller_settings: :class:`ControllerSettings` (``box`` is replaced by ``settings.box``'s
            bounding setpoint box).
        max_flight_time: stop after this much simulated flight, s.
    """
    settings = settings or KiteRTOSettings()
    gma = gma or make_kite_gma(settings)
    cs = replace(controller_settings or ControllerSettings(), box=settings.box.setpoint_box())
    session = RTOSession(gma, settings.experiment, settings.max_repeats)
    c_first = Setpoints.from_array(setpoints_from_shape(gma.next_request().c))
    plant, controller = make_closed_loop(c_first, plant_config, seed=seed, settings=cs)
    m = plant.measure()
    crashes0 = m.crashes
    new = session.start(m.t)
    k0 = len(gma.records)
    while len(gma.records) - k0 < n_iter and not session.failed and m.t < max_flight_time:
        if new is not None:
            controller.set_setpoints(Setpoints.from_array(new))
        m = plant.step(controller.command(m))
        new = session.on_measurement(m)
    iterates = [setpoints_from_shape(gma.history.c0 if k0 == 0 else gma.records[k0 - 1].c_next)]
    iterates += [setpoints_from_shape(r.c_next) for r in gma.records[k0:]]
    return RTOResult(records=list(gma.records[k0:]), experiments=session.experiments,
                     iterates=np.array(iterates), iterate_times=np.r_[0.0, session.record_times],
                     flight_time=float(m.t), crashes=m.crashes - crashes0, seed=seed, failed=session.failed,
                     history=gma.history)
