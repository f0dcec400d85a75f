"""Privileged directions of the kite for directional modifier adaptation (DMA, ``kite_rto.gma.directional``).

The model's optimality conditions at its own optimum ``x_0`` (shape coordinates ``(theta_0, A_phi, aspect)``)
move with the uncertain model parameters. :func:`privileged_directions_for` re-solves the model's best
realization of ``x_0`` once per parameter of :class:`ModelUncertainty`, each deviated by its plausible amount,
and hands the change of the Lagrangian gradient to :func:`~kite_rto.gma.privileged_directions`.

What it finds on the default box (``benchmarks/bench_rto.py`` prints it): the model optimum sits in the box
corner (30 deg, 42 deg, 0.16). The theta_0 bound is robustly active: the model's gradient there (68 kN per box
width) changes by at most 19 kN under any deviation, so GMA spends no experiment on theta_0. The two privileged
directions span (A_phi, aspect). With a single direction (97.6 % of the sensitivity) the aspect derivative
comes from the model alone and GMA stalls at ~96 % of the oracle: the plant's aspect mismatch comes mostly from
steering dead time and tracking at tight turns, which no model parameter represents.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from functools import lru_cache

import numpy as np

from ..gma import (BoundActivity, ModelSettings, PrivilegedDirections, bound_side, lagrangian_gradient, model_optimum,
                   privileged_directions, robust_bounds)
from .experiment import H_MIN
from .ocp import KiteOCPSettings, model_problem
from ..kite.params import KiteParams, ParameterError
from ..flight.shape import ShapeBox

__all__ = ["ModelUncertainty", "bound_activity_for", "privileged_directions_for"]


@dataclass(frozen=True)
class ModelUncertainty:
    """Plausible deviations of the model parameters from their nominal values: a prior from the literature, not
    the plant's values (docs/theory.md *The prior*).

    Each deviation is the far end of the range the literature reports around the nominal model, on the side a
    real kite usually lies; it is wider than, and not equal to, the default plant's own offset (E -0.4, g_s
    -0.005, shear +0.05, c_E +2), which GMA must not know.

    Attributes:
        E: glide ratio, dimensionless: -1.0 (Erhard & Strauch: "typically 4-5" for the model's 5).
        g_s: turning constant, rad/m: -0.01 (Erhard & Strauch, table II: 0.03-0.05 rad/m around the model's 0.04).
        shear: wind-shear exponent, dimensionless: +0.10 (0.1-0.25 over land; Costello et al. 2017 use 0.15, the
            IEC 61400-1 normal wind profile 0.2, rough terrain more).
        c_E: glide loss when steering, dimensionless: +3.0 (one-sided: the nominal model has none; the do-mpc kite
            example's loss E_0 - 0.028 u^2 is several units of E at large steering inputs, and 3 keeps the glide
            ratio positive at full steering for E >= 4).
        altitude_error: how much higher than the plant the model may put the lap's minimum altitude, m (> 0):
            25 m. The c_E prior alone takes the model's best realization of its own optimum from 21.8 m above
            h_min onto the constraint, so the constraint's pull must be considered when deciding which bounds
            are robustly active (:func:`bound_activity_for`).
    """

    E: float = -1.0
    g_s: float = -0.01
    shear: float = 0.10
    c_E: float = 3.0
    altitude_error: float = 25.0

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v == 0:
                raise ParameterError(f"ModelUncertainty.{f.name} = {v!r}: expected a finite nonzero deviation")
        if self.altitude_error < 0:
            raise ParameterError(f"ModelUncertainty.altitude_error = {self.altitude_error!r}: expected a "
                                 "positive altitude error, m")

    def names(self) -> list[str]:
        """The uncertain model parameters (:class:`KiteParams` fields), in order."""
        return [f.name for f in fields(self) if f.name != "altitude_error"]

    def values(self) -> list[float]:
        return [float(getattr(self, n)) for n in self.names()]


@lru_cache(maxsize=8)
def bound_activity_for(box: ShapeBox, x0: tuple, model_params: KiteParams = KiteParams(),
                       ocp: KiteOCPSettings = KiteOCPSettings(), h_min: float = H_MIN,
                       uncertainty: ModelUncertainty = ModelUncertainty()) -> BoundActivity:
    """Which bounds of ``box`` the model's **constrained** optimum keeps for every deviation of ``uncertainty``
    and with the altitude constraint tightened by ``uncertainty.altitude_error``
    (:func:`~kite_rto.gma.robust_bounds`); one optimum NLP per case (6 on the kite, about 10 s each)."""
    names = uncertainty.names()
    x0 = np.asarray(x0, dtype=float)

    def optimum(theta, offsets):
        params = replace(model_params, **dict(zip(names, (float(t) for t in theta))))
        problem = model_problem(params, ocp, c_lb=box.lower(), c_ub=box.upper(), c_guess=x0,
                                name="kite_activity", shape=True, h_min=h_min)
        return model_optimum(problem, offsets)

    theta0 = [float(getattr(model_params, n)) for n in names]
    return robust_bounds(optimum, theta0, uncertainty.values(), box.lower(), box.upper(),
                         constraint_offsets=(uncertainty.altitude_error / ocp.constraint_unit,), tol=1e-3)


@lru_cache(maxsize=8)
def privileged_directions_for(box: ShapeBox, x0: tuple, nu: tuple, model_params: KiteParams = KiteParams(),
                               ocp: KiteOCPSettings = KiteOCPSettings(), h_min: float = H_MIN,
                               uncertainty: ModelUncertainty = ModelUncertainty(),
                               n_directions: int = 2, at_bound: tuple | None = None) -> PrivilegedDirections:
    """DMA's privileged directions (shape coordinates) at the model optimum ``x0`` with constraint multipliers
    ``nu`` (tuples, for the cache); one realization NLP per uncertain parameter and one nominal, about 2 s each.

    ``at_bound`` (-1 / 0 / +1 per coordinate): the bounds that may be held, e.g.
    :attr:`BoundActivity.at_bound` of :func:`bound_activity_for`; default: every bound ``x0`` sits on (the
    gradient-only test of :func:`~kite_rto.gma.privileged_directions` then decides alone)."""
    x0 = np.asarray(x0, dtype=float)
    nu = np.asarray(nu, dtype=float)
    settings, names = ModelSettings(), uncertainty.names()

    def gradient(theta):
        params = replace(model_params, **dict(zip(names, (float(t) for t in theta))))
        problem = model_problem(params, ocp, c_lb=box.lower(), c_ub=box.upper(), c_guess=x0,
                                name="kite_dma", shape=True, h_min=h_min)
        return lagrangian_gradient(problem, x0, nu, settings)

    theta0 = [float(getattr(model_params, n)) for n in names]
    return privileged_directions(gradient, theta0, uncertainty.values(), n_directions,
                                 scale=box.upper() - box.lower(),
                                 at_bound=bound_side(x0, box.lower(), box.upper(), 1e-6) if at_bound is None
                                 else np.asarray(at_bound))
