"""One campaign result per scenario x seed x method (:class:`RunResult`) and the results table (:func:`write_table`).

The table is sorted by the campaign's order (scenario, seed, method) and holds no wall time, so two runs of the
same campaign give the same bytes; each row names the code version its run was computed with (a cached run keeps
its own); wall seconds go to a separate file (:func:`write_wall_times`). Floats are
rounded (percentages to 1e-3, metres and seconds to 1e-2) and lists are JSON-encoded in their cells. A judged
crash has no altitude: None in the lists, an empty cell.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict, dataclass, fields

from ..rto.judge import Verdict

__all__ = ["RunResult", "TABLE_COLUMNS", "OPTIONAL_COLUMNS", "write_table", "write_wall_times"]


def _r(v, digits: int):
    return None if v is None or not math.isfinite(v) else round(float(v), digits)


@dataclass(frozen=True)
class RunResult:
    """One run, judged on the scenario's deterministic plant against its oracle.

    Attributes:
        scenario, tuning, h_min: the scenario's name, tuning flag and altitude floor (m).
        seed: plant seed.
        method: ``gma`` (or a GMA variant's name) or a baseline.
        reach_index: first iterate (GMA: 0 = the model optimum) judged >= 99 % of the oracle above the floor;
            None if none is.
        t99_s: flight time (s) at which that iterate became available; None if none is.
        held_from: first index from which every iterate reaches; None if the last one does not.
        times_s: flight time (s) at which each iterate became available.
        percent: judged mean tension of each iterate, % of the oracle.
        altitude: judged minimum altitude of each iterate, m (None: the judged flight crashed).
        final_percent: ``percent`` of the last iterate.
        lowest_altitude: lowest of ``altitude``, m (None: a judged flight crashed).
        below_floor: iterates judged below h_min - 2 m (crashes included).
        flight_time_s, experiments, crashes: what the method flew.
        budget_s: a baseline's flight-time budget, s (None for GMA).
        oracle_kn: the scenario's oracle mean tension, kN.
        message: why the run stopped early ("" if it did not).
        code_version: the :func:`~kite_rto.campaign.version.code_version` the run was computed with.
        wall_s: wall time of the run on its worker, s (not in the table).
        yield_percent: a campaign of fixed flights: the yield of the whole flight
            (:mod:`~kite_rto.rto.flight_yield`), % of the oracle's energy; None otherwise.
        below_floor_s: the same: flight time on setpoints judged below h_min - 2 m, s; None otherwise.
    """

    scenario: str
    tuning: bool
    h_min: float
    seed: int
    method: str
    reach_index: int | None
    t99_s: float | None
    held_from: int | None
    times_s: tuple
    percent: tuple
    altitude: tuple
    final_percent: float
    lowest_altitude: float | None
    below_floor: int
    flight_time_s: float
    experiments: int
    crashes: int
    budget_s: float | None
    oracle_kn: float
    message: str
    code_version: str
    wall_s: float
    yield_percent: float | None = None
    below_floor_s: float | None = None

    @classmethod
    def judged(cls, scenario, seed: int, method: str, flown, verdict: Verdict, oracle_kn: float,
               budget_s: float | None, code: str, wall_s: float, flight=None) -> "RunResult":
        """The result of ``flown`` (:class:`~kite_rto.campaign.methods.Flown`) on ``scenario`` given its
        :class:`Verdict`, computed with code version ``code``; ``flight``: its
        :class:`~kite_rto.rto.flight_yield.FlightYield` (a campaign of fixed flights) or None."""
        return cls(scenario=scenario.name, tuning=scenario.tuning, h_min=float(scenario.h_min), seed=int(seed),
                   method=method, reach_index=verdict.reach_index,
                   t99_s=_r(verdict.reach_time, 2), held_from=verdict.held_from,
                   times_s=tuple(_r(t, 2) for t in flown.times), percent=tuple(_r(p, 3) for p in verdict.percent),
                   altitude=tuple(_r(z, 2) for z in verdict.min_altitude),
                   final_percent=_r(verdict.percent[-1], 3), lowest_altitude=_r(verdict.lowest_altitude, 2),
                   below_floor=int(verdict.below_floor), flight_time_s=_r(flown.flight_time, 2),
                   experiments=int(flown.experiments), crashes=int(flown.crashes),
                   budget_s=_r(budget_s, 2), oracle_kn=_r(oracle_kn, 3),
                   message=flown.message, code_version=code, wall_s=round(float(wall_s), 2),
                   yield_percent=None if flight is None else _r(flight.percent, 3),
                   below_floor_s=None if flight is None else _r(flight.below_floor_s, 2))

    def to_dict(self) -> dict:
        """Plain JSON-serializable values (tuples as lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict) -> "RunResult":
        names = {f.name for f in fields(cls)}
        d = {**{k: None for k in OPTIONAL_COLUMNS}, **d}
        if set(d) != names:
            raise ValueError(f"RunResult.from_dict: fields {sorted(set(d) ^ names)} differ from {sorted(names)}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})


OPTIONAL_COLUMNS = ("yield_percent", "below_floor_s")
"""Columns a table of a campaign without fixed flights may lack (they are None there)."""
TABLE_COLUMNS = tuple(f.name for f in fields(RunResult) if f.name != "wall_s")
"""The results table's columns, in order (every :class:`RunResult` field but ``wall_s``)."""


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, tuple):
        return json.dumps(list(v))
    return str(v)


def write_table(path, results) -> None:
    """Write ``results`` (:class:`RunResult`, already in campaign order) as CSV with :data:`TABLE_COLUMNS` (without
    :data:`OPTIONAL_COLUMNS` when no result has them: a campaign without fixed flights writes the table it always
    wrote)."""
    yields = any(getattr(r, c) is not None for r in results for c in OPTIONAL_COLUMNS)
    columns = TABLE_COLUMNS if yields else tuple(c for c in TABLE_COLUMNS if c not in OPTIONAL_COLUMNS)
    with open(path, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(columns)
        for r in results:
            w.writerow([_cell(getattr(r, c)) for c in columns])


def write_wall_times(path, results) -> None:
    """Write scenario, seed, method and wall seconds of each result as CSV."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(("scenario", "seed", "method", "wall_s"))
        for r in results:
            w.writerow((r.scenario, r.seed, r.method, f"{r.wall_s:.2f}"))
