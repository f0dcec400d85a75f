"""The methods a campaign compares on one scenario and seed: GMA (:func:`fly_gma`) and the baselines
(:func:`fly_baseline`), each returning what it flew as a :class:`Flown`.

GMA runs the pure runner with a :class:`~kite_rto.rto.settings.KiteRTOSettings` (a *variant*) whose experiment
h_min is the scenario's (:func:`scenario_settings`; GMA's OCP takes it from there). The baselines start at GMA's
start point (the model optimum under the scenario's h_min), use GMA's experiment spec and box, and fly a given
flight-time budget.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..flight.shape import setpoints_from_shape
from ..rto.baselines import bayes_opt_plant, finite_difference_ascent, model_only, nelder_mead_plant
from ..rto.builder import model_only_optimum
from ..rto.flight_yield import Segment, segments_of_history
from ..rto.runner import run_rto
from ..rto.settings import KiteRTOSettings
from .scenarios import Scenario

__all__ = ["GMA", "BASELINES", "METHODS", "Flown", "scenario_settings", "start_point", "fly_gma", "fly_baseline"]

GMA = "gma"
"""The method name of GMA with default settings (further GMA variants get their own names)."""
BASELINES = ("model-only", "nelder-mead", "fd-ascent", "bayes-opt")
"""The baselines: the model optimum held, and the model-free Nelder–Mead, FD ascent and Bayesian optimization."""
METHODS = (GMA,) + BASELINES
_UNBOUNDED = 10**9
"""GMA's iterations in a flight of fixed length: as many as it holds."""


@dataclass(frozen=True)
class Flown:
    """What one method flew.

    Attributes:
        iterates: the recommended setpoints in order (rad, (n, 3)): GMA's c_0..c_K, a baseline's candidates.
        times: flight time (s) at which each became available.
        flight_time: total simulated flight, s.
        experiments: experiments flown.
        crashes: plant crashes during the flight.
        message: why the run stopped early ("" if it did not).
        segments: what was flown when: :class:`~kite_rto.rto.flight_yield.Segment` s (setpoints rad), one per
            finished experiment, for the yield of the flight.
    """

    iterates: np.ndarray
    times: np.ndarray
    flight_time: float
    experiments: int
    crashes: int
    message: str = ""
    segments: tuple = ()


def scenario_settings(settings: KiteRTOSettings, scenario: Scenario) -> KiteRTOSettings:
    """``settings`` with the scenario's h_min (m) in its experiment spec (GMA's OCP derives its h_min from it)."""
    return replace(settings, experiment=replace(settings.experiment, h_min=scenario.h_min))


def start_point(settings: KiteRTOSettings) -> np.ndarray:
    """GMA's start setpoints (rad) for ``settings``: ``settings.c0``, else the model optimum in its box under its
    experiment's h_min (as :func:`~kite_rto.rto.builder.make_gma` starts)."""
    if settings.c0 is not None:
        return np.asarray(settings.c0, dtype=float)
    return model_only_optimum(settings).c


def fly_gma(scenario: Scenario, seed: int, n_iter: int, settings: KiteRTOSettings,
            flight: float | None = None) -> Flown:
    """GMA (``settings`` with the scenario's h_min) for ``n_iter`` iterations on the scenario's plant, or, with
    ``flight`` (s), for as many iterations as that flight time holds."""
    if flight is None:
        res = run_rto(scenario.plant, seed, n_iter, scenario_settings(settings, scenario))
    else:
        res = run_rto(scenario.plant, seed, _UNBOUNDED, scenario_settings(settings, scenario), max_flight_time=flight)
    return Flown(iterates=res.iterates, times=res.iterate_times, flight_time=res.flight_time,
                 experiments=len(res.experiments), crashes=res.crashes, message=res.message,
                 segments=tuple(segments_of_history(res.history, setpoints_from_shape)))


def fly_baseline(method: str, scenario: Scenario, seed: int, settings: KiteRTOSettings, budget: float,
                 stop=None) -> Flown:
    """Baseline ``method`` (one of :data:`BASELINES`) on the scenario's plant for ``budget`` s of flight, with
    GMA's experiment spec, box and start point from ``settings``; it ends early once ``stop(c)`` accepts a
    candidate."""
    settings = scenario_settings(settings, scenario)
    c0, spec, box, plant = start_point(settings), settings.experiment, settings.box, scenario.plant
    if method == "model-only":
        run = model_only(c0, budget)
    elif method == "nelder-mead":
        run = nelder_mead_plant(plant, seed, c0, budget, spec, box, stop=stop)
    elif method == "fd-ascent":
        run = finite_difference_ascent(plant, seed, c0, budget, spec, box, stop=stop)
    elif method == "bayes-opt":
        run = bayes_opt_plant(plant, seed, c0, budget, spec, box, stop=stop)
    else:
        raise ValueError(f"baseline {method!r}: expected one of {', '.join(BASELINES)}")
    return Flown(iterates=np.array(run.candidates), times=np.array(run.times), flight_time=float(run.flight_time),
                 experiments=run.experiments, crashes=run.crashes,
                 segments=tuple(Segment(t0, t1, tuple(map(float, c)), "") for t0, t1, c in run.flown))
