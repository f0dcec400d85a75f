"""What the optimizer run shows on its status (``/rto/status``) and in its log: setpoints in degrees, vectors in
4 significant digits, and the status key/values of a run (:func:`status_values`; docs/interface.md lists them)."""
from __future__ import annotations

import math

import numpy as np

from ..flight.shape import setpoints_from_shape

__all__ = ["degrees", "shape_degrees", "status_values", "vector_text"]


def shape_degrees(x) -> str:
    """Setpoints in degrees of GMA's shape coordinates ``x``."""
    return degrees(setpoints_from_shape(x))


def degrees(c) -> str:
    """Setpoints ``c`` (rad) in degrees."""
    return "(" + ", ".join(f"{math.degrees(v):.2f}" for v in c) + ") deg"


def vector_text(v) -> str:
    """A vector in 4 significant digits, as the status shows it."""
    return "[" + ", ".join(f"{x:.4g}" for x in np.asarray(v, dtype=float).ravel()) + "]"


def status_values(run) -> dict:
    """The status of ``run`` (an :class:`~kite_rto.runtime.optimizer_run.OptimizerRun`) as key -> value (str or
    number): iteration, phase, the current experiment, the last record."""
    req = run.session.request
    kv = {"iteration": len(run.gma.records), "phase": run.phase, "experiments_done": len(run.gma.history.experiments)}
    if run.manual_note:
        kv["manual_setpoints"] = run.manual_note
    if run.persist.error:
        kv["storage_error"] = run.persist.error
    if req is not None:
        kv.update(experiment=req.request_id, purpose=req.purpose, setpoints_deg=shape_degrees(req.c),
                  experiment_t_start=f"{run.session.evaluator.t_start:.2f}")
    if run.gma.records:
        r = run.gma.records[-1]
        kv.update(measured_cost_kN=f"{r.cost:.2f}", measured_constraint_m=f"{r.constraints[0]:.2f}",
                  grad_cost=vector_text(r.grad_cost), grad_constraint=vector_text(r.jac_constraints.ravel()),
                  eps=vector_text(r.eps), lambda_=vector_text(r.lam), mu=vector_text(r.mu.ravel()),
                  c_star_deg=shape_degrees(r.c_star), c_next_deg=shape_degrees(r.c_next), decision=r.decision)
    return {k.rstrip("_"): v for k, v in kv.items()}
