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

from ..gma import GMASettings, PrivilegedDirections, lagrangian_gradient, privileged_directions
from .ocp import KiteOCPSettings, model_problem
from ..kite.params import KiteParams, ParameterError
from ..flight.shape import ShapeBox

__all__ = ["ModelUncertainty", "privileged_directions_for"]


@dataclass(frozen=True)
class ModelUncertainty:
    """Plausible deviations of the model parameters from their nominal values (a prior, not the plant's values).

    Attributes:
        E: glide ratio, dimensionless (a real kite is often less efficient than its nominal polar).
        g_s: turning constant, rad/m.
        shear: wind-shear exponent, dimensionless.
        c_E: glide loss when steering, dimensionless (one-sided: the nominal model has none).
    """

    E: float = -0.5
    g_s: float = -0.005
    shear: float = 0.05
    c_E: float = 1.0

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v == 0:
                raise ParameterError(f"ModelUncertainty.{f.name} = {v!r}: expected a finite nonzero deviation")

    def names(self) -> list[str]:
        return [f.name for f in fields(self)]

    def values(self) -> list[float]:
        return [float(getattr(self, n)) for n in self.names()]


def _at_bound(x, lb, ub, tol: float = 1e-6) -> np.ndarray:
    w = ub - lb
    return np.where(x <= lb + tol * w, -1, np.where(x >= ub - tol * w, 1, 0))


@lru_cache(maxsize=8)
def privileged_directions_for(box: ShapeBox, x0: tuple, nu: tuple, model_params: KiteParams = KiteParams(),
                               ocp: KiteOCPSettings = KiteOCPSettings(),
                               uncertainty: ModelUncertainty = ModelUncertainty(),
                               n_directions: int = 2) -> PrivilegedDirections:
    """DMA's privileged directions (shape coordinates) at the model optimum ``x0`` with constraint multipliers
    ``nu`` (tuples, for the cache); one realization NLP per uncertain parameter and one nominal, about 2 s each."""
    x0 = np.asarray(x0, dtype=float)
    nu = np.asarray(nu, dtype=float)
    settings, names = GMASettings(), uncertainty.names()

    def gradient(theta):
        params = replace(model_params, **dict(zip(names, (float(t) for t in theta))))
        problem = model_problem(params, ocp, c_lb=box.lower(), c_ub=box.upper(), c_guess=x0,
                                     name="kite_dma", shape=True)
        return lagrangian_gradient(problem, x0, nu, settings)

    theta0 = [float(getattr(model_params, n)) for n in names]
    return privileged_directions(gradient, theta0, uncertainty.values(), n_directions,
                                 scale=box.upper() - box.lower(),
                                 at_bound=_at_bound(x0, box.lower(), box.upper()))
