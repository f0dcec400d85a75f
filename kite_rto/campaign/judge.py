"""Judge a run's iterates on a scenario's deterministic plant against its oracle (:func:`judge`, :class:`Verdict`).

An iterate *reaches* the target when, re-flown on the deterministic plant (turbulence and noise off,
:func:`~kite_rto.rto.oracle.plant_performance`), it gives at least ``fraction`` of the oracle's mean tension with
a minimum altitude of at least ``h_min - h_tol``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..rto.oracle import plant_performance
from .scenarios import Scenario

__all__ = ["Verdict", "judge", "reaches"]


@dataclass(frozen=True)
class Verdict:
    """The judged iterates of one run.

    Attributes:
        tension_kn: deterministic-plant mean tension of each iterate, kN.
        min_altitude: deterministic-plant minimum altitude of each iterate, m.
        percent: tension as a percentage of the oracle's.
        reached: per iterate, tension >= fraction x oracle and altitude >= h_min - h_tol.
        reach_index: first iterate that reaches (None: none does).
        reach_time: flight time (s) at which that iterate became available (inf: none).
        held_from: first index from which every iterate reaches (None: the last one does not).
        lowest_altitude: lowest judged altitude over all iterates, m.
        below_floor: iterates whose judged altitude is below ``h_min - h_tol``.
    """

    tension_kn: tuple
    min_altitude: tuple
    percent: tuple
    reached: tuple
    reach_index: int | None
    reach_time: float
    held_from: int | None
    lowest_altitude: float
    below_floor: int


def reaches(scenario: Scenario, oracle_tension_kn: float, c, fraction: float = 0.99, h_tol: float = 2.0) -> bool:
    """True if setpoints ``c`` (rad), flown on ``scenario``'s deterministic plant, give at least ``fraction`` of
    ``oracle_tension_kn`` (kN) with a minimum altitude of at least ``h_min - h_tol`` (m): :func:`judge`'s test of
    one iterate (the baselines' stop)."""
    return _passes(plant_performance(scenario.plant, c), scenario, oracle_tension_kn, fraction, h_tol)


def _passes(performance: tuple, scenario: Scenario, oracle_tension_kn: float, fraction: float, h_tol: float) -> bool:
    """The judge's test of one ``(tension kN, min altitude m)``."""
    tension, z = performance
    return bool(tension >= fraction * oracle_tension_kn and z >= scenario.h_min - h_tol)


def judge(scenario: Scenario, oracle_tension_kn: float, iterates, times, fraction: float = 0.99,
          h_tol: float = 2.0) -> Verdict:
    """Re-fly ``iterates`` (setpoints rad, (n, 3)) available at flight ``times`` (s) on ``scenario``'s
    deterministic plant and judge them against ``fraction`` of ``oracle_tension_kn`` (kN)."""
    iterates = np.atleast_2d(np.asarray(iterates, dtype=float))
    times = np.asarray(times, dtype=float)
    if len(times) != len(iterates):
        raise ValueError(f"judge: {len(iterates)} iterates but {len(times)} times")
    perf = [plant_performance(scenario.plant, c) for c in iterates]
    tension = tuple(float(t) for t, _ in perf)
    alt = tuple(float(z) for _, z in perf)
    floor = scenario.h_min - h_tol
    reached = tuple(_passes(p, scenario, oracle_tension_kn, fraction, h_tol) for p in perf)
    k = next((i for i, r in enumerate(reached) if r), None)
    held = next((j for j in range(len(reached)) if all(reached[j:])), None)
    return Verdict(tension_kn=tension, min_altitude=alt,
                   percent=tuple(100.0 * t / oracle_tension_kn for t in tension), reached=reached,
                   reach_index=k, reach_time=float(times[k]) if k is not None else math.inf, held_from=held,
                   lowest_altitude=float(min(alt)), below_floor=sum(z < floor for z in alt))
