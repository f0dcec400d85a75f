"""When an experiment at fixed setpoints ends, from the flight alone: :class:`ExperimentEnd`.

An experiment ends at the first sample after its start at which the plant's crash count changed (crashed), the
``n_laps``-th whole lap after the settling is complete (complete), or ``max_duration`` s have passed (timed out).
Laps are :class:`~kite_rto.flight.laps.LapCrossing` laps of ``(t, phi)``; a lap counts once it starts at least
``settle_time`` s after the start, and the first ``settle_laps`` of those are dropped (SPEC §4).

The rule needs time, phi and the crash count only, no tension and no wind, so every process that sees the plant's
samples decides it identically: :class:`~kite_rto.rto.experiment.ExperimentEvaluator` ends its experiments with it,
and the controller of a synchronized graph knows with it where the optimizer's next decision is due
(:mod:`kite_rto.runtime.plan`).
"""
from __future__ import annotations

from ..flight.laps import LapCrossing, LapDetector

__all__ = ["ExperimentEnd", "CRASHED", "COMPLETE", "TIMED_OUT"]

CRASHED, COMPLETE, TIMED_OUT = "crashed", "complete", "timed out"
"""How an experiment ended (:meth:`ExperimentEnd.update`)."""


class ExperimentEnd:
    """The end rule of one experiment started at ``t_start`` s (see the module docstring).

    Args:
        t_start: s, the time of the sample at which the setpoints were applied.
        n_laps: whole laps averaged, >= 1.
        settle_time: s after the start before which no lap counts.
        settle_laps: counted laps dropped as the transient.
        max_duration: s after the start at which the experiment ends with what it has.
        crossing: the lap rule (default: :class:`~kite_rto.flight.laps.LapDetector`'s defaults); it is reset here.

    Attributes:
        kept: the last :meth:`update` completed a lap that the experiment averages.
        ended: how the experiment ended (one of :data:`CRASHED`, :data:`COMPLETE`, :data:`TIMED_OUT`), None before.
    """

    def __init__(self, t_start: float, n_laps: int, settle_time: float, settle_laps: int, max_duration: float,
                 crossing: LapCrossing | None = None):
        self.t_start, self.n_laps = float(t_start), int(n_laps)
        self.settle_time, self.settle_laps, self.max_duration = settle_time, int(settle_laps), max_duration
        self.crossing = crossing or LapDetector().crossing
        self.crossing.reset()
        self.kept = False
        self.ended = None
        self._crashes = None
        self._seen = 0
        self._n_kept = 0

    def update(self, t: float, phi: float, crashes: int) -> str | None:
        """Add the next sample after the start (t s, phi rad, the plant's crash count): how the experiment ended
        at this sample, or None while it goes on (and after it ended: :attr:`ended` says how)."""
        self.kept = False
        if self.ended is not None:
            return None
        if self._crashes is None:
            self._crashes = crashes
        elif crashes != self._crashes:
            self.ended = CRASHED
            return CRASHED
        lap = self.crossing.update(t, phi)
        if lap is not None and lap[0] >= self.t_start + self.settle_time:
            self._seen += 1
            if self._seen > self.settle_laps:
                self.kept = True
                self._n_kept += 1
                if self._n_kept >= self.n_laps:
                    self.ended = COMPLETE
                    return COMPLETE
        if t - self.t_start >= self.max_duration:
            self.ended = TIMED_OUT
            return TIMED_OUT
        return None
