"""Modifiers from the model's own differences over the plant's perturbations (``GMASettings.model_secant``).

A difference quotient over a step ``h`` measures the plant's *secant*, not its gradient: for forward differences
the error is ``f'' h / 2``. With steps large enough to beat the measurement noise (half a box width on the kite)
that error is of the size of the gradients near the optimum, and GMA's fixed point, where the modified gradient
``grad phi_hat + (secant_p - grad phi_hat)`` vanishes, is where the plant's *secant* vanishes: half a step from the
plant optimum (measured on the kite: *nimble* scenario, docs/benchmarks.md).

The model is cheap to evaluate at the same points. With ``model_secant`` on, GMA runs the same gradient estimator
on the model's values at the very setpoints the plant flew (the nominal point and the points the estimator uses)
and takes the difference as the gradient modifier:

    lambda = secant_p - secant_hat,       grad phi_p (estimated) = grad phi_hat + secant_p - secant_hat

and likewise for the constraints. The truncation errors cancel up to the plant-model *curvature mismatch*,
``(f''_p - f''_hat) h / 2``, so large steps keep their low noise without their bias. At the model's own points
the model values are exact, so the estimate's noise (``cost_std``) is the plant's. Costs one model solve per
point used (:class:`ModelPoint` solves lazily: a past point the estimator only looks at is never solved).
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from .gradients import GradientEstimate, GradientEstimator, PlantPoint

__all__ = ["ModelPoint", "model_secant_estimate"]


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
                          evaluate: Callable[[np.ndarray], tuple], constraints: bool = True,
                          cost: bool = True) -> tuple:
    """The plant estimate ``plant`` corrected by the model's truncation error (module docstring).

    Args:
        estimator: the strategy that produced ``plant`` from ``nominal``, ``new`` and ``past``.
        plant: its estimate from the plant's measurements.
        c_k: the operating point (n_c,).
        nominal, new, past: the plant points ``plant`` came from.
        model: the model's linearization at ``c_k`` (:class:`~kite_rto.gma.ModelRealization`: ``grad_phi``,
            ``jac_g``).
        evaluate: ``c -> (phi_hat, g_hat)`` of the model (NaN where it cannot realize ``c``).
        constraints: correct the constraints' Jacobian too (False: only the cost gradient; the constraints keep
            the plant's quotients).
        cost: correct the cost gradient (False: only the constraints; the cost keeps the plant's quotients).

    Returns ``(estimate, note)``: ``plant`` with ``grad phi_hat + secant_p - secant_hat`` (constraints likewise),
    same quality and standard deviations; ``plant`` itself when the model's secant is not finite (the note says
    so).
    """
    def as_model(p):
        return ModelPoint(p, evaluate)

    own = estimator.estimate_at(c_k, as_model(nominal), [as_model(p) for p in new], [as_model(p) for p in past],
                                model)
    n_c = np.size(c_k)
    g_phi = np.asarray(model.grad_phi, float).ravel()
    j_g = np.asarray(model.jac_g, float).reshape(-1, n_c)
    grad = plant.cost - own.cost + g_phi if cost else np.asarray(plant.cost, float)
    cons = plant.constraints.reshape(j_g.shape)
    if constraints:
        cons = cons - own.constraints.reshape(j_g.shape) + j_g
    if not (np.all(np.isfinite(grad)) and np.all(np.isfinite(cons))):
        return plant, "model secant not finite: the plant's difference quotients used as they are"
    diff = g_phi - own.cost
    note = (f"model secant: truncation correction {np.round(diff, 6).tolist()} on the cost gradient" if cost else
            f"model secant: truncation correction on the constraints only, "
            f"{np.round(j_g - own.constraints.reshape(j_g.shape), 6).tolist()}")
    return (GradientEstimate(grad, cons, plant.quality, plant.cost_std, plant.method, plant.notes,
                             plant.displacements), note)
