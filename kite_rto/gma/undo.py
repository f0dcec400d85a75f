"""Undoing a step the plant measured as a loss: a trust region that adapts to the plant's own measurements.

When the nominal cost measured at ``c_k`` exceeds the one measured at ``c_{k-1}`` by more than ``sigma`` standard
errors of their difference, ``c_{k-1}``'s measured constraints held (``g <= 0``) and GMA's own step led from
``c_{k-1}`` to ``c_k``, the step is undone: the next operating point is ``c_{k-1}`` and the trust region shrinks in
the setpoints that moved. The gradient measured at ``c_k`` still enters the modifiers; a step back is not tested in
turn. The standard error comes from the experiments' ``cost_std``, pooled over the run (a standard error from a
few samples is itself uncertain; the plant's noise is taken as stationary) and scaled by each experiment's effort.
Measured on the kite, together with longer experiments near the optimum: fewer iterates that leave a near-optimal
point on a noisy measurement (docs/history.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._checks import check_range
from .mechanism import Iteration, Mechanism
from .modifiers import Decision

__all__ = ["Undo", "pooled_cost_variance"]


@dataclass(frozen=True)
class Undo:
    """Settings of the measured step test.

    Attributes:
        sigma: standard errors of the measured cost difference beyond which a step is undone, ``>= 0``.
    """

    sigma: float = 1.0

    def __post_init__(self):
        check_range(type(self).__name__, "sigma", self.sigma, 0.0, None)

    def build(self, problem) -> "UndoMechanism":
        return UndoMechanism(self)


def pooled_cost_variance(experiments) -> float | None:
    """The variance of one experiment's cost at effort 1, pooled over ``experiments`` (``(request, result)``
    pairs): the mean of ``cost_std^2`` times the request's effort; ``None`` when no result carries a ``cost_std``."""
    v = [r.cost_std ** 2 * q.effort for q, r in experiments if r.cost_std is not None]
    return float(np.mean(v)) if v else None


class UndoMechanism(Mechanism):
    """Sets ``it.target`` to ``c_{k-1}`` when the measured step test fails (module docstring)."""

    def __init__(self, settings: Undo):
        self.settings = settings

    def revise(self, it: Iteration, shrink) -> None:
        recs = it.history.iterations
        if not recs:
            return
        prev = recs[-1]
        if prev.outcome is not Decision.STEP or not np.array_equal(prev.c_next, it.c_k) or np.any(prev.constraints > 0):
            return
        unit = pooled_cost_variance(it.history.experiments)
        if unit is None:
            return
        efforts = {q.request_id: q.effort for q, _ in it.history.experiments}
        before, now = efforts[prev.experiment_ids[0]], efforts[it.nominal_id]
        rise, z = it.nominal.cost - prev.cost, self.settings.sigma
        se = math.sqrt(unit / before + unit / now)
        if not rise > z * se:
            return
        it.notes.append(f"step undone: the cost measured at c_k is {rise:.4g} above c_(k-1)'s ({rise / se:.3g} "
                        f"standard errors of the difference, > {z:g})")
        it.target = np.asarray(prev.c_k, float).copy()
        shrink(it.target - it.c_k != 0)
