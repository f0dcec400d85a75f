"""Constraint modifiers from the model's own differences over the plant's perturbations (:class:`ModelSecant`).

A difference quotient over a step ``h`` measures the plant's *secant*, not its gradient: for forward differences
the error is ``f'' h / 2``. With steps large enough to beat the measurement noise (half a box width on the kite)
that error is of the size of the gradients near the optimum, and GMA's fixed point, where the modified gradient
``grad phi_hat + (secant_p - grad phi_hat)`` vanishes, is where the plant's *secant* vanishes: half a step from the
plant optimum.

The model is cheap to evaluate at the same points. With :class:`ModelSecant` on, GMA runs the same gradient
estimator on the model's values at the very setpoints the plant flew (the nominal point and the points the
estimator uses) and takes the difference as the constraints' gradient modifier:

    mu = secant_p - secant_hat,       grad g_p (estimated) = grad g_hat + secant_p - secant_hat

The truncation errors cancel up to the plant-model *curvature mismatch*, ``(g''_p - g''_hat) h / 2``, so large
steps keep their low noise without their bias. The cost keeps the plant's quotients (correcting it too, and only
near a settled point, were measured and lost: docs/history.md). Measured on the kite, whose model constraint is
the reference path's geometry: fewer iterates below the altitude floor after a long step. Costs one model solve
per point used (:class:`ModelPoint` solves lazily: a past point the estimator only looks at is never solved).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from .gradients import GradientEstimate, GradientEstimator, PlantPoint
from .mechanism import Iteration, Mechanism

__all__ = ["ModelSecant", "ModelPoint", "model_secant_estimate"]


@dataclass(frozen=True)
class ModelSecant:
    """Settings of the model-secant correction of the constraints' gradient modifiers (no parameters: on or off)."""

    def build(self, problem) -> "ModelSecantMechanism":
        return ModelSecantMechanism()


class ModelPoint:
    """A plant point's setpoints with the model's values there, solved on first access of ``cost`` or
    ``constraints`` (duck-types :class:`~kite_rto.gma.PlantPoint`; the standard deviations are the plant
    point's, so an estimator weighs model and plant points alike).

    Args:
        point: the plant point (its ``c`` and standard deviations are kept).
        evaluate: ``c -> (phi_hat, g_hat (n_g,))``, NaN where the model cannot realize ``c``.
    """

    def __init__(self, point: PlantPoint, evaluate: Callable[[np.ndarray], tuple]):
        self.c = np.asarray(point.c, float)
        self.cost_std = point.cost_std
        self.constraints_std = point.constraints_std
        self._evaluate = evaluate
        self._values = None

    def _solve(self) -> tuple:
        if self._values is None:
            phi, g = self._evaluate(self.c)
            self._values = (float(phi), np.asarray(g, float).ravel())
        return self._values

    @property
    def cost(self) -> float:
        """``phi_hat(c)``, cost units."""
        return self._solve()[0]

    @property
    def constraints(self) -> np.ndarray:
        """``g_hat(c)`` (n_g,), constraint units."""
        return self._solve()[1]


def model_secant_estimate(estimator: GradientEstimator, plant: GradientEstimate, c_k, nominal: PlantPoint,
                          new: Sequence[PlantPoint], past: Sequence[PlantPoint], model,
                          evaluate: Callable[[np.ndarray], tuple]) -> tuple:
    """The plant estimate ``plant`` with its constraints' Jacobian corrected by the model's truncation error
    (module docstring).

    Args:
        estimator: the strategy that produced ``plant`` from ``nominal``, ``new`` and ``past``.
        plant: its estimate from the plant's measurements.
        c_k: the operating point (n_c,).
        nominal, new, past: the plant points ``plant`` came from.
        model: the model's linearization at ``c_k`` (:class:`~kite_rto.gma.ModelRealization`: ``grad_phi``,
            ``jac_g``).
        evaluate: ``c -> (phi_hat, g_hat)`` of the model (NaN where it cannot realize ``c``).

    Returns ``(estimate, note)``: ``plant`` with ``grad g_hat + secant_p - secant_hat`` for the constraints, the
    same cost gradient, quality and standard deviations; ``plant`` itself when the model's secant is not finite
    (the note says so).
    """
    def as_model(p):
        return ModelPoint(p, evaluate)

    own = estimator.estimate(c_k, as_model(nominal), [as_model(p) for p in new], [as_model(p) for p in past],
                             model)
    n_c = np.size(c_k)
    j_g = np.asarray(model.jac_g, float).reshape(-1, n_c)
    grad = np.asarray(plant.cost, float)
    cons = plant.constraints.reshape(j_g.shape) - own.constraints.reshape(j_g.shape) + j_g
    if not (np.all(np.isfinite(grad)) and np.all(np.isfinite(cons))):
        return plant, "model secant not finite: the plant's difference quotients used as they are"
    note = (f"model secant: truncation correction on the constraints only, "
            f"{np.round(j_g - own.constraints.reshape(j_g.shape), 6).tolist()}")
    return (GradientEstimate(grad, cons, plant.quality, plant.cost_std, plant.method, plant.notes,
                             plant.displacements), note)


class ModelSecantMechanism(Mechanism):
    """Corrects ``it.estimate``'s constraint Jacobian with the model's secant (module docstring)."""

    def estimate(self, it: Iteration) -> None:
        est = it.estimate
        if not (it.model.success and est.quality > 0 and np.all(np.isfinite(est.cost))
                and np.all(np.isfinite(est.constraints))):
            return
        est, note = model_secant_estimate(it.estimator, est, it.c_k, it.nominal, it.new, it.past, it.model,
                                          it.model_values)
        est.notes = "; ".join(n for n in (est.notes, note) if n)
        it.estimate = est
