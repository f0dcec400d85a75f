"""Learning only while it pays: at a settled point GMA stops perturbing and watches; a change makes it learn again.

Every perturbation experiment is flown away from the best known point: while the iterate moves, that is the price of
its gradient; at a point where it has settled, perturbing on for ever costs the same every iteration and buys
nothing while the plant stays the same. :class:`Settle` therefore divides a run into two phases:

* **learning** (GMA as configured): after ``after`` consecutive iterations whose step stayed below ``step`` box
  widths in every setpoint, the point counts as settled;
* **watching**: each iteration flies the nominal point alone (no perturbation, no modifier update, no step:
  :attr:`~kite_rto.gma.Decision.WATCHED`). The first ``after`` measurements make the reference (their mean; a
  measurement's standard deviation from the results' ``cost_std`` and ``constraints_std``, pooled, or without them
  the spread of the reference values); every later one is tested for a change with Page's two-sided CUSUM (Page
  1954, "Continuous inspection schemes", Biometrika 41): with ``z`` the measurement standardized against the
  reference, ``S+ = max(0, S+ + z - drift)`` and ``S- = max(0, S- - z - drift)``; a sum above ``threshold`` is a
  change (for the constraints only a rise, towards violation, counts). A change ends the watch: the next
  iteration learns again, at the settled point, with perturbations, and the mechanisms forget what they learned
  before it (:mod:`~kite_rto.gma.mechanism`).

The CUSUM's defaults are the textbook ones (``drift`` 0.5 and ``threshold`` 4 standard deviations: a shift of
one standard deviation is detected after about 8 measurements, while an unchanged plant raises a false alarm about
once in 170).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._checks import check_int, check_range
from .mechanism import Iteration, Mechanism
from .modifiers import Decision

__all__ = ["Settle", "SettleMechanism"]


@dataclass(frozen=True)
class Settle:
    """Settings of the settled-point watch (module docstring).

    Attributes:
        step: largest step that counts as calm, box widths per setpoint, ``> 0``.
        after: consecutive calm iterations that settle the point, ``>= 1``.
        drift: the CUSUM's allowance ``k``, standard deviations, ``>= 0``.
        threshold: the CUSUM's decision limit ``h``, standard deviations, ``> 0``.
    """

    step: float = 0.02
    after: int = 2
    drift: float = 0.5
    threshold: float = 4.0

    def __post_init__(self):
        n = type(self).__name__
        check_range(n, "step", self.step, 0.0, None, low_open=True)
        check_int(n, "after", self.after, 1)
        check_range(n, "drift", self.drift, 0.0, None)
        check_range(n, "threshold", self.threshold, 0.0, None, low_open=True)

    def build(self, problem) -> "SettleMechanism":
        return SettleMechanism(self, problem.c_width)


class SettleMechanism(Mechanism):
    """The learning/watching state machine of :class:`Settle`; restored from the records on resume."""

    def __init__(self, settings: Settle, width):
        self.settings = settings
        self.width = np.asarray(width, float)
        self._reset()

    def _reset(self) -> None:
        self.watching = False
        self._calm = 0                     # consecutive calm learning iterations
        self._reference: list = []         # the settled point's first measurements: (values, standard errors)
        self._ref = None                   # (mean, its standard error, one measurement's), cost then constraints
        self._up = self._down = None       # CUSUM sums per watched quantity

    # -------------------------------------------------------------------- hooks
    def perturb(self) -> bool | None:
        """False while watching: the next iteration flies the nominal point alone."""
        return False if self.watching else None

    def adapt(self, it: Iteration) -> None:
        self._learned(it.step, it.decision)

    def watch(self, nominal) -> str:
        """A watched nominal measurement (a :class:`~kite_rto.gma.PlantPoint`); returns ``""`` while the point
        holds, else why learning starts again."""
        s = self.settings
        x, sx = _values(nominal)
        if self._ref is None:                  # the reference: the first measurements of the settled point
            self._reference.append((x, sx))
            if len(self._reference) == s.after:
                self._ref = _reference(self._reference)
                self._up = np.zeros(x.size)
                self._down = np.zeros(x.size)
            return ""
        mean, se, spread = self._ref
        sd = np.where(np.isfinite(sx), sx, spread)
        z = (x - mean) / np.sqrt(np.maximum(sd ** 2 + se ** 2, 1e-300))
        self._up = np.maximum(0.0, self._up + z - s.drift)
        self._down = np.maximum(0.0, self._down - z - s.drift)
        self._down[1:] = 0.0                                    # a constraint that falls is a safer plant
        names = ["cost"] + [f"g[{i}]" for i in range(x.size - 1)]
        why = [f"{names[i]} {'rose' if self._up[i] > s.threshold else 'fell'} (CUSUM "
               f"{max(self._up[i], self._down[i]):.3g} > {s.threshold:g})"
               for i in range(x.size) if max(self._up[i], self._down[i]) > s.threshold]
        if why:
            self._reset()
            return "; ".join(why)
        return ""

    def resume(self, history) -> None:
        self._reset()
        results = {q.request_id: r for q, r in history.experiments}
        for rec in history.iterations:
            res = results.get(rec.experiment_ids[0]) if rec.experiment_ids else None
            if res is None:
                continue
            if rec.outcome is Decision.WATCHED:
                self.watch(res)                 # an ExperimentResult: cost, constraints and their std as watched
            else:
                self._learned(rec.step, rec.outcome)

    # ------------------------------------------------------------------ private
    def _learned(self, step, decision) -> None:
        if self.watching:
            return
        calm = decision is not None and decision.moved and bool(np.all(np.abs(step) <= self.settings.step * self.width))
        self._calm = self._calm + 1 if calm else 0
        if self._calm >= self.settings.after:
            self.watching = True


def _reference(measured) -> tuple:
    """``(mean, its standard error, one measurement's standard deviation)`` per quantity from ``measured``, a list
    of ``(values, standard errors)``: the standard errors pooled where every measurement has one, else the spread
    of the values."""
    v = np.array([m[0] for m in measured])
    sds = np.array([m[1] for m in measured])
    spread = v.std(axis=0, ddof=1) if len(v) > 1 else np.zeros(v.shape[1])
    known = np.isfinite(sds).all(axis=0)
    per = np.where(known, np.sqrt(np.mean(np.where(np.isfinite(sds), sds, 0.0) ** 2, axis=0)), spread)
    return v.mean(axis=0), per / math.sqrt(len(v)), per


def _values(point) -> tuple:
    """``(values, standard errors)`` of a nominal measurement (a :class:`~kite_rto.gma.PlantPoint` or an
    :class:`~kite_rto.gma.ExperimentResult`): cost then constraints (NaN where unknown)."""
    g = np.atleast_1d(np.asarray(point.constraints, float))
    x = np.r_[float(point.cost), g]
    sc = math.nan if point.cost_std is None else float(point.cost_std)
    sg = np.full(g.size, np.nan) if point.constraints_std is None else np.atleast_1d(np.asarray(point.constraints_std,
                                                                                                  float))
    return x, np.r_[sc, sg]
