"""The gain of the modifier filter matched to the gradient noise (:class:`~kite_rto.gma.NoiseFilter`): a scalar
Kalman filter per setpoint on the gradient modifiers.

The fixed filter ``lambda_k = (1 - b) lambda_{k-1} + b lambda_k^measured`` (:class:`~kite_rto.gma.ModifierFilter`)
averages over about ``2 / b - 1`` iterations whatever the noise. With a :class:`~kite_rto.gma.NoiseFilter` of drift
bound ``q``, :class:`~kite_rto.gma.GMA` chooses the gain ``K_i`` of setpoint ``i`` each iteration from two variances:

* the measurement's, ``R_i``: the mean of ``s_i^2`` over the estimates of the chain, ``s_i`` an estimate's
  standard deviation (:attr:`~kite_rto.gma.GradientEstimate.cost_std`, from the experiments' measured standard
  errors). The pooled value, not each estimate's own: a standard error from a few samples is itself uncertain,
  and an underestimated one would let a bad measurement in with a high gain; the plant's noise is taken as
  stationary;
* the filtered modifier's, ``P_i``, grown by the drift of the modifier over the last step ``d``:
  ``P_i <- P_i + (q |d / w| / w_i)^2``. The modifier is the plant-minus-model gradient, so over a step it
  changes by the plant-model curvature mismatch times the step; ``q`` bounds that mismatch, cost units per
  squared box width (``w`` the box width, ``|d / w|`` the Euclidean step in box widths).

``K_i = P_i / (P_i + R_i)``, then ``P_i <- (1 - K_i) P_i``. Long steps make ``P`` large and the gain close to 1
(the new measurement counts); at a converged point the steps shrink, ``P`` keeps falling and the filter
averages ever more iterations (about ``1 / n`` after ``n`` iterations at one point): the least-squares mean of
the history, forgetting it as fast as the iterate moves. The first estimate is taken as it is (``P = R``). The
gradient-of-constraint modifiers ``mu[:, i]`` get the same gain (they come from the same experiments) unless the
constraints have a drift bound of their own.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["noise_gain"]


def noise_gain(points: Sequence[np.ndarray], stds: Sequence[np.ndarray], drift: float, width) -> tuple:
    """Replay the filter of the module docstring over a chain of gradient estimates.

    Args:
        points: the operating points ``c_0, ..., c_n`` of the estimates in the chain (each (n_c,)), setpoint units.
        stds: each estimate's standard deviations ``s`` (each (n_c,)), cost units per setpoint unit; pooled.
        drift: ``q``, cost units per squared box width, ``>= 0``.
        width: the box width ``w`` (n_c,), setpoint units.

    Returns ``(K, P)``: the gain applied to the last estimate and the filtered variance after it (each (n_c,)).
    With a single estimate ``K = 1``. A component whose ``s_i`` is zero throughout (known exactly) gets ``K_i = 1``.
    """
    if len(points) != len(stds) or not len(points):
        raise ValueError(f"noise_gain: expected as many points as standard deviations (>= 1), got "
                         f"{len(points)} and {len(stds)}")
    w = np.asarray(width, dtype=float)
    R = np.mean([np.asarray(s, dtype=float) ** 2 for s in stds], axis=0)
    P = R.copy()
    K = np.ones_like(P)
    for prev, c in zip(points[:-1], points[1:]):
        step = float(np.linalg.norm((np.asarray(c, float) - np.asarray(prev, float)) / w))
        P_pred = P + (drift * step / w) ** 2
        total = P_pred + R
        K = np.divide(P_pred, total, out=np.ones_like(P_pred), where=total > 0)
        P = (1.0 - K) * P_pred
    return K, P
