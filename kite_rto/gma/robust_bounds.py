"""Robustly active bounds: which bounds of the setpoint box the model's constrained optimum keeps over the
uncertainty of its parameters and constraints (:func:`robust_bounds`).

A setpoint at a robustly active bound needs no plant derivative (:func:`~kite_rto.gma.privileged_directions` leaves
it out). The test runs **with the constraints**: a bound is robustly active only if the model's constrained optimum
stays on it for every parameter deviation and for every constraint shifted by its plausible error. A gradient-only
test at the model optimum misses a constraint that is inactive there but, once active, pulls the setpoint off its
bound.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ._nlp import ModifiedNLP
from .bound_hold import bound_side
from .modifiers import Modifiers
from .problem import ModelProblem
from .settings import ModelSettings

__all__ = ["BoundActivity", "robust_bounds", "model_optimum"]


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


def model_optimum(problem: ModelProblem, offsets=None, settings: ModelSettings | None = None) -> np.ndarray:
    """``y(u)`` (n_c,) at the optimum of ``problem`` with its constraints shifted, ``g(u) + offsets <= 0``
    (``offsets`` (n_g,), constraint units; ``None`` or empty = none), inside the setpoint box. Builds its own NLP
    with the solver ``settings``. ``RuntimeError`` if the solve fails."""
    settings = settings or ModelSettings()
    off = np.zeros(problem.n_g) if offsets is None or np.size(offsets) == 0 else \
        np.asarray(offsets, dtype=float).ravel()
    if off.size != problem.n_g:
        raise ValueError(f"model_optimum: offsets has {off.size} entries, expected n_g={problem.n_g}")
    mid = 0.5 * (problem.c_lb + problem.c_ub)
    mods = Modifiers(mid, off, np.zeros(problem.n_c), np.zeros((problem.n_g, problem.n_c)), np.zeros(problem.n_g))
    res = ModifiedNLP(problem, settings).solve(mods, radius=np.full(problem.n_c, np.inf), x0=problem.u0)
    if not res.success:
        raise RuntimeError(f"model_optimum: the model {problem.name!r} has no optimum with offsets "
                           f"{off.tolist()} ({res.status})")
    return np.clip(problem.evaluate(res.x[: problem.n_u])[2], problem.c_lb, problem.c_ub)
