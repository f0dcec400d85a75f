"""Baselines for GMA on the same plant and measurement budget (same experiments, same flight time limit).

* :func:`model_only` — fly the model-only optimum, no adaptation.
* :func:`finite_difference_ascent` — model-free: forward-difference gradient of the measured tension, projected
  gradient step in box-normalized shape coordinates, step length halved when the measured tension drops.
* :func:`nelder_mead_plant` — SciPy Nelder–Mead directly on measured experiments (box-normalized, clipped).
* :func:`bayes_opt_plant` — Bayesian optimization (the ``bayes_opt`` package: a Gaussian process with a learned
  noise level, upper confidence bound) on measured experiments in box-normalized shape coordinates.

Each returns a :class:`BaselineRun`: the candidate setpoints it would recommend after each experiment and the
flight time at which it could; :func:`kite_rto.rto.judge.judge` judges the candidates on the deterministic
plant.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .experiment import ExperimentSpec, PlantFlight
from ..flight.shape import ShapeBox
from ..kite.plant import PlantConfig

__all__ = ["BaselineRun", "model_only", "finite_difference_ascent", "nelder_mead_plant", "bayes_opt_plant"]


class _Budget(Exception):
    pass


@dataclass
class BaselineRun:
    """Candidates (rad, (n, 3)) and the flight time (s) at which each became the recommendation.

    ``stop``: optional ``callable(c) -> bool`` judging each new candidate; once it returns True the run ends
    early (``stopped``), e.g. when a candidate reaches the target on the deterministic plant. ``crashes``: plant
    crashes during the run's flight. ``flown``: ``(t_start, t_end, c)`` (s, s, rad) of every finished experiment,
    in order (the model-only run: its point over the whole budget).
    """

    name: str
    candidates: list = field(default_factory=list)
    times: list = field(default_factory=list)
    flight_time: float = 0.0
    experiments: int = 0
    crashes: int = 0
    stop: object = None
    stopped: bool = False
    flown: list = field(default_factory=list)

    def add(self, c, t) -> None:
        self.candidates.append(np.asarray(c, dtype=float).copy())
        self.times.append(float(t))
        if self.stop is not None and not self.stopped and self.stop(self.candidates[-1]):
            self.stopped = True


def model_only(c0, budget: float) -> BaselineRun:
    """The model-only optimum ``c0`` held for the whole budget (s)."""
    run = BaselineRun("model-only")
    run.add(c0, 0.0)
    run.flight_time = budget
    run.flown = [(0.0, float(budget), np.asarray(c0, dtype=float).copy())]
    return run


def _flight(config, seed, spec, c0):
    return PlantFlight(config or PlantConfig(), seed, spec, c0=c0)


def _finish(run: BaselineRun, fl: PlantFlight) -> BaselineRun:
    run.flight_time, run.experiments = fl.t, len(fl.experiments)
    starts = [e.t_start for e in fl.experiments[:1]] + [e.t_end for e in fl.experiments[:-1]]   # contiguous: a
    run.flown = [(t0, e.t_end, np.asarray(e.c, dtype=float).copy())                       # repeated attempt
                 for t0, e in zip(starts, fl.experiments)]                                 # flew the same c
    run.crashes = 0 if fl.plant is None else fl.plant.crashes
    return run


def _merit(out, penalty: float) -> float:
    """Measured cost plus ``penalty`` (kN/m) times the altitude violation (m): lower is better."""
    return out.cost + penalty * max(0.0, out.constraint)


def finite_difference_ascent(config: PlantConfig | None, seed: int, c0, budget: float,
                             spec: ExperimentSpec | None = None, box: ShapeBox | None = None,
                             fd_step: float = 0.5, step: float = 0.3, stop=None) -> BaselineRun:
    """Model-free projected gradient ascent on the measured (normalized) tension.

    Per iteration: nominal + 3 forward perturbations (``fd_step`` of the box width); move ``step`` (box
    widths) along the normalized gradient; halve ``step`` when the nominal tension dropped. Altitude:
    the measured constraint ``g`` > 0 adds its gradient (penalty 5 kN/m).
    """
    box = box or ShapeBox()
    spec = spec or ExperimentSpec()
    fl = _flight(config, seed, spec, c0)
    run = BaselineRun("FD ascent", stop=stop)
    x = np.clip(box.to_unit(c0), 0.0, 1.0)
    run.add(box.from_unit(x), 0.0)
    prev = -math.inf
    while fl.t < budget and not run.stopped:
        f0 = fl.fly(box.from_unit(x))
        merit0 = -f0.cost - 5.0 * max(0.0, f0.constraint)
        if merit0 < prev:
            step *= 0.5
        prev = merit0
        grad = np.zeros(3)
        for i in range(3):
            xp = x.copy()
            h = fd_step if x[i] + fd_step <= 1.0 else -fd_step
            xp[i] = np.clip(x[i] + h, 0.0, 1.0)
            fp = fl.fly(box.from_unit(xp))
            grad[i] = ((-fp.cost - 5.0 * max(0.0, fp.constraint)) - merit0) / (xp[i] - x[i])
        n = np.linalg.norm(grad)
        if n > 0:
            x = np.clip(x + step * grad / n, 0.0, 1.0)
        run.add(box.from_unit(x), fl.t)
    return _finish(run, fl)


def nelder_mead_plant(config: PlantConfig | None, seed: int, c0, budget: float,
                      spec: ExperimentSpec | None = None, box: ShapeBox | None = None,
                      simplex: float = 0.3, stop=None) -> BaselineRun:
    """SciPy Nelder–Mead on measured experiments; the candidate is the best measured point so far."""
    from scipy.optimize import minimize
    box = box or ShapeBox()
    spec = spec or ExperimentSpec()
    fl = _flight(config, seed, spec, c0)
    run = BaselineRun("Nelder-Mead", stop=stop)
    x0 = np.clip(box.to_unit(c0), 0.0, 1.0)
    run.add(c0, 0.0)
    best = [math.inf]

    def f(x):
        if fl.t >= budget or run.stopped:
            raise _Budget
        xc = np.clip(x, 0.0, 1.0)
        out = fl.fly(box.from_unit(xc))
        val = out.cost + 5.0 * max(0.0, out.constraint)
        if val < best[0]:
            best[0] = val
            run.add(box.from_unit(xc), fl.t)
        return val + 1e3 * float(np.sum((x - xc) ** 2))

    sim = np.vstack([x0] + [np.clip(x0 + (simplex if x0[i] < 0.5 else -simplex) * np.eye(3)[i], 0, 1)
                            for i in range(3)])
    try:
        minimize(f, x0, method="Nelder-Mead", options={"initial_simplex": sim, "maxfev": 10_000,
                                                        "xatol": 1e-3, "fatol": 1e-3})
    except _Budget:
        pass
    return _finish(run, fl)


def bayes_opt_plant(config: PlantConfig | None, seed: int, c0, budget: float,
                    spec: ExperimentSpec | None = None, box: ShapeBox | None = None, init_points: int = 4,
                    kappa: float = 2.576, penalty: float = 5.0, stop=None) -> BaselineRun:
    """Bayesian optimization on measured experiments; the candidate is the best measured point so far.

    The ``bayes_opt`` package's Gaussian process (Matern 5/2 plus a white-noise kernel whose level is fitted, so
    the experiments' scatter is learned, not assumed) over box-normalized shape coordinates, with an upper
    confidence bound (``kappa``) as acquisition. The measured merit is the experiment's cost plus ``penalty``
    kN per metre of altitude violation (as in :func:`nelder_mead_plant`). It flies ``c0`` first, then
    ``init_points`` uniform random points (seeded with ``seed``), then the acquisition's maximizers, until the
    flight time reaches ``budget`` (s) or ``stop`` accepts a candidate.
    """
    from bayes_opt import BayesianOptimization, acquisition
    from sklearn.gaussian_process.kernels import Matern, WhiteKernel
    box = box or ShapeBox()
    spec = spec or ExperimentSpec()
    names = ("theta_0", "A_phi", "aspect")
    fl = _flight(config, seed, spec, c0)
    run = BaselineRun("Bayes-opt", stop=stop)
    run.add(c0, 0.0)
    opt = BayesianOptimization(f=None, pbounds={n: (0.0, 1.0) for n in names}, random_state=seed, verbose=0,
                               acquisition_function=acquisition.UpperConfidenceBound(kappa=kappa),
                               allow_duplicate_points=True)
    opt.set_gp_params(kernel=Matern(nu=2.5) + WhiteKernel(noise_level=0.1, noise_level_bounds=(1e-6, 1.0)))
    queue = [np.clip(box.to_unit(c0), 0.0, 1.0)] + [np.array([p[n] for n in names])
                                                   for p in opt.random_sample(init_points)]
    best = math.inf
    while fl.t < budget and not run.stopped:
        x = queue.pop(0) if queue else np.array([opt.suggest()[n] for n in names])
        x = np.clip(x, 0.0, 1.0)
        val = _merit(fl.fly(box.from_unit(x)), penalty)
        opt.register(params=dict(zip(names, x.tolist())), target=-val)
        if val < best:
            best = val
            run.add(box.from_unit(x), fl.t)
    return _finish(run, fl)

