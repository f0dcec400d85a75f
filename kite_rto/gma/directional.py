"""Directional Modifier Adaptation: plant derivatives only along a few privileged directions.

Costello, François & Bonvin, "A directional modifier-adaptation algorithm for real-time optimization",
J. Process Control 39 (2016) 64-76; applied to the kite in Costello's thesis (2015), chapter 4. Estimating the
full plant gradient costs ``n_c`` perturbation experiments per iteration. Most of them are wasted when the
plant-model mismatch moves the gradient mainly in a few directions of setpoint space. DMA therefore measures
the plant's derivatives only along ``r < n_c`` **privileged directions** ``U = [d_1 .. d_r]`` (n_c, r) and
takes the model's gradient elsewhere:

    grad phi_p  ~  grad phi_hat + U^{+T} b,    b = D_p - U^T grad phi_hat   (r,)

where ``D_p`` are the measured directional derivatives and ``U^+ = (U^T U)^{-1} U^T``; the constraints
likewise. The privileged directions are the leading left singular vectors of the sensitivity of the model's
Lagrangian gradient to its uncertain parameters (:func:`privileged_directions`): the directions in which
parameter uncertainty moves the optimality conditions most.

:class:`DirectionalGradient` fits ``b`` from any plant points, not only perturbations along ``U``: with
``dc_j = c_j - c_k`` and ``z_j = U^+ dc_j`` (coordinates in the direction basis), first order gives
``f(c_j) - f(c_k) - grad_hat^T dc_j = b^T z_j``. A past operating point (an earlier iterate or
perturbation) is therefore as good as a planned perturbation once its ``z_j`` are well conditioned, and later
iterations need no perturbation experiment at all.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ._nlp import RealizationNLP
from .gradients import GradientEstimate, GradientEstimator, PlantPoint, _positive
from .problem import ModelProblem
from .settings import ModelSettings

__all__ = ["DirectionalGradient", "PrivilegedDirections", "privileged_directions", "lagrangian_gradient"]


class DirectionalGradient(GradientEstimator):
    """Plant gradients along privileged directions (DMA), the model's gradient in the other directions.

    Args:
        directions: ``U``, shape (n_c, r) with 1 <= r <= n_c, columns = directions in setpoint units
            (linearly independent; e.g. :attr:`PrivilegedDirections.directions`).
        step: perturbation ``c_k + step * d_j`` along each direction (multiples of the column), ``> 0``.
        reuse: fit ``b`` from past plant points when they are well conditioned, instead of planning
            perturbations (needs ``r`` usable points).
        radius: largest usable distance of a past point from ``c_k`` per setpoint, setpoint units (scalar or
            (n_c,)); default ``2 * step * max_j |d_j|`` per setpoint, unbounded for a setpoint that no direction
            moves (its displacement is carried by the model's gradient).
        window: number of most recent usable past points (default ``2 r``).
        rcond_min: threshold, in (0, 1], on the quality of the past points' direction coordinates ``z_j / step``
            for reuse: ``min(s_min, 1) / max(s_max, 1)`` of their singular values, 1 for full steps along every
            direction, smaller for short, long or ill-conditioned ones (also ``GradientEstimate.quality``).

    A perturbation that would leave the setpoint box is taken backwards, and clipped to the box when that leaves it
    too (whichever keeps more of the direction). The fit always uses the setpoints actually flown.
    """

    def __init__(self, directions, step: float = 0.5, reuse: bool = True, radius=None,
                 window: int | None = None, rcond_min: float = 0.2):
        U = np.asarray(directions, dtype=float)
        if U.ndim == 1:
            U = U[:, None]
        if U.ndim != 2 or U.shape[1] < 1 or U.shape[1] > U.shape[0] or not np.all(np.isfinite(U)):
            raise ValueError(f"DirectionalGradient.directions: expected a finite (n_c, r) array with "
                             f"1 <= r <= n_c, got shape {np.shape(directions)}")
        s = np.linalg.svd(U, compute_uv=False)
        if s[-1] <= 1e-12 * s[0]:
            raise ValueError(f"DirectionalGradient.directions: the {U.shape[1]} columns are linearly dependent "
                             f"(singular values {s.tolist()})")
        self.U = U
        self._U_pinv = np.linalg.pinv(U)
        self.step = float(_positive("DirectionalGradient.step", step)[0])
        if not isinstance(reuse, bool):
            raise ValueError(f"DirectionalGradient.reuse={reuse!r}: expected True or False")
        self.reuse = reuse
        self._radius_arg = radius
        if radius is None:
            reach = 2.0 * self.step * np.max(np.abs(U), axis=1)
            self.radius = np.where(reach > 0, reach, np.inf)
        else:
            self.radius = _positive("DirectionalGradient.radius", radius)
            if self.radius.size not in (1, U.shape[0]):
                raise ValueError(f"DirectionalGradient.radius={radius!r}: expected 1 or {U.shape[0]} values")
        if window is not None and (isinstance(window, bool) or not isinstance(window, int) or window < 1):
            raise ValueError(f"DirectionalGradient.window={window!r}: expected an integer >= 1 or None")
        self.window = window if window is not None else 2 * U.shape[1]
        if not 0.0 < rcond_min <= 1.0:
            raise ValueError(f"DirectionalGradient.rcond_min={rcond_min!r}: expected a value in (0, 1]")
        self.rcond_min = float(rcond_min)

    @property
    def n_directions(self) -> int:
        return self.U.shape[1]

    def coordinates(self, dc) -> np.ndarray:
        """Direction-basis coordinates ``z = U^+ dc`` of setpoint displacements ``dc`` (n_c,) or (m, n_c)."""
        return np.asarray(dc, dtype=float) @ self._U_pinv.T

    def _rcond(self, z: np.ndarray) -> float:
        if z.shape[0] < self.n_directions:
            return 0.0
        s = np.linalg.svd(z / self.step, compute_uv=False)
        return float(min(s[-1], 1.0) / max(s[0], 1.0)) if s[0] > 0 else 0.0

    def _select(self, c_k, past):
        radius = np.broadcast_to(self.radius, c_k.shape)
        chosen = []
        for pt in reversed(list(past)):
            dc = np.asarray(pt.c, float) - c_k
            if np.max(np.abs(dc) / radius) <= 1.0 and np.linalg.norm(self.coordinates(dc)) > 1e-9 * self.step:
                chosen.append(pt)
            if len(chosen) == self.window:
                break
        z = self.coordinates(np.array([np.asarray(p.c, float) - c_k for p in chosen]).reshape(-1, c_k.size))
        return chosen, self._rcond(z)

    def plan(self, c_k, lb, ub, past=()):
        """One point per direction: ``c_k + step * d_j`` clipped to the box, or backwards where the backward step
        keeps more of the direction than the forward one (none when past points can be reused)."""
        c_k = np.asarray(c_k, float)
        if self.reuse and self._select(c_k, past)[1] >= self.rcond_min:
            return []
        points = []
        for d in self.U.T:
            cands = [np.clip(c_k + sign * self.step * d, lb, ub) for sign in (1.0, -1.0)]
            kept = [self._kept(c_k, c, d) for c in cands]
            # the backward step only when it keeps more than rounding does (both full steps inside the box differ
            # by ~1e-16, and argmax would pick a side at random)
            points.append(cands[1] if kept[1] > kept[0] * (1.0 + 1e-9) else cands[0])
        return points

    def _kept(self, c_k, x, d) -> float:
        """The fraction of the direction's step ``step * d`` that the point ``x`` keeps: its displacement from
        ``c_k`` projected on the step, in direction coordinates (1 for the whole step, less when clipped)."""
        full = self.coordinates(self.step * d)
        return abs(float(self.coordinates(x - c_k) @ full)) / float(full @ full)

    def estimate(self, c_k, nominal: PlantPoint, new: Sequence[PlantPoint], past=(), model=None):
        """The DMA gradient at ``c_k``; ``model`` supplies ``grad_phi`` (n_c,) and ``jac_g`` (n_g, n_c) there
        (a :class:`~kite_rto.gma.ModelRealization`)."""
        c_k = np.asarray(c_k, float)
        n_c, n_g = c_k.size, np.size(nominal.constraints)
        if model is None:
            raise ValueError("DirectionalGradient.estimate needs the model gradients at c_k (model=...)")
        g_phi = np.asarray(model.grad_phi, float).ravel()
        j_g = np.asarray(model.jac_g, float).reshape(n_g, n_c)
        pts = list(new) if len(new) else self._select(c_k, past)[0]
        dc = np.array([np.asarray(p.c, float) - c_k for p in pts]).reshape(-1, n_c)
        z = self.coordinates(dc)
        rcond = self._rcond(z)
        nan = GradientEstimate(np.full(n_c, np.nan), np.full((n_g, n_c), np.nan), 0.0, None,
                               "directional", "")
        if rcond <= 0.0 or not (np.all(np.isfinite(g_phi)) and np.all(np.isfinite(j_g))):
            nan.notes = ("the model gradients at c_k are not finite" if rcond > 0 else
                         f"{len(pts)} points do not span the {self.n_directions} privileged directions")
            return nan
        resid = np.column_stack([
            [p.cost - nominal.cost for p in pts] - dc @ g_phi,
            np.array([np.asarray(p.constraints, float) - np.asarray(nominal.constraints, float)
                      for p in pts]).reshape(len(pts), n_g) - dc @ j_g.T])
        b, *_ = np.linalg.lstsq(z, resid, rcond=None)           # (r, 1 + n_g): directional corrections
        corr = self._U_pinv.T @ b                               # (n_c, 1 + n_g), in span(U)
        std = None
        if nominal.cost_std is not None:
            cov_b = np.linalg.pinv(z.T @ z) * 2.0 * nominal.cost_std ** 2
            std = np.sqrt(np.maximum(np.diag(self._U_pinv.T @ cov_b @ self._U_pinv), 0.0))
        source = "perturbations" if len(new) else "past points"
        return GradientEstimate(g_phi + corr[:, 0], j_g + corr[:, 1:].T, rcond, std,
                                f"directional ({self.n_directions} of {n_c})",
                                f"{len(pts)} {source}, b = {np.round(b[:, 0], 6).tolist()}", dc)


@dataclass
class PrivilegedDirections:
    """Result of :func:`privileged_directions`.

    Attributes:
        directions: (n_c, r) columns in setpoint units, each of unit length in scaled coordinates ``c / scale``.
        scaled: (n_c, r) the same directions in scaled coordinates (orthonormal).
        singular_values: the singular values of the scaled sensitivity in the free setpoints, descending
            (cost units per scaled setpoint unit).
        captured: fraction of that sensitivity's squared Frobenius norm captured by the r directions.
        sensitivity: (n_c, n_theta) the Lagrangian-gradient change per parameter deviation, cost units per
            setpoint unit (all setpoints).
        gradient: (n_c,) the nominal Lagrangian gradient, cost units per setpoint unit.
        fixed: (n_c,) bool, setpoints held at a robustly active bound (no direction moves them).
    """

    directions: np.ndarray
    scaled: np.ndarray
    singular_values: np.ndarray
    captured: float
    sensitivity: np.ndarray
    gradient: np.ndarray
    fixed: np.ndarray


def privileged_directions(lagrangian_gradient: Callable[[np.ndarray], np.ndarray], theta0, deviations,
                          n_directions: int, scale=None, at_bound=None,
                          robust_margin: float = 0.5) -> PrivilegedDirections:
    """The ``n_directions`` setpoint directions in which parameter uncertainty moves the model's optimality
    conditions most (DMA's privileged directions).

    Args:
        lagrangian_gradient: ``theta -> grad_c L`` (n_c,): the gradient with respect to the setpoints of the
            model's Lagrangian ``phi_hat + nu^T g_hat`` at a fixed operating point (usually the model
            optimum, with its multipliers ``nu``), for model parameters ``theta``.
        theta0: nominal parameters (n_theta,).
        deviations: a plausible deviation of each parameter (n_theta,), nonzero; the sensitivity is the
            forward difference over it, so a one-sided uncertainty (a parameter that can only grow) is given
            with its sign.
        n_directions: r, at least 1 and at most the number of free setpoints.
        scale: setpoint scale (n_c,) > 0, e.g. the box width; the SVD is taken in ``c / scale``.
        at_bound: (n_c,) -1 / 0 / +1: setpoint at its lower bound / free / at its upper bound at the
            operating point. A bound is **robustly active** when the gradient keeps pushing against it for
            every deviation, by more than ``robust_margin`` times its change (for a minimization, a positive
            component at a lower bound, a negative one at an upper bound). Such setpoints stay at their bound
            whatever the parameters are, so their plant derivative is not needed and the directions are
            sought among the other setpoints only.
        robust_margin: in (0, 1]; larger keeps fewer bounds as robust.
    """
    theta0 = np.asarray(theta0, dtype=float).ravel()
    dev = np.asarray(deviations, dtype=float).ravel()
    if dev.size != theta0.size or not np.all(np.isfinite(dev)) or np.any(dev == 0):
        raise ValueError(f"privileged_directions: deviations={deviations!r}: expected {theta0.size} finite "
                         f"nonzero values")
    if not 0.0 < robust_margin <= 1.0:
        raise ValueError(f"privileged_directions: robust_margin={robust_margin!r}: expected a value in (0, 1]")
    g0 = np.asarray(lagrangian_gradient(theta0), dtype=float).ravel()
    n_c = g0.size
    side = np.zeros(n_c) if at_bound is None else np.asarray(at_bound, dtype=float).ravel()
    if side.size != n_c or not np.all(np.isin(side, (-1.0, 0.0, 1.0))):
        raise ValueError(f"privileged_directions: at_bound={at_bound!r}: expected {n_c} values in -1, 0, +1")
    w = np.ones(n_c) if scale is None else _positive("privileged_directions: scale", scale)
    if w.size not in (1, n_c):
        raise ValueError(f"privileged_directions: scale={scale!r}: expected 1 or {n_c} values")
    w = np.broadcast_to(w, (n_c,)).astype(float)
    cols = []
    for j in range(theta0.size):
        th = theta0.copy()
        th[j] += dev[j]
        cols.append(np.asarray(lagrangian_gradient(th), dtype=float).ravel() - g0)
    S = np.column_stack(cols)
    if not (np.all(np.isfinite(S)) and np.all(np.isfinite(g0))):
        raise ValueError("privileged_directions: the Lagrangian gradient is not finite for some parameters")
    push = -side * g0                                   # > 0: the gradient presses the setpoint onto its bound
    fixed = (side != 0) & (push > 0) & (push * robust_margin > np.max(np.abs(S), axis=1))
    free = ~fixed
    n_free = int(free.sum())
    if isinstance(n_directions, bool) or not isinstance(n_directions, int) or not 1 <= n_directions <= n_free:
        raise ValueError(f"privileged_directions: n_directions={n_directions!r}: expected an integer in "
                         f"[1, {n_free}] ({n_free} setpoints not at a robustly active bound)")
    Uf, sv, _ = np.linalg.svd((w[:, None] * S)[free], full_matrices=False)   # grad w.r.t. c/scale = scale grad_c
    Us = np.zeros((n_c, n_directions))
    Us[free] = Uf[:, :n_directions]
    Us = Us * np.where(Us.sum(axis=0) < 0, -1.0, 1.0)                # sign convention: components sum >= 0
    total = float(np.sum(sv ** 2))
    captured = float(np.sum(sv[:n_directions] ** 2) / total) if total > 0 else math.nan
    return PrivilegedDirections(directions=w[:, None] * Us, scaled=Us, singular_values=sv, captured=captured,
                                sensitivity=S, gradient=g0, fixed=fixed)


def lagrangian_gradient(problem: ModelProblem, c, nu=None, settings: ModelSettings | None = None) -> np.ndarray:
    """``grad_c (phi_hat + nu^T g_hat)`` (n_c,) of the model's best realization of setpoints ``c``
    (``min phi s.t. y(u) = c``): the cost part from the multipliers of ``y(u) = c``, the constraint part by
    central differences of warm re-solves (step ``settings.fd_step`` of the box width), computed only
    for nonzero multipliers ``nu`` (n_g,). Builds its own NLP.
    Raises ``RuntimeError`` if the model cannot realize ``c``."""
    settings = settings or ModelSettings()
    c = np.asarray(c, dtype=float).ravel()
    nu = np.zeros(problem.n_g) if nu is None else np.asarray(nu, dtype=float).ravel()
    if c.size != problem.n_c or nu.size != problem.n_g:
        raise ValueError(f"lagrangian_gradient: c has {c.size} entries and nu {nu.size}, expected "
                         f"n_c={problem.n_c} and n_g={problem.n_g}")
    nlp = RealizationNLP(problem, settings)
    base = nlp.solve(c)
    if not base.success:
        raise RuntimeError(f"lagrangian_gradient: the model {problem.name!r} cannot realize c = "
                           f"{np.round(c, 6).tolist()} ({base.status})")
    grad = nlp.value_gradient(base)
    if np.any(nu != 0):
        h = settings.fd_step * problem.c_width
        for i in range(problem.n_c):
            dc = np.eye(problem.n_c)[i] * h[i]
            g_pm = []
            for sign in (1.0, -1.0):
                res = nlp.solve(c + sign * dc, base.x, keep=False)
                if not res.success:
                    raise RuntimeError(f"lagrangian_gradient: the re-solve at c[{i}] {sign * h[i]:+g} failed "
                                       f"({res.status})")
                g_pm.append(problem.evaluate(res.x)[1])
            grad[i] += float(nu @ (g_pm[0] - g_pm[1])) / (2.0 * h[i])
    return grad
