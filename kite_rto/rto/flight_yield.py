"""The yield of a flight: the energy of the whole flight, learning included, against what the best setpoints give.

An operator flies for hours; what counts is the line's energy over the whole flight, every experiment included,
not where the last iterate ends. The **yield** of a flight (SPEC §4) is

    Y = ∫ T_det(c(t), t) dt / ∫ T_opt(t) dt

over the flight, with ``c(t)`` the setpoints being flown at time ``t``, ``T_det(c, t)`` the mean tension the plant's
deterministic twin gives for ``c`` in the mean wind of that moment, and ``T_opt(t)`` the oracle's in that wind.
Beside it: the flight time spent on setpoints whose judged minimum altitude is below the floor.

The timeline is a list of :class:`Segment` s (setpoints held from ``t_start`` to ``t_end``); each is integrated
in sub-intervals of at most ``resolution`` s (one evaluation at each sub-interval's midpoint), so a judge whose
answer changes with time (a drifting mean wind) is followed, and a stationary one is asked once per segment.
The judge and the oracle are callables: this module knows nothing of kites. :func:`segments_of_history` reads a
GMA history's experiments as a timeline.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

__all__ = ["Segment", "SegmentYield", "FlightYield", "flight_yield", "segments_of_history"]


@dataclass(frozen=True)
class Segment:
    """Setpoints ``c`` held from ``t_start`` to ``t_end`` (s); ``purpose`` says why (e.g. ``"nominal"``)."""

    t_start: float
    t_end: float
    c: tuple
    purpose: str = ""

    def __post_init__(self):
        if not (math.isfinite(self.t_start) and math.isfinite(self.t_end) and self.t_end >= self.t_start):
            raise ValueError(f"Segment: t_start = {self.t_start!r}, t_end = {self.t_end!r}: expected finite times "
                             "with t_end >= t_start (s)")

    @property
    def duration(self) -> float:
        """s."""
        return self.t_end - self.t_start


@dataclass(frozen=True)
class SegmentYield:
    """One segment, judged: its ``energy`` and the oracle's (tension x time, kN s = kJ), and ``below_floor_s``."""

    segment: Segment
    energy: float
    oracle_energy: float
    below_floor_s: float

    @property
    def percent(self) -> float:
        """The segment's yield, % (NaN for an empty segment)."""
        return 100.0 * self.energy / self.oracle_energy if self.oracle_energy > 0 else math.nan


@dataclass(frozen=True)
class FlightYield:
    """The yield of a flight.

    Attributes:
        percent: 100 x the flight's energy over the oracle's in the same winds, %.
        flight_time: s covered by the segments.
        energy: ∫ T_det dt, kN s (= kJ).
        oracle_energy: ∫ T_opt dt, kN s.
        below_floor_s: s flown on setpoints whose judged minimum altitude is below the floor (the whole segment
            counts).
        by_purpose: ``{purpose: (flight time s, yield %)}``, e.g. how much the perturbations cost.
        segments: the per-segment :class:`SegmentYield` s.
    """

    percent: float
    flight_time: float
    energy: float
    oracle_energy: float
    below_floor_s: float
    by_purpose: dict
    segments: tuple

    def summary(self) -> dict:
        """The scalars and ``by_purpose``, JSON-ready."""
        return {"yield_percent": self.percent, "flight_time_s": self.flight_time, "energy_MJ": self.energy / 1e3,
                "oracle_energy_MJ": self.oracle_energy / 1e3, "below_floor_s": self.below_floor_s,
                "by_purpose": {k: {"flight_time_s": t, "yield_percent": p} for k, (t, p) in self.by_purpose.items()}}


def flight_yield(segments: Sequence[Segment], judge: Callable, oracle: Callable, floor: float,
                 resolution: float = math.inf) -> FlightYield:
    """Integrate the judged tension and the oracle's over ``segments``.

    Args:
        segments: the flight's timeline (:class:`Segment` s; gaps between them are not counted).
        judge: ``judge(c, t) -> (tension kN, min altitude m)`` of setpoints ``c`` in the conditions at time ``t`` s.
        oracle: ``oracle(t) -> tension kN`` of the best setpoints in the conditions at time ``t`` (> 0).
        floor: lowest acceptable judged minimum altitude, m.
        resolution: longest sub-interval integrated with one evaluation, s (> 0; inf: one per segment, for
            conditions that do not change).
    """
    if not resolution > 0:
        raise ValueError(f"flight_yield: resolution = {resolution!r}: expected > 0 s")
    rows = []
    for seg in segments:
        n = 1 if not math.isfinite(resolution) else max(1, math.ceil(seg.duration / resolution - 1e-9))
        edges = np.linspace(seg.t_start, seg.t_end, n + 1)
        energy = oracle_energy = below = 0.0
        for a, b in zip(edges[:-1], edges[1:]):
            t = 0.5 * (a + b)
            tension, z = judge(seg.c, t)
            best = oracle(t)
            if not (math.isfinite(best) and best > 0):
                raise ValueError(f"flight_yield: oracle({t:g}) = {best!r}: expected a tension > 0 kN")
            energy += tension * (b - a)
            oracle_energy += best * (b - a)
            below += (b - a) if not z >= floor else 0.0
        rows.append(SegmentYield(seg, energy, oracle_energy, below))
    total = sum(r.energy for r in rows)
    best = sum(r.oracle_energy for r in rows)
    by_purpose = {}
    for purpose in dict.fromkeys(r.segment.purpose for r in rows):
        part = [r for r in rows if r.segment.purpose == purpose]
        e, o = sum(r.energy for r in part), sum(r.oracle_energy for r in part)
        by_purpose[purpose] = (sum(r.segment.duration for r in part), 100.0 * e / o if o > 0 else math.nan)
    return FlightYield(percent=100.0 * total / best if best > 0 else math.nan,
                       flight_time=sum(r.segment.duration for r in rows), energy=total, oracle_energy=best,
                       below_floor_s=sum(r.below_floor_s for r in rows), by_purpose=by_purpose, segments=tuple(rows))


def segments_of_history(history, to_setpoints: Callable = tuple) -> list[Segment]:
    """The timeline of a GMA history's experiments (:class:`~kite_rto.gma.History`), in submission order.

    Each experiment's result carries ``t_start`` and ``t_end`` (s) in its ``extra``; a segment runs from the end
    of the one before (the first: from its own start) to its ``t_end``, so flight between two submitted
    experiments (a repeated, invalid attempt of the next one) counts with the setpoints of the next one, which
    were being flown. ``to_setpoints`` maps a request's ``c`` to the setpoints judged.
    """
    segments, t_prev = [], None
    for req, res in history.experiments:
        t0, t1 = res.extra.get("t_start"), res.extra.get("t_end")
        if t0 is None or t1 is None:
            raise ValueError(f"segments_of_history: experiment {req.request_id!r} has no t_start/t_end in its "
                             "result's extra: expected the flight times of every experiment")
        start = float(t0) if t_prev is None else t_prev
        segments.append(Segment(start, float(t1), tuple(map(float, to_setpoints(req.c))), req.purpose))
        t_prev = float(t1)
    return segments
