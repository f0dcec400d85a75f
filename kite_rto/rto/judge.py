"""The judge: setpoints re-flown on a plant's deterministic twin against its oracle (:func:`judge_point`,
:func:`judge`, :func:`reaches`), and a whole flight's yield (:func:`judge_flight`). The one place of the target: the campaign, the run report and the benchmarks judge
with it.

An iterate *reaches* the target when, re-flown on the deterministic plant (turbulence and noise off,
:func:`~kite_rto.rto.oracle.plant_performance`), it gives at least :data:`REACH_FRACTION` of the oracle's mean
tension with a minimum altitude of at least ``h_min -`` :data:`ALTITUDE_TOLERANCE_M` (:func:`altitude_floor`).
Every function takes the plant configuration and h_min it judges against explicitly: a run is judged on its own
plant and altitude floor, never on a default one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kite.plant import PlantConfig
from ..flight.shape import setpoints_from_shape
from .flight_yield import FlightYield, flight_yield, segments_of_history
from .oracle import plant_performance

__all__ = ["REACH_FRACTION", "REACH_PERCENT", "ALTITUDE_TOLERANCE_M", "Judged", "Verdict", "altitude_floor",
           "judge_point", "judge", "reaches", "judge_flight"]

REACH_FRACTION = 0.99
"""The target: this fraction of the oracle's mean tension."""
REACH_PERCENT = 100.0 * REACH_FRACTION
""":data:`REACH_FRACTION` as a percentage of the oracle (99)."""
ALTITUDE_TOLERANCE_M = 2.0
"""How far (m) a judged minimum altitude may lie below h_min and still count as above the floor."""


def altitude_floor(h_min: float) -> float:
    """The lowest judged minimum altitude (m) that counts as above the floor of ``h_min`` (m)."""
    return h_min - ALTITUDE_TOLERANCE_M


@dataclass(frozen=True)
class Judged:
    """One setpoint, judged.

    Attributes:
        tension_kn: deterministic-plant mean tension, kN (0 for a crash).
        min_altitude: deterministic-plant minimum altitude, m (-inf for a crash).
        percent: tension as a percentage of the oracle's.
        above_floor: min_altitude >= :func:`altitude_floor` (h_min).
        reached: above the floor and tension >= :data:`REACH_FRACTION` x the oracle's.
    """

    tension_kn: float
    min_altitude: float
    percent: float
    above_floor: bool
    reached: bool


@dataclass(frozen=True)
class Verdict:
    """The judged iterates of one run.

    Attributes:
        tension_kn: deterministic-plant mean tension of each iterate, kN.
        min_altitude: deterministic-plant minimum altitude of each iterate, m.
        percent: tension as a percentage of the oracle's.
        reached: per iterate, :attr:`Judged.reached`.
        reach_index: first iterate that reaches (None: none does).
        reach_time: flight time (s) at which that iterate became available (inf: none).
        held_from: first index from which every iterate reaches (None: the last one does not).
        lowest_altitude: lowest judged altitude over all iterates, m.
        below_floor: iterates whose judged altitude is below :func:`altitude_floor` (h_min).
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


def _check(plant, h_min, oracle_tension_kn) -> None:
    if not isinstance(plant, PlantConfig):
        raise ValueError(f"judge: plant = {plant!r}: expected the PlantConfig the run flew")
    if not math.isfinite(h_min):
        raise ValueError(f"judge: h_min = {h_min!r}: expected the run's altitude floor in m (finite)")
    if not (math.isfinite(oracle_tension_kn) and oracle_tension_kn > 0):
        raise ValueError(f"judge: oracle_tension_kn = {oracle_tension_kn!r}: expected the oracle's mean tension in "
                         "kN (> 0)")


def judge_point(plant: PlantConfig, h_min: float, oracle_tension_kn: float, c) -> Judged:
    """Setpoints ``c`` (rad) flown on ``plant``'s deterministic twin, judged against ``oracle_tension_kn`` (kN)
    and the floor of ``h_min`` (m)."""
    _check(plant, h_min, oracle_tension_kn)
    tension, z = plant_performance(plant, c)
    above = bool(z >= altitude_floor(h_min))
    return Judged(tension_kn=float(tension), min_altitude=float(z), percent=100.0 * tension / oracle_tension_kn,
                  above_floor=above, reached=bool(above and tension >= REACH_FRACTION * oracle_tension_kn))


def reaches(plant: PlantConfig, h_min: float, oracle_tension_kn: float, c) -> bool:
    """True if setpoints ``c`` (rad) reach the target (:func:`judge_point`): the baselines' stop."""
    return judge_point(plant, h_min, oracle_tension_kn, c).reached


def judge(plant: PlantConfig, h_min: float, oracle_tension_kn: float, iterates, times) -> Verdict:
    """Re-fly ``iterates`` (setpoints rad, (n, 3)) available at flight ``times`` (s) on ``plant``'s deterministic
    twin and judge them against ``oracle_tension_kn`` (kN) and the floor of ``h_min`` (m)."""
    iterates = np.atleast_2d(np.asarray(iterates, dtype=float))
    times = np.asarray(times, dtype=float)
    if len(times) != len(iterates):
        raise ValueError(f"judge: {len(iterates)} iterates but {len(times)} times: expected one time per iterate")
    points = [judge_point(plant, h_min, oracle_tension_kn, c) for c in iterates]
    reached = tuple(p.reached for p in points)
    k = next((i for i, r in enumerate(reached) if r), None)
    held = next((j for j in range(len(reached)) if all(reached[j:])), None)
    return Verdict(tension_kn=tuple(p.tension_kn for p in points), min_altitude=tuple(p.min_altitude for p in points),
                   percent=tuple(p.percent for p in points), reached=reached, reach_index=k,
                   reach_time=float(times[k]) if k is not None else math.inf, held_from=held,
                   lowest_altitude=float(min(p.min_altitude for p in points)),
                   below_floor=sum(not p.above_floor for p in points))


def judge_flight(plant: PlantConfig, h_min: float, oracle_tension_kn: float, history) -> FlightYield:
    """The yield of a GMA run's whole flight (:mod:`~kite_rto.rto.flight_yield`): every experiment of ``history``
    (requests in shape coordinates) judged on ``plant``'s deterministic twin in its (stationary) mean wind, over
    the oracle's ``oracle_tension_kn`` (kN), with the time flown below the floor of ``h_min`` (m)."""
    _check(plant, h_min, oracle_tension_kn)
    return flight_yield(segments_of_history(history, setpoints_from_shape),
                        judge=lambda c, t: plant_performance(plant, c), oracle=lambda t: oracle_tension_kn,
                        floor=altitude_floor(h_min))
