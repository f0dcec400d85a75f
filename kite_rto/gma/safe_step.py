"""Safe steps: no iterate may violate the plant's constraints beyond their tolerance.

The modified problem predicts the constraints with the model's curvature plus an affine correction; when the
plant's constraint curves differently, or the measured gradient is uncertain, its step can end outside the
plant's feasible set. :class:`SafeStep` shortens the filtered step ``d`` to ``alpha d``, ``alpha`` in [0, 1] the
largest value with, for every constraint ``j``,

    g_j + k s_j + alpha (J_j d + k t_j) + 0.5 M_j alpha^2 |d / w|^2  <=  max(tol_j, g_j + k s_j)

where ``g_j`` is the measured constraint at ``c_k`` with standard deviation ``s_j``, ``J_j`` the estimated plant
gradient, ``t_j`` the standard deviation of ``J_j d``, ``k = sigma``, ``w`` the box width, ``tol_j = tolerance``
and ``M_j`` a bound on the plant constraint's curvature in box widths (an SCFO-style sufficient condition, Bunin et
al. 2014). From a point within ``k s_j`` of the limit, or beyond it, the step may not make the constraint worse.
``M_j`` starts at ``curvature`` and grows to the largest curvature the measurements show, from either end of each
past step (:func:`observed_curvature`), so a model that disagrees with the plant earns shorter steps. Where the
estimate extrapolates a difference taken on the other side of ``c_k`` than the step (a negative weight in
:func:`step_weights`), that part of the step is predicted with the worse of the estimated and the model's slope:
a secant through a curved region can flip the sign the model has right. Measured on the kite: without safe steps
half the runs flew an iterate below the altitude floor, with them none (docs/history.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ._checks import Scalar, check_range, per_setpoint
from .mechanism import Iteration, Mechanism
from .modifiers import Decision

__all__ = ["SafeStep", "safe_fraction", "observed_curvature", "step_weights", "ConstraintSample"]


def step_weights(displacements, step, width) -> np.ndarray:
    """``a`` (m,): the least-squares combination ``d = sum_i a_i p_i`` of the fitted points ``p_i =
    displacements[i] / width`` that makes up the step ``d = step / width`` (box widths). A gradient fitted to
    differences over those points predicts the change over the step with these weights; a negative ``a_i``
    extrapolates a difference taken on the other side of ``c_k`` than the step.

    Args:
        displacements: ``c_i - c_k`` (m, n_c), setpoint units.
        step: the step (n_c,), setpoint units.
        width: box width per setpoint (n_c,).
    """
    w = np.asarray(width, float)
    P = np.asarray(displacements, float).reshape(-1, w.size) / w
    if P.shape[0] == 0:
        return np.zeros(0)
    a, *_ = np.linalg.lstsq(P.T, np.asarray(step, float) / w, rcond=None)
    return a


def safe_fraction(g, g_std, slope, slope_std, curvature, step_sq: float, sigma: float, tolerance
                  ) -> tuple[float, int | None]:
    """The largest ``alpha`` in [0, 1] that satisfies the condition of the module docstring for all constraints.

    Args:
        g, g_std: measured constraints at ``c_k`` and their standard deviations (n_g,), constraint units.
        slope, slope_std: ``J d`` and its standard deviation (n_g,), constraint units.
        curvature: ``M`` (n_g,), constraint units per squared box width, ``>= 0``.
        step_sq: ``|d / w|^2``, squared step in box widths.
        sigma: ``k``.
        tolerance: ``tol`` (n_g,), constraint units.

    Returns ``(alpha, j)`` with ``j`` the limiting constraint (``None`` when the full step is safe).
    """
    alpha, limiting = 1.0, None
    for j in range(np.size(g)):
        start = g[j] + sigma * g_std[j]
        room = max(tolerance[j], start) - start                          # >= 0
        b = slope[j] + sigma * slope_std[j]
        a = 0.5 * curvature[j] * step_sq
        if a + b <= room:
            continue
        if a <= 0.0:
            aj = room / b
        else:
            aj = (-b + math.sqrt(b * b + 4.0 * a * room)) / (2.0 * a)
        aj = min(max(aj, 0.0), 1.0)
        if aj < alpha:
            alpha, limiting = aj, j
    return alpha, limiting


class ConstraintSample(NamedTuple):
    """The constraints measured at an operating point: ``c_k`` (n_c,), the point GMA went on to, ``c_next`` (n_c,),
    the measured ``constraints`` (n_g,) and their standard deviations ``constraints_std`` (n_g,) or ``None``, and
    the estimated Jacobian ``jac_constraints`` (n_g, n_c)."""

    c_k: np.ndarray
    c_next: np.ndarray
    constraints: np.ndarray
    constraints_std: np.ndarray | None
    jac_constraints: np.ndarray


def observed_curvature(samples, width, sigma: float, min_step: float, n_g: int) -> np.ndarray:
    """(n_g,) the largest constraint curvature (constraint units per squared box width) that consecutive samples
    (:class:`ConstraintSample`, in order) show: for a step ``d = c_{k+1} - c_k`` of at least ``min_step`` box widths
    (largest component) that GMA took, ``2 (e - k s) / |d / w|^2`` with ``e`` the larger of
    ``g(c_{k+1}) - g(c_k) - J_k d`` (the gradient at the start predicting the end) and ``g(c_k) - g(c_{k+1}) +
    J_{k+1} d`` (the gradient at the end predicting the start: an estimate that extrapolates badly backwards, a
    secant over a perturbation in a strongly curved region, is caught before its own step), ``s`` the standard
    deviation of the two measurements and ``k = sigma``; 0 when no step shows any."""
    out = np.zeros(n_g)
    w = np.asarray(width, float)
    for prev, cur in zip(samples[:-1], samples[1:]):
        d = np.asarray(cur.c_k, float) - np.asarray(prev.c_k, float)
        if np.max(np.abs(d) / w) < min_step or not np.allclose(prev.c_next, cur.c_k):
            continue
        J = np.asarray(prev.jac_constraints, float).reshape(n_g, -1)
        if not np.all(np.isfinite(J)):
            continue
        dg = np.asarray(cur.constraints, float) - np.asarray(prev.constraints, float)    # measured change
        e = dg - J @ d
        J_end = np.asarray(cur.jac_constraints, float).reshape(n_g, -1)
        if np.all(np.isfinite(J_end)):
            e = np.maximum(e, J_end @ d - dg)
        s = np.hypot(*(np.zeros(n_g) if x is None else np.asarray(x, float)
                       for x in (prev.constraints_std, cur.constraints_std)))
        out = np.maximum(out, 2.0 * (e - sigma * s) / float(np.sum((d / w) ** 2)))
    return out


def predicted_change(est, model_jac: np.ndarray, step: np.ndarray, width: np.ndarray, n_g: int
                     ) -> tuple[np.ndarray, bool]:
    """``(change, model_used)``: each constraint's predicted change over ``step`` (n_g,). The estimate's Jacobian,
    unless the estimate extrapolates (some fitted point's weight in :func:`step_weights` is negative) and the
    model's Jacobian ``model_jac`` (n_g, n_c) is finite: then term by term, the step being ``sum_i a_i p_i + r`` over
    the fitted points ``p_i`` plus a remainder ``r`` outside their span; a term with ``a_i >= 0`` and the remainder
    are predicted with the estimated Jacobian, a term with ``a_i < 0`` with the worse (larger) of the estimated and
    the model's."""
    J = est.constraints.reshape(n_g, -1)
    usable = bool(np.all(np.isfinite(model_jac)))
    if not usable or est.displacements is None or not np.any(step):
        return J @ step, False
    P = np.asarray(est.displacements, float).reshape(-1, step.size)
    a = step_weights(P, step, width)
    if not np.any(a < -1e-9):
        return J @ step, False
    change = J @ (step - P.T @ a)
    for a_i, p_i in zip(a, P):
        measured = a_i * (J @ p_i)
        change = change + (np.maximum(measured, a_i * (model_jac @ p_i)) if a_i < -1e-9 else measured)
    return change, True


@dataclass(frozen=True)
class SafeStep:
    """Settings of safe steps (module docstring).

    Attributes:
        curvature: prior bound ``M`` on the plant constraints' curvature, constraint units per squared box width,
            ``>= 0``; scalar or one per constraint. It grows to what the measured steps show.
        sigma: standard deviations ``k`` of the measured constraint and of the predicted change, ``>= 0``.
        tolerance: how far the plant's constraints may be exceeded, constraint units, ``>= 0``; scalar or one per
            constraint.
        learn_min_step: steps shorter than this (largest component, box widths) do not update ``M`` (their
            gradient error over the step would look like curvature), ``>= 0``.
    """

    curvature: Scalar = 0.0
    sigma: float = 2.0
    tolerance: Scalar = 0.0
    learn_min_step: float = 0.01

    def __post_init__(self):
        n = type(self).__name__
        check_range(n, "curvature", self.curvature, 0.0, None)
        check_range(n, "sigma", self.sigma, 0.0, None)
        check_range(n, "tolerance", self.tolerance, 0.0, None)
        check_range(n, "learn_min_step", self.learn_min_step, 0.0, None)

    def build(self, problem) -> "SafeStepMechanism":
        return SafeStepMechanism(self, problem.n_g)


class SafeStepMechanism(Mechanism):
    """Returns the fraction of the step that keeps the predicted constraints within tolerance."""

    def __init__(self, settings: SafeStep, n_g: int):
        self.settings = settings
        self._M0 = per_setpoint("SafeStep.curvature", settings.curvature, n_g)
        self._tol = per_setpoint("SafeStep.tolerance", settings.tolerance, n_g)

    def limit(self, it: Iteration) -> float | None:
        s, pr = self.settings, it.problem
        n_g, w, step = pr.n_g, it.width, it.step
        if it.decision is not Decision.STEP or not n_g:
            return None
        est, nominal = it.estimate, it.nominal
        if not np.all(np.isfinite(est.constraints)):
            it.notes.append("safe step: no finite constraint gradient, step not taken")
            return 0.0
        g_std = np.zeros(n_g) if nominal.constraints_std is None else np.asarray(nominal.constraints_std, float)
        slope_std = np.zeros(n_g)
        if est.cost_std is not None and nominal.cost_std:   # same design: the cost's derivative std, rescaled
            slope_std = float(np.abs(step) @ np.asarray(est.cost_std, float)) * g_std / nominal.cost_std
        samples = [ConstraintSample(r.c_k, r.c_next, r.constraints, getattr(it.nominal_result(r), "constraints_std",
                                                                          None), r.jac_constraints)
                   for r in it.history.iterations]
        samples.append(ConstraintSample(it.c_k, it.c_k, nominal.constraints, nominal.constraints_std,
                                        est.constraints))
        M = np.maximum(self._M0, observed_curvature(samples, w, s.sigma, s.learn_min_step, n_g))
        model_jac = np.asarray(it.model.jac_g, float).reshape(n_g, pr.n_c)
        slope, used = predicted_change(est, model_jac, step, w, n_g)
        alpha, j = safe_fraction(nominal.constraints, g_std, slope, slope_std, M, float(np.sum((step / w) ** 2)),
                                 s.sigma, self._tol)
        if j is not None:
            change = est.constraints.reshape(n_g, -1) @ step
            it.notes.append(f"safe step: scaled by {alpha:.3g} (g[{j}] = {nominal.constraints[j]:+.4g}, predicted "
                            f"change {float(change[j]):+.4g}, "
                            + (f"model's change {float(slope[j]):+.4g}, " if used else "")
                            + f"curvature bound {M[j]:.4g})")
        return alpha
