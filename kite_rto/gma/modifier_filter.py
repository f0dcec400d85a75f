"""Filters of the gradient modifiers: a fixed first-order filter and a gain matched to the gradient noise.

:class:`ModifierFilter`: ``lambda_k = (1 - b) lambda_{k-1} + b lambda_k^measured`` (``mu`` likewise) averages noisy
plant-gradient estimates over about ``2 / b - 1`` iterations (Marchetti et al. 2009); ``eps_k`` is never filtered.
:class:`NoiseFilter` replaces ``b`` by a Kalman gain per setpoint from the estimates' standard deviations and the
modifier's drift over the steps (:mod:`~kite_rto.gma.noise_filter`), wherever the estimates carry a standard
deviation; elsewhere the fixed filter (or none) applies. Both set ``it.modifier_std``, the filtered cost modifier's
standard deviation, which :mod:`~kite_rto.gma.bound_hold` compares the descent into the box with. Measured on the
kite, whose experiments scatter as much as the cost differences near the optimum: without a filter half the runs
ended below 99 % of the optimum, and the noise-matched gain ended more runs above it than the fixed one
(docs/history.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._checks import Scalar, check_range, per_setpoint
from .mechanism import Iteration, Mechanism
from .noise_filter import noise_gain

__all__ = ["ModifierFilter", "NoiseFilter"]


@dataclass(frozen=True)
class ModifierFilter:
    """Settings of the fixed modifier filter.

    Attributes:
        gain: ``b`` in ``(0, 1]``; 1 takes each measurement as it is.
    """

    gain: float = 0.5

    def __post_init__(self):
        check_range(type(self).__name__, "gain", self.gain, 0.0, 1.0, low_open=True)


@dataclass(frozen=True)
class NoiseFilter:
    """Settings of the filter matched to the gradient noise (needs the estimates' ``cost_std``).

    Attributes:
        drift: ``q >= 0``, a bound on the plant-model curvature mismatch, cost units per squared box width: the
            filtered modifier's variance grows by ``(q |step / w|)^2`` per step, so long steps forget the past.
        constraint_drift: ``None``: the constraints' modifiers ``mu`` take the cost's gain. A number ``q_g >= 0``
            (scalar or one per constraint) gives each constraint a gain of its own from its own noise (the
            gradient's standard deviation times the constraint's measured standard deviation over the cost's) and
            drift bound, constraint units per squared box width: a constraint measured more precisely than the
            cost then follows its measurements.
    """

    drift: float = 5.0
    constraint_drift: Scalar | None = None

    def __post_init__(self):
        check_range(type(self).__name__, "drift", self.drift, 0.0, None)
        if self.constraint_drift is not None:
            check_range(type(self).__name__, "constraint_drift", self.constraint_drift, 0.0, None)


def build_filters(fixed: ModifierFilter | None, noise: NoiseFilter | None, problem) -> "FilterMechanism | None":
    """The mechanism of the two settings, or ``None`` when both are off."""
    if fixed is None and noise is None:
        return None
    return FilterMechanism(1.0 if fixed is None else fixed.gain, noise, problem)


def _finite_modifiers(record) -> bool:
    return bool(np.all(np.isfinite(record.lam)) and np.all(np.isfinite(record.mu)))


class FilterMechanism(Mechanism):
    """Filters ``it.modifiers`` against the last record with finite modifiers (module docstring)."""

    def __init__(self, gain: float, noise: NoiseFilter | None, problem):
        self.gain, self.noise, self.problem = gain, noise, problem

    def modify(self, it: Iteration) -> None:
        b, mods, est = self.gain, it.modifiers, it.estimate
        if b == 1.0 and self.noise is None:
            return
        prev = next((r for r in reversed(it.history.iterations) if _finite_modifiers(r)), None)
        if prev is None or not (np.all(np.isfinite(mods.lam)) and np.all(np.isfinite(mods.mu))):
            return
        own_std = it.modifier_std
        it.modifier_std = own_std * np.sqrt(b / (2.0 - b))     # the fixed filter's stationary std
        chain = self._chain(it)
        b_mu = None
        if chain is not None:
            b, P = noise_gain(*chain, self.noise.drift, it.width)
            it.modifier_std = np.sqrt(P)
            it.notes.append(f"modifiers filtered by noise (gain {np.round(b, 3).tolist()})")
            b_mu = self._constraint_gains(it, chain)
            if b_mu is not None:
                it.notes.append(f"constraint modifiers filtered by their own noise (gain "
                                f"{np.round(b_mu, 3).tolist()})")
        else:
            it.notes.append(f"modifiers filtered (b = {b:g})")
        mods.lam = (1.0 - b) * prev.lam + b * mods.lam
        b_mu = b if b_mu is None else b_mu
        mods.mu = (1.0 - b_mu) * prev.mu.reshape(mods.mu.shape) + b_mu * mods.mu

    def _chain(self, it: Iteration):
        """``(points, stds)``: the iterations since the last one without finite modifiers or a standard deviation,
        then this one; ``None`` without the noise filter or without this estimate's standard deviation."""
        est = it.estimate
        if self.noise is None or est.cost_std is None:
            return None
        points, stds = [it.c_k], [np.asarray(est.cost_std, float)]
        for r in reversed(it.history.iterations):
            if r.grad_cost_std is None or not _finite_modifiers(r):
                break
            points.insert(0, r.c_k)
            stds.insert(0, np.asarray(r.grad_cost_std, float))
        return points, stds

    def _constraint_gains(self, it: Iteration, chain) -> np.ndarray | None:
        """(n_g, n_c) the constraints' own gains (``NoiseFilter.constraint_drift``), ``None`` when off or when some
        iteration of the chain lacks the standard deviations."""
        pr, drift = self.problem, self.noise.constraint_drift
        if drift is None or not pr.n_g:
            return None
        points, cost_stds = chain
        recs = it.history.iterations[len(it.history.iterations) - (len(points) - 1):]
        nominals = [it.nominal_result(r) for r in recs] + [it.nominal]
        ratios = []
        for pt in nominals:
            if pt is None or not pt.cost_std or pt.constraints_std is None:
                return None
            ratios.append(np.asarray(pt.constraints_std, float).reshape(pr.n_g) / pt.cost_std)
        drift = per_setpoint("NoiseFilter.constraint_drift", drift, pr.n_g)
        gains = [noise_gain(points, [sd * r[j] for sd, r in zip(cost_stds, ratios)], drift[j], it.width)[0]
                 for j in range(pr.n_g)]
        return np.array(gains).reshape(pr.n_g, pr.n_c)
