"""Make the kite's :class:`~kite_rto.gma.GMA`: the lap OCP in shape coordinates, its model-only optimum, the
privileged directions, started at the model optimum.

GMA works in shape coordinates ``x = (theta_0, A_phi, aspect)`` over a :class:`~kite_rto.flight.shape.ShapeBox`
(every point of it is trackable; the trackable set is a curved band in setpoints). GMA's records hold ``x``;
:func:`~kite_rto.flight.shape.setpoints_from_shape` turns them into setpoints ``c = (theta_0, A_phi, A_theta)``,
rad. The OCP and the model optimum take seconds to build and solve, so they are cached per process.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..gma import GMA, PrivilegedDirections
from ..flight.shape import ShapeBox, setpoints_from_shape, shape_from_setpoints
from ..kite.params import KiteParams
from .directions import bound_activity_for, privileged_directions_for
from .ocp import KiteOCPSettings, model_problem
from .settings import KiteRTOSettings
from .startup_cache import cached, directions_from_json, directions_to_json

__all__ = ["lap_problem", "ModelOptimum", "model_only_optimum", "bound_activity", "gma_directions", "make_gma"]


@lru_cache(maxsize=4)
def _lap_problem(box: ShapeBox, model_params: KiteParams, ocp: KiteOCPSettings, h_min: float):
    return model_problem(model_params, ocp, c_lb=box.lower(), c_ub=box.upper(),
                         c_guess=0.5 * (box.lower() + box.upper()), name="kite_lap", shape=True, h_min=h_min)


def lap_problem(settings: KiteRTOSettings, model_params: KiteParams = KiteParams()):
    """The kite lap OCP of ``settings`` in shape coordinates on its box, with its experiment's h_min (cached per
    process: building it takes seconds)."""
    return _lap_problem(settings.box, model_params, settings.ocp, settings.experiment.h_min)


def _model_key(settings: KiteRTOSettings, model_params: KiteParams) -> tuple:
    """What the model optimum depends on: the box, the model, the OCP and h_min."""
    return settings.box, model_params, settings.ocp, settings.experiment.h_min


@lru_cache(maxsize=4)
def _model_optimum_cached(box, model_params, ocp, h_min) -> tuple:
    """The model optimum's numbers (per process, and on disk: :mod:`.startup_cache`)."""
    return tuple(tuple(v) if isinstance(v, list) else v for v in
                 cached("model-optimum", (box, model_params, ocp, h_min),
                        lambda: _model_optimum(box, model_params, ocp, h_min), to_json=list, from_json=list))


def _model_optimum(box, model_params, ocp, h_min) -> tuple:
    from .ocp_solve import solve_model_optimum
    pr = _lap_problem(box, model_params, ocp, h_min)
    sol = solve_model_optimum(pr)
    x = np.clip(sol.c, box.lower(), box.upper())
    i = pr.equalities.numel() + pr.inner_constraints.numel()
    nu = np.maximum(sol.lam_g[i:i + pr.n_g], 0.0)        # multipliers of g(u) <= 0 at the model optimum
    return (tuple(setpoints_from_shape(x).tolist()), sol.mean_tension_kn, sol.min_altitude, tuple(x.tolist()),
            tuple(nu.tolist()))


@dataclass(frozen=True)
class ModelOptimum:
    """The model's own optimum in a box (a failed solve raises :class:`~kite_rto.rto.ocp_solve.OCPSolveError`).

    Attributes:
        c: setpoints (theta_0, A_phi, A_theta), rad, shape (3,).
        mean_tension_kn: the model's mean tension there, kN.
        min_altitude: the model's lowest altitude over the lap, m.
    """

    c: np.ndarray
    mean_tension_kn: float
    min_altitude: float


def model_only_optimum(settings: KiteRTOSettings, model_params: KiteParams = KiteParams()) -> ModelOptimum:
    """The :class:`ModelOptimum` of ``settings`` (its box, OCP and h_min; cached per process)."""
    c, t, z, _, _ = _model_optimum_cached(*_model_key(settings, model_params))
    return ModelOptimum(np.array(c), t, z)


def gma_directions(settings: KiteRTOSettings, model_params: KiteParams = KiteParams()) -> PrivilegedDirections:
    """The :class:`~kite_rto.gma.PrivilegedDirections` of ``settings`` (shape coordinates), computed at the
    model optimum in ``settings.box`` (cached on disk by :mod:`.startup_cache`; about 10 s to compute)."""
    _, _, _, x_opt, nu = _model_optimum_cached(*_model_key(settings, model_params))
    held = bound_activity(settings, model_params)
    key = (settings.box, x_opt, nu, model_params, settings.ocp, settings.experiment.h_min, settings.uncertainty,
           settings.n_directions, held)
    return cached("directions", key, lambda: privileged_directions_for(*key), to_json=directions_to_json,
                  from_json=directions_from_json)


def bound_activity(settings: KiteRTOSettings, model_params: KiteParams = KiteParams()) -> tuple:
    """Per shape coordinate -1 / 0 / +1: the box bound the model's constrained optimum keeps under every
    deviation of ``settings.uncertainty`` and the tightened altitude constraint (:func:`bound_activity_for`;
    cached on disk, about a minute to compute)."""
    _, _, _, x_opt, _ = _model_optimum_cached(*_model_key(settings, model_params))
    key = (settings.box, x_opt, model_params, settings.ocp, settings.experiment.h_min, settings.uncertainty)
    return tuple(cached("bound-activity", key, lambda: [int(v) for v in bound_activity_for(*key).at_bound]))


def make_gma(settings: KiteRTOSettings | None = None, model_params: KiteParams | None = None, c0=None,
             history=None) -> GMA:
    """A :class:`GMA` on the kite lap model of ``settings`` in shape coordinates, started at setpoints ``c0`` (rad;
    default: ``settings.c0``, else the model optimum), or resumed from ``history``."""
    settings = settings or KiteRTOSettings()
    model_params = model_params or KiteParams()
    problem = lap_problem(settings, model_params)
    if c0 is None:
        c0 = settings.c0 if settings.c0 is not None else model_only_optimum(settings, model_params).c
    x0 = np.clip(shape_from_setpoints(c0), settings.box.lower(), settings.box.upper())
    directions = gma_directions(settings, model_params).directions if settings.gradient == "directional" \
        else None
    return GMA(problem, settings.gma, settings.gradient_estimator(directions), c0=x0, history=history)
