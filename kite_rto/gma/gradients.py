"""Plant gradient estimation with respect to the setpoints ``c``: interchangeable strategies.

Every strategy implements the small :class:`GradientEstimator` interface:

* ``plan(c_k, lb, ub, past) -> list[np.ndarray]``: the extra setpoints (perturbation experiments) it needs
  around the operating point ``c_k``, given the finished experiments ``past``;
* ``estimate(c_k, nominal, new, past, model) -> GradientEstimate``: the estimate from the nominal measurement at
  ``c_k``, the results ``new`` of the planned experiments (same order), ``past`` and the model's linearization
  at ``c_k`` (a :class:`~kite_rto.gma.ModelRealization`; strategies that do not use it ignore it).

A :class:`GradientEstimate` carries the gradient of the cost (n_c,), the Jacobian of the constraints
(n_g, n_c) and a quality indicator (reciprocal condition number of the scaled design, 1 = ideal).
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Sequence

import numpy as np

__all__ = ["PlantPoint", "GradientEstimate", "GradientEstimator", "FiniteDifferenceGradient",
           "LeastSquaresGradient"]


@dataclass
class PlantPoint:
    """One finished plant experiment as the estimators see it: setpoints ``c`` (n_c,), measured cost,
    constraints (n_g,), and optional standard deviations of these measurements."""

    c: np.ndarray
    cost: float
    constraints: np.ndarray
    cost_std: float | None = None
    constraints_std: np.ndarray | None = None


@dataclass
class GradientEstimate:
    """Plant gradients at ``c_k``.

    Attributes:
        cost: ``d phi_p / d c``, shape (n_c,), cost units per setpoint unit.
        constraints: ``d g_p / d c``, shape (n_g, n_c).
        quality: reciprocal condition number of the step matrix scaled by the nominal steps, in [0, 1];
            1 for coordinate finite differences, 0 = unusable.
        cost_std: predicted standard deviation of each entry of ``cost`` due to measurement noise (n_c,),
            ``None`` when the measurements carried no standard deviation.
        method: name of the strategy that produced it.
        notes: free text (e.g. why a fallback was used).
        displacements: ``c_j - c_k`` (m, n_c) of the points whose differences from the nominal one the
            estimate is a linear fit of (setpoint units): a safe step predicts a change over a step that
            extrapolates these differences more cautiously (:mod:`~kite_rto.gma.safe_step`); ``None`` when the
            estimate is not such a fit (central differences, whose error is of third order).
    """

    cost: np.ndarray
    constraints: np.ndarray
    quality: float
    cost_std: np.ndarray | None = None
    method: str = ""
    notes: str = ""
    displacements: np.ndarray | None = None


class GradientEstimator(ABC):
    """Common interface of the plant-gradient strategies (see the module docstring)."""

    @abstractmethod
    def plan(self, c_k: np.ndarray, lb: np.ndarray, ub: np.ndarray,
             past: Sequence[PlantPoint]) -> list[np.ndarray]:
        """Setpoints of the perturbation experiments needed at ``c_k`` (each inside ``[lb, ub]``)."""

    @abstractmethod
    def estimate(self, c_k: np.ndarray, nominal: PlantPoint, new: Sequence[PlantPoint],
                 past: Sequence[PlantPoint], model=None) -> GradientEstimate:
        """Gradient estimate at ``c_k`` from the nominal result, the planned results, past points and the model's
        linearization ``model`` at ``c_k``."""


def _positive(name: str, value) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
    if arr.size == 0 or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"{name}={value!r}: expected finite values > 0")
    return arr


class FiniteDifferenceGradient(GradientEstimator):
    """Coordinate finite differences around ``c_k``: ``n_c`` (forward) or ``2 n_c`` (central) experiments.

    Args:
        step: step ``h`` per setpoint, absolute setpoint units, scalar or shape (n_c,), ``> 0``.
        scheme: ``"forward"`` (error ``O(h)``) or ``"central"`` (error ``O(h^2)``, twice the experiments).

    Perturbed setpoints are clipped to the setpoint box; a step that would leave the box is taken the other
    way instead. The differences always use the setpoints actually requested.
    """

    def __init__(self, step, scheme: str = "forward"):
        self.step = _positive("FiniteDifferenceGradient.step", step)
        if scheme not in ("forward", "central"):
            raise ValueError(f"FiniteDifferenceGradient.scheme={scheme!r}: expected 'forward' or 'central'")
        self.scheme = scheme

    @classmethod
    def from_noise(cls, noise_std: float, curvature, scheme: str = "forward",
                   third_derivative=None) -> "FiniteDifferenceGradient":
        """Choose steps that minimize the error bound of the difference quotient.

        Forward: truncation ``h |f''| / 2`` plus noise ``2 sigma / h`` is smallest at
        ``h = 2 sqrt(sigma / |f''|)``. Central: truncation ``h^2 |f'''| / 6`` plus noise ``sigma / h`` is
        smallest at ``h = (3 sigma / |f'''|)^(1/3)``; without ``third_derivative`` the forward rule is used.

        Args:
            noise_std: standard deviation ``sigma`` of one cost measurement (cost units), ``> 0``.
            curvature: estimate of ``|d^2 phi_p / d c_i^2|`` per setpoint (e.g. from the model), ``> 0``.
            third_derivative: estimate of ``|d^3 phi_p / d c_i^3|`` per setpoint (central only).
        """
        sigma = float(_positive("noise_std", noise_std)[0])
        curv = _positive("curvature", curvature)
        if scheme == "central" and third_derivative is not None:
            step = (3.0 * sigma / _positive("third_derivative", third_derivative)) ** (1.0 / 3.0)
        else:
            step = 2.0 * np.sqrt(sigma / curv)
        return cls(step, scheme)

    def _steps(self, n: int) -> np.ndarray:
        if self.step.size == 1:
            return np.full(n, self.step[0])
        if self.step.size != n:
            raise ValueError(f"FiniteDifferenceGradient.step has {self.step.size} entries, expected {n}")
        return self.step

    def plan(self, c_k, lb, ub, past=()):
        c_k = np.asarray(c_k, float)
        points = []
        for i, h in enumerate(self._steps(c_k.size)):
            inside = lb[i] <= c_k[i] + h <= ub[i]
            signs = (1.0, -1.0) if self.scheme == "central" else (1.0 if inside else -1.0,)
            for s in signs:
                c = c_k.copy()
                c[i] = np.clip(c_k[i] + s * h, lb[i], ub[i])
                points.append(c)
        return points

    def estimate(self, c_k, nominal, new, past=(), model=None):
        c_k = np.asarray(c_k, float)
        n_c, n_g = c_k.size, np.size(nominal.constraints)
        per = 2 if self.scheme == "central" else 1
        if len(new) != per * n_c:
            raise ValueError(f"FiniteDifferenceGradient.estimate: expected {per * n_c} results, got {len(new)}")
        grad, jac = np.zeros(n_c), np.zeros((n_g, n_c))
        std = np.zeros(n_c) if nominal.cost_std is not None else None
        ok = True
        for i in range(n_c):
            a, b = (new[2 * i], new[2 * i + 1]) if per == 2 else (new[i], nominal)
            dc = a.c[i] - b.c[i]
            if abs(dc) < 1e-300:
                ok = False
                continue
            grad[i] = (a.cost - b.cost) / dc
            jac[:, i] = (np.asarray(a.constraints, float) - np.asarray(b.constraints, float)) / dc
            if std is not None:
                sa = a.cost_std if a.cost_std is not None else nominal.cost_std
                sb = b.cost_std if b.cost_std is not None else nominal.cost_std
                std[i] = math.hypot(sa, sb) / abs(dc)
        disp = None if per == 2 else np.array([np.asarray(p.c, float) - c_k for p in new])
        return GradientEstimate(grad, jac, 1.0 if ok else 0.0, std, f"finite-difference ({self.scheme})",
                                "" if ok else "a step collapsed on the setpoint box", disp)


class LeastSquaresGradient(GradientEstimator):
    """Gradients from past operating points by least squares, with finite differences as fallback.

    The affine fit ``f(c_j) - f(c_k) ~ grad^T (c_j - c_k)`` uses the ``window`` most recent past points
    within ``radius`` of ``c_k``. The step matrix, scaled by ``radius``, must have a reciprocal condition
    number ``>= rcond_min`` (and at least ``n_c`` rows); otherwise the estimator asks for the perturbation
    experiments of ``fallback`` and uses them instead.

    Args:
        fallback: finite-difference strategy used when the past points are ill-conditioned.
        radius: largest usable distance per setpoint (absolute units); default ``10 * fallback.step``.
        window: number of most recent usable points (``None`` = ``2 n_c``).
        rcond_min: conditioning threshold in (0, 1].
    """

    def __init__(self, fallback: FiniteDifferenceGradient, radius=None, window: int | None = None,
                 rcond_min: float = 0.1):
        if not isinstance(fallback, FiniteDifferenceGradient):
            raise ValueError(f"LeastSquaresGradient.fallback={fallback!r}: expected a FiniteDifferenceGradient")
        self.fallback = fallback
        self.radius = None if radius is None else _positive("LeastSquaresGradient.radius", radius)
        if window is not None and (not isinstance(window, int) or window < 1):
            raise ValueError(f"LeastSquaresGradient.window={window!r}: expected an integer >= 1 or None")
        self.window = window
        if not 0.0 < rcond_min <= 1.0:
            raise ValueError(f"LeastSquaresGradient.rcond_min={rcond_min!r}: expected a value in (0, 1]")
        self.rcond_min = float(rcond_min)

    def _select(self, c_k, past):
        n = c_k.size
        radius = self.radius if self.radius is not None else 10.0 * self.fallback._steps(n)
        window = self.window if self.window is not None else 2 * n
        chosen = []
        for pt in reversed(list(past)):
            d = (np.asarray(pt.c, float) - c_k) / radius
            if 0 < np.max(np.abs(d)) <= 1.0:
                chosen.append((d, pt))
            if len(chosen) == window:
                break
        if len(chosen) < n:
            return chosen, 0.0
        s = np.linalg.svd(np.array([d for d, _ in chosen]), compute_uv=False)
        return chosen, float(s[-1] / s[0]) if s[0] > 0 else 0.0

    def plan(self, c_k, lb, ub, past=()):
        c_k = np.asarray(c_k, float)
        _, rcond = self._select(c_k, past)
        return [] if rcond >= self.rcond_min else self.fallback.plan(c_k, lb, ub, past)

    def estimate(self, c_k, nominal, new, past=(), model=None):
        c_k = np.asarray(c_k, float)
        if len(new) > 0:
            est = self.fallback.estimate(c_k, nominal, new, past)
            est.notes = "past points ill-conditioned: finite-difference fallback"
            return est
        chosen, rcond = self._select(c_k, past)
        dc = np.array([np.asarray(pt.c, float) - c_k for _, pt in chosen])
        df = np.array([pt.cost - nominal.cost for _, pt in chosen])
        dg = np.array([np.asarray(pt.constraints, float) - np.asarray(nominal.constraints, float)
                       for _, pt in chosen]).reshape(len(chosen), -1)
        sol, *_ = np.linalg.lstsq(dc, np.column_stack([df, dg]), rcond=None)
        std = None
        if nominal.cost_std is not None:
            cov = np.linalg.pinv(dc.T @ dc) * 2.0 * nominal.cost_std ** 2
            std = np.sqrt(np.diag(cov))
        return GradientEstimate(sol[:, 0], sol[:, 1:].T.copy(), rcond, std, "least-squares (past points)",
                                f"{len(chosen)} past points", dc)
