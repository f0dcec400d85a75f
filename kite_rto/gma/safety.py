"""Safe steps (issue #14, item 3): no iterate may violate the plant's constraints beyond their tolerance.

The modified problem predicts the constraints with the model's curvature plus an affine correction; when the
plant's constraint curves differently, or the measured gradient is uncertain, its step can end outside the
plant's feasible set. With ``GMASettings.safe_curvature`` set, :class:`~kite_rto.gma.GMA` shortens the filtered
step ``d`` to ``alpha d``, ``alpha`` in [0, 1] the largest value with, for every constraint ``j``,

    g_j + k s_j + alpha (J_j d + k t_j) + 0.5 M_j alpha^2 |d / w|^2  <=  max(tol_j, g_j + k s_j)

where ``g_j`` is the measured constraint at ``c_k`` with standard deviation ``s_j``, ``J_j`` the estimated plant
gradient, ``t_j`` the standard deviation of ``J_j d``, ``k = safe_sigma``, ``w`` the box width, ``tol_j =
safe_tolerance`` and ``M_j`` a bound on the plant constraint's curvature in box widths (an SCFO-style
sufficient condition, Bunin et al. 2014). From a point within ``k s_j`` of the limit, or beyond it, the step may
not make the constraint worse. ``M_j`` starts at ``safe_curvature`` and grows to the largest curvature the
measurements show: ``2 (e - k s) / |d / w|^2`` for each past step, ``e`` the measured constraint change minus
its first-order prediction (:func:`observed_curvature`), so a model that disagrees with the plant earns shorter
steps.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["safe_fraction", "observed_curvature", "truncation_bound", "step_weights"]


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


def truncation_bound(displacements, step, width) -> float:
    """``0.5 sum_i |a_i| |p_i|^2`` (squared box widths): how far, per unit of curvature bound ``M``, the
    truncation errors of a gradient fitted to differences over the points ``p_i = displacements[i] / width``
    can move its prediction of the change over ``step`` (``a`` from :func:`step_weights`). Each difference
    ``f(c_k + p_i) - f(c_k)`` is the gradient's term plus at most ``0.5 M |p_i|^2``; a fit that is linear in those
    differences passes them on with weights ``a_i``. Arguments as :func:`step_weights`'s.
    """
    w = np.asarray(width, float)
    P = np.asarray(displacements, float).reshape(-1, w.size) / w
    a = step_weights(displacements, step, width)
    return 0.5 * float(np.abs(a) @ np.sum(P ** 2, axis=1))


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


def observed_curvature(records, stds, width, sigma: float, min_step: float, n_g: int,
                       both_ends: bool = False) -> np.ndarray:
    """(n_g,) the largest constraint curvature (constraint units per squared box width) that consecutive
    iteration records show: for a step ``d = c_{k+1} - c_k`` of at least ``min_step`` box widths (largest
    component), ``2 (e - k s) / |d / w|^2`` with ``e = g(c_{k+1}) - g(c_k) - J_k d`` and ``s`` the standard
    deviation of the two measurements (``stds``: one (n_g,) array or ``None`` per record); 0 when no step shows
    any. With ``both_ends`` also ``e = g(c_k) - g(c_{k+1}) + J_{k+1} d``, the gradient estimated at the step's end
    predicting its start: the curvature bound holds from either end, and an estimate that extrapolates badly
    backwards (a secant over a perturbation in a strongly curved region) is caught before its own step."""
    out = np.zeros(n_g)
    w = np.asarray(width, float)
    for i in range(len(records) - 1):
        prev, cur = records[i], records[i + 1]
        d = np.asarray(cur.c_k, float) - np.asarray(prev.c_k, float)
        if np.max(np.abs(d) / w) < min_step or not np.allclose(prev.c_next, cur.c_k):
            continue
        J = np.asarray(prev.jac_constraints, float).reshape(n_g, -1)
        if not np.all(np.isfinite(J)):
            continue
        dg = np.asarray(cur.constraints, float) - np.asarray(prev.constraints, float)    # measured change
        e = dg - J @ d
        if both_ends:
            J_end = np.asarray(cur.jac_constraints, float).reshape(n_g, -1)
            if np.all(np.isfinite(J_end)):
                e = np.maximum(e, J_end @ d - dg)
        s = np.hypot(*(np.zeros(n_g) if x is None else np.asarray(x, float) for x in (stds[i], stds[i + 1])))
        out = np.maximum(out, 2.0 * (e - sigma * s) / float(np.sum((d / w) ** 2)))
    return out
