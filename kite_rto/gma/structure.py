"""Measurements overrule the model's structure (issue #14, item 2).

Directional modifier adaptation (:mod:`~kite_rto.gma.directional`) trusts the model in two ways: a setpoint at
a *robustly active* bound gets no experiment at all, and outside the ``r`` privileged directions the plant
gradient is the model's. Both are decided from the model alone. This module lets plant data overrule them:

* :func:`robust_bounds` — the activity test **with the constraints**: a bound is robustly active only if the
  model's constrained optimum stays on it for every parameter deviation and for every constraint shifted by
  its plausible error. A gradient-only test at the model optimum misses a constraint that is inactive there
  but, once active, pulls the setpoint off its bound.
* :func:`excluded_directions`, :func:`structure_plan`, :func:`structure_test` — the measured check that
  :class:`~kite_rto.gma.GMA` runs when ``GMASettings.structure_check_every`` or ``structure_stall`` asks for it:
  one experiment along each direction that the gradient estimator leaves to the model, and a comparison of the
  measured change of cost and constraints with the change the estimate predicts. A mismatch larger than
  ``structure_sigma`` standard deviations (from ``ExperimentResult.cost_std`` / ``constraints_std`` and the
  estimate's ``cost_std``) plus ``structure_rel_tol`` of the predicted change means the model is wrong along that
  direction: GMA adds it to the estimator's directions (``DirectionalGradient.with_directions``) and records it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ._nlp import ModifiedNLP
from .gradients import GradientEstimate, PlantPoint
from .modifiers import Modifiers
from .problem import ModelProblem
from .settings import GMASettings

__all__ = ["BoundActivity", "robust_bounds", "bound_side", "model_optimum", "excluded_directions",
           "structure_plan", "StructureTest", "structure_test"]


@dataclass
class BoundActivity:
    """Result of :func:`robust_bounds`.

    Attributes:
        at_bound: (n_c,) -1 / 0 / +1: the setpoint sits at its lower / no / upper bound in **every** case
            (pass it as ``privileged_directions(..., at_bound=...)``: a 0 there keeps the setpoint free).
        nominal: (n_c,) -1 / 0 / +1 at the nominal model optimum alone (what a test at one point sees).
        optima: (m, n_c) the model's constrained optimum in each case, setpoint units.
        cases: (m,) a label per case: ``"nominal"``, ``"theta[j]"``, ``"constraint[i]"``.
    """

    at_bound: np.ndarray
    nominal: np.ndarray
    optima: np.ndarray
    cases: list[str]

    @property
    def fragile(self) -> np.ndarray:
        """(n_c,) bool: active at the nominal optimum but left in some case."""
        return (self.nominal != 0) & (self.at_bound == 0)


def bound_side(c, lb, ub, tol):
    """Per setpoint -1 / 0 / +1: ``c`` within ``tol`` box widths of its lower bound / inside / within ``tol`` of
    its upper bound."""
    w = ub - lb
    return np.where(c <= lb + tol * w, -1, np.where(c >= ub - tol * w, 1, 0))


def robust_bounds(optimum: Callable[[np.ndarray, np.ndarray], np.ndarray], theta0, deviations, c_lb, c_ub,
                  constraint_offsets=(), tol: float = 1e-6) -> BoundActivity:
    """Which setpoint bounds stay active in the model's **constrained** optimum over the uncertainty.

    Args:
        optimum: ``(theta, offsets) -> c*`` (n_c,): ``y(u)`` at the model's optimum for parameters ``theta`` with
            its constraints shifted, ``g(u) + offsets <= 0`` (e.g. :func:`model_optimum` of the model built
            with ``theta``).
        theta0: nominal parameters (n_theta,).
        deviations: a plausible deviation per parameter (n_theta,), nonzero, with its sign.
        c_lb, c_ub: the setpoint box (n_c,).
        constraint_offsets: a plausible error of each constraint (n_g,), constraint units; a positive offset
            tightens the constraint (the plant's constraint may be closer than the model says). Zero entries are
            skipped; an empty sequence tests no constraint shift.
        tol: a setpoint within ``tol`` box widths of a bound is at it.

    Cases: the nominal model, each parameter deviated alone, each constraint shifted alone.
    """
    theta0 = np.asarray(theta0, dtype=float).ravel()
    dev = np.asarray(deviations, dtype=float).ravel()
    if dev.size != theta0.size or not np.all(np.isfinite(dev)) or np.any(dev == 0):
        raise ValueError(f"robust_bounds: deviations={deviations!r}: expected {theta0.size} finite nonzero values")
    lb, ub = np.asarray(c_lb, float).ravel(), np.asarray(c_ub, float).ravel()
    off = np.asarray(constraint_offsets, dtype=float).ravel()
    if not np.all(np.isfinite(off)):
        raise ValueError(f"robust_bounds: constraint_offsets={constraint_offsets!r}: expected finite values")
    cases = [("nominal", theta0, np.zeros(off.size))]
    for j in range(theta0.size):
        th = theta0.copy()
        th[j] += dev[j]
        cases.append((f"theta[{j}]", th, np.zeros(off.size)))
    for i in np.flatnonzero(off):
        cases.append((f"constraint[{i}]", theta0, np.eye(off.size)[i] * off[i]))
    optima = np.array([np.asarray(optimum(th, o), dtype=float).ravel() for _, th, o in cases])
    if optima.shape[1] != lb.size or not np.all(np.isfinite(optima)):
        raise ValueError(f"robust_bounds: optimum returned {optima.tolist()}: expected finite (n_c={lb.size},) "
                         f"setpoints")
    sides = np.array([bound_side(c, lb, ub, tol) for c in optima])
    robust = np.where(np.all(sides == sides[0], axis=0), sides[0], 0)
    return BoundActivity(robust, sides[0], optima, [name for name, _, _ in cases])


def model_optimum(problem: ModelProblem, offsets=None, settings: GMASettings | None = None) -> np.ndarray:
    """``y(u)`` (n_c,) at the optimum of ``problem`` with its constraints shifted, ``g(u) + offsets <= 0``
    (``offsets`` (n_g,), constraint units; ``None`` or empty = none), inside the setpoint box. Builds its own NLP.
    ``RuntimeError`` if the solve fails."""
    settings = settings or GMASettings()
    off = np.zeros(problem.n_g) if offsets is None or np.size(offsets) == 0 else \
        np.asarray(offsets, dtype=float).ravel()
    if off.size != problem.n_g:
        raise ValueError(f"model_optimum: offsets has {off.size} entries, expected n_g={problem.n_g}")
    mid = 0.5 * (problem.c_lb + problem.c_ub)
    mods = Modifiers(mid, off, np.zeros(problem.n_c), np.zeros((problem.n_g, problem.n_c)), np.zeros(problem.n_g))
    res = ModifiedNLP(problem, settings).solve(mods, radius=np.full(problem.n_c, np.inf),
                                               convexification=np.zeros(problem.n_c), penalty=None, x0=problem.u0)
    if not res.success:
        raise RuntimeError(f"model_optimum: the model {problem.name!r} has no optimum with offsets "
                           f"{off.tolist()} ({res.status})")
    return np.clip(problem.evaluate(res.x[: problem.n_u])[2], problem.c_lb, problem.c_ub)


def excluded_directions(directions, width) -> np.ndarray:
    """(n_c, n_c - r) a basis of the setpoint directions an estimator with ``directions`` (n_c, r) leaves to
    the model: the orthogonal complement of their span (setpoint units, where the directional correction
    ``U^{+T} b`` vanishes), each column scaled to a largest component of one box width (``width`` (n_c,))."""
    U = np.asarray(directions, dtype=float)
    Q, s, _ = np.linalg.svd(U, full_matrices=True)
    rank = int(np.sum(s > 1e-12 * max(s[0], 1e-300)))
    N = Q[:, rank:]
    w = np.asarray(width, float).ravel()
    if N.shape[1] == 0:
        return N
    N = N / np.max(np.abs(N) / w[:, None], axis=0)
    return N * np.where(N.sum(axis=0) < 0, -1.0, 1.0)            # sign convention: components sum >= 0


def structure_plan(c_k, excluded, step: float, c_lb, c_ub) -> list[np.ndarray]:
    """One experiment per excluded direction ``n``: ``c_k + step n`` or ``c_k - step n``, clipped to the box,
    whichever keeps more of the direction (``step`` relative to the box width, as ``n`` has width units)."""
    c_k = np.asarray(c_k, float)
    points = []
    for n in np.asarray(excluded, float).T:
        cands = [np.clip(c_k + sign * step * n, c_lb, c_ub) for sign in (1.0, -1.0)]
        kept = [abs(float((c - c_k) @ n)) for c in cands]
        points.append(cands[int(np.argmax(kept))])
    return points


@dataclass
class StructureTest:
    """One measured check along an excluded direction (:func:`structure_test`).

    Attributes:
        dc: the displacement flown, ``c - c_k`` (n_c,), setpoint units.
        residual_cost: measured minus predicted cost change, ``phi_p(c) - phi_p(c_k) - grad^T dc``, cost units.
        threshold_cost: the significance threshold for it, cost units.
        residual_constraints: (n_g,) the same for the constraints, constraint units.
        threshold_constraints: (n_g,).
        significant: some residual exceeds its threshold: the model is wrong along ``dc``.
    """

    dc: np.ndarray
    residual_cost: float
    threshold_cost: float
    residual_constraints: np.ndarray
    threshold_constraints: np.ndarray
    significant: bool

    def describe(self) -> str:
        """One line for ``IterationRecord.notes``."""
        which = (["cost"] if abs(self.residual_cost) > self.threshold_cost else []) + \
            [f"g[{i}]" for i in np.flatnonzero(np.abs(self.residual_constraints) > self.threshold_constraints)]
        verdict = f"mismatch in {', '.join(which)}: direction restored" if self.significant else "model agrees"
        return (f"structure check along dc={np.round(self.dc, 6).tolist()}: cost residual "
                f"{self.residual_cost:+.4g} (threshold {self.threshold_cost:.3g}), constraint residuals "
                f"{np.round(self.residual_constraints, 6).tolist()} (thresholds "
                f"{np.round(self.threshold_constraints, 6).tolist()}): {verdict}")


def structure_test(c_k, nominal: PlantPoint, point: PlantPoint, est: GradientEstimate, sigma: float,
                   rel_tol: float) -> StructureTest:
    """Compare the measured change from ``nominal`` (at ``c_k``) to ``point`` with the change ``est`` predicts.

    Thresholds: ``sigma`` standard deviations of the residual plus ``rel_tol`` times the predicted change. The
    residual's standard deviation combines both measurements' (``cost_std``, ``constraints_std``; 0 when not
    given) and, for the cost, the estimate's ``cost_std`` along ``dc`` (``sum_i |dc_i| std_i``).
    """
    dc = np.asarray(point.c, float) - np.asarray(c_k, float)
    pred_f = float(np.asarray(est.cost, float) @ dc)
    pred_g = np.asarray(est.constraints, float) @ dc
    r_f = point.cost - nominal.cost - pred_f
    r_g = np.asarray(point.constraints, float) - np.asarray(nominal.constraints, float) - pred_g

    def std(a, b, n):
        va = np.zeros(n) if a is None else np.broadcast_to(np.asarray(a, float), (n,))
        vb = va if b is None else np.broadcast_to(np.asarray(b, float), (n,))
        return np.sqrt(va ** 2 + vb ** 2)

    s_f = float(std(nominal.cost_std, point.cost_std, 1)[0])
    if est.cost_std is not None:
        s_f = math.hypot(s_f, float(np.abs(dc) @ np.asarray(est.cost_std, float)))
    n_g = r_g.size
    s_g = std(nominal.constraints_std, point.constraints_std, n_g) if n_g else np.zeros(0)
    t_f = sigma * s_f + rel_tol * abs(pred_f)
    t_g = sigma * s_g + rel_tol * np.abs(pred_g)
    significant = bool(abs(r_f) > t_f or np.any(np.abs(r_g) > t_g))
    return StructureTest(dc, float(r_f), float(t_f), r_g, t_g, significant)
