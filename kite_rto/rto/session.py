"""The per-sample RTO logic shared by the pure runner and the ROS optimizer node: :class:`RTOSession`.

``session.start(t)`` gives the first setpoints, then ``session.on_measurement(m)`` for every plant measurement
returns new setpoints to apply (or None). It feeds an :class:`~kite_rto.rto.experiment.ExperimentEvaluator`,
repeats crashed experiments and calls GMA's ``next_request`` / ``submit``. GMA works in shape coordinates; the
session hands out setpoints ``c = (theta_0, A_phi, A_theta)``, rad.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..gma import GMA, ExperimentResult
from ..flight.shape import setpoints_from_shape
from .experiment import ExperimentEvaluator, ExperimentOutcome, ExperimentSpec

__all__ = ["RTOSession", "ExperimentLog"]


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
        gma: a :class:`GMA` (e.g. from :func:`~kite_rto.rto.builder.make_gma`).
        spec: the :class:`ExperimentSpec` of every experiment.
        max_repeats: repetitions of an invalid experiment (crash, no lap) before giving up on it.

    Attributes:
        message: why the session stopped ("" while it runs); see :meth:`stop`.
    """

    def __init__(self, gma: GMA, spec: ExperimentSpec | None = None, max_repeats: int = 3):
        self.gma = gma
        self.spec = spec or ExperimentSpec()
        self.evaluator = ExperimentEvaluator(self.spec)
        self.max_repeats = int(max_repeats)
        self.request = None
        self.repeats = 0
        self.experiments: list[ExperimentLog] = []
        self.record_times: list[float] = []   # flight time (s) at which each IterationRecord completed
        self.message = ""

    @property
    def records(self):
        return self.gma.records

    @property
    def stopped(self) -> bool:
        """True once the session had to stop (:attr:`message` says why); it then ignores measurements."""
        return bool(self.message)

    def stop(self, reason: str) -> None:
        """Stop the session for ``reason`` (non-empty text)."""
        if not reason:
            raise ValueError("RTOSession.stop: expected a non-empty reason")
        self.message = reason

    @property
    def c(self) -> np.ndarray | None:
        """Setpoints ``(theta_0, A_phi, A_theta)`` of the experiment in progress (rad)."""
        return None if self.request is None else setpoints_from_shape(self.request.c)

    def start(self, t: float) -> np.ndarray:
        """Begin (or resume) with GMA's next request at time ``t`` s; returns the setpoints to apply."""
        self.request = self.gma.next_request()
        self.repeats = 0
        self.restart(t)
        return self.c

    def restart(self, t: float) -> None:
        """Measure the open request's experiment again from time ``t`` s (same setpoints and laps; the data so far
        is discarded): after a crash, a plant restart or setpoints that were held."""
        self.evaluator.start(t, self.c, self._laps())

    def _laps(self) -> int | None:
        """Laps the open request averages: the spec's ``n_laps`` times the request's effort
        (``GMASettings.effort_schedule``), rounded, at least 1; None without a request."""
        if self.request is None:
            return None
        return max(1, int(round(self.spec.n_laps * self.request.effort)))

    def on_measurement(self, m) -> np.ndarray | None:
        """Feed one plant measurement; returns new setpoints (rad, (3,)) when they must change, else None.

        A crashed experiment is repeated (the same setpoints are returned again, restarting the settling).
        """
        if self.request is None or self.stopped:
            return None
        out = self.evaluator.update(m)
        if out is None:
            return None
        if not out.valid and self.repeats < self.max_repeats:
            self.repeats += 1
            self.restart(m.t)
            return self.c
        if not out.valid:
            self.stop(f"experiment {self.request.request_id} invalid after {self.repeats} repeats")
            return None
        self.experiments.append(ExperimentLog(self.request.request_id, self.c, out, self.repeats))
        rec = self.gma.submit(_result(self.request.request_id, out))
        if rec is not None:
            self.record_times.append(float(m.t))
        return self.start(m.t)
