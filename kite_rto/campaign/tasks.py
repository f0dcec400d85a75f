"""What a campaign's workers run: a scenario's oracle (:func:`oracle_task`), a GMA run (:func:`gma_task`) and a
baseline run (:func:`baseline_task`), each from a picklable :class:`RunSpec`, answering plain JSON values.

Every task first checks that the worker runs the client's code version. A baseline's flight-time budget is
``spec.budget`` times the flight time at which the reference GMA run on the same scenario and seed reached 99 % of
the oracle (its whole flight time if it did not), and it stops once a candidate reaches 99 %. In a campaign of
fixed flights (``RunSpec.flight``) every method flies that long and its result carries the yield of the flight.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from functools import partial

from ..flight.shape import ShapeBox
from ..rto.flight_yield import flight_yield
from ..rto.judge import altitude_floor, judge, reaches
from ..rto.oracle import find_oracle, plant_performance
from ..rto.settings import KiteRTOSettings
from .methods import fly_baseline, fly_gma
from .results import RunResult
from .scenarios import Scenario
from .version import check_code_version

__all__ = ["RunSpec", "oracle_task", "gma_task", "baseline_task", "baseline_budget"]


@dataclass(frozen=True)
class RunSpec:
    """One run of a campaign.

    Attributes:
        scenario: the :class:`Scenario` flown.
        seed: plant seed.
        method: a GMA variant's name or a baseline (:data:`~kite_rto.campaign.methods.BASELINES`).
        settings: GMA: the variant's settings; a baseline: the reference GMA's (experiment spec, box, start).
        n_iter: GMA iterations.
        budget: a baseline's flight time over the reference GMA's time to 99 % (> 0).
        code: the client's :func:`~kite_rto.campaign.version.code_version`.
        flight: a campaign of fixed flights: every method flies this long (s; GMA as many iterations as it holds,
            a baseline without stopping early) and is judged by its yield; None: the time-to-99 % campaign.
    """

    scenario: Scenario
    seed: int
    method: str
    settings: KiteRTOSettings
    n_iter: int
    budget: float
    code: str
    flight: float | None = None


def oracle_task(scenario: Scenario, box: ShapeBox, code: str) -> dict:
    """The scenario's oracle (:func:`~kite_rto.rto.oracle.find_oracle`, cached on disk by it):
    ``{"scenario", "tension_kn", "c" (rad), "wall_s" (to compute or read it)}``."""
    check_code_version(code)
    t0 = time.perf_counter()
    res = find_oracle(scenario.plant, box, h_min=scenario.h_min)
    return {"scenario": scenario.name, "tension_kn": res.tension_kn, "c": list(res.c),
            "wall_s": time.perf_counter() - t0}


def gma_task(spec: RunSpec, oracle: dict) -> dict:
    """GMA on the scenario, judged: a :class:`RunResult` as a dict."""
    check_code_version(spec.code)
    t0 = time.perf_counter()
    flown = fly_gma(spec.scenario, spec.seed, spec.n_iter, spec.settings, spec.flight)
    verdict = judge(spec.scenario.plant, spec.scenario.h_min, oracle["tension_kn"], flown.iterates, flown.times)
    return RunResult.judged(spec.scenario, spec.seed, spec.method, flown, verdict, oracle["tension_kn"], None,
                            spec.code, time.perf_counter() - t0, _yield(spec, oracle, flown)).to_dict()


def _yield(spec: RunSpec, oracle: dict, flown):
    """The flight's :class:`~kite_rto.rto.flight_yield.FlightYield` on the scenario's deterministic plant in its
    (stationary) wind, for a campaign of fixed flights; None otherwise."""
    if spec.flight is None:
        return None
    sc = spec.scenario
    return flight_yield(flown.segments, lambda c, t: plant_performance(sc.plant, c), lambda t: oracle["tension_kn"],
                        altitude_floor(sc.h_min))


def baseline_budget(budget: float, gma_row: dict) -> float:
    """``budget`` times the reference GMA run's flight time to 99 % (its whole flight time if it did not reach), s."""
    t_ref = gma_row["t99_s"] if gma_row["t99_s"] is not None else gma_row["flight_time_s"]
    return budget * t_ref


def baseline_task(spec: RunSpec, oracle: dict, gma_row: dict | None = None) -> dict:
    """Baseline ``spec.method`` on the scenario with the budget from the reference GMA run ``gma_row`` (a fixed
    flight: ``spec.flight``, no reference), judged: a :class:`RunResult` as a dict."""
    check_code_version(spec.code)
    t0 = time.perf_counter()
    if spec.flight is None:
        budget_s = baseline_budget(spec.budget, gma_row)
        stop = partial(reaches, spec.scenario.plant, spec.scenario.h_min, oracle["tension_kn"])
    else:                                     # a fixed flight: the whole of it, as an operator would fly it
        budget_s, stop = spec.flight, None
    flown = fly_baseline(spec.method, spec.scenario, spec.seed, spec.settings, budget_s, stop)
    verdict = judge(spec.scenario.plant, spec.scenario.h_min, oracle["tension_kn"], flown.iterates, flown.times)
    return RunResult.judged(spec.scenario, spec.seed, spec.method, flown, verdict, oracle["tension_kn"], budget_s,
                            spec.code, time.perf_counter() - t0, _yield(spec, oracle, flown)).to_dict()
