"""What an operator did to a run, kept in its database's event log (:meth:`~kite_rto.gma.HistoryStore.events`).

Two kinds of events, written by the optimizer node (lifecycle transitions) and :class:`~.optimizer_run.OptimizerRun`
(manual setpoints):

- ``transition``: ``{"transition": label, "from": state, "to": state, "t": sim s or null}``, one per lifecycle
  transition that succeeded (``configure``, ``activate``, ``deactivate``, ``cleanup``, ``shutdown``);
- ``manual_setpoints``: ``{"c": [theta_0, A_phi, A_theta] rad, "x": shape coordinates, "requests": ids, "t": sim s
  or null}``, stored in the same transaction as the open iteration's new requests.

:func:`was_paused` tells a restarted optimizer whether its run was paused: the last ``activate`` or ``deactivate``
it stored was a ``deactivate`` (a node stopped or shut down while inactive stays paused). :func:`setpoints_error`
checks an operator's setpoints as GMA's own are checked.
"""
from __future__ import annotations

import math

import numpy as np

from ..flight.path import SetpointError, validate_setpoints
from ..flight.shape import shape_from_setpoints
from ..kite.params import KiteParams
from .run_status import degrees

__all__ = ["MANUAL", "TRANSITION", "transition_event", "was_paused", "setpoints_error"]

TRANSITION = "transition"
MANUAL = "manual_setpoints"


def transition_event(label: str, start: str, goal: str, t: float | None) -> tuple[str, dict]:
    """The event of the lifecycle transition ``label`` from state ``start`` to ``goal`` at sim time ``t`` s."""
    return TRANSITION, {"transition": label, "from": start, "to": goal, "t": t}


def was_paused(events) -> bool:
    """True when the last ``activate``/``deactivate`` transition in ``events`` ((kind, data, ...) tuples, oldest
    first) is a ``deactivate``."""
    for kind, data, *_ in reversed(list(events)):
        if kind == TRANSITION and data.get("transition") in ("activate", "deactivate"):
            return data["transition"] == "deactivate"
    return False


def setpoints_error(c, box, lb, ub) -> str:
    """Why an operator's setpoints ``c`` = (theta_0, A_phi, A_theta) rad are refused ("" if they are not): outside
    the safe ``box`` or the turn limit, or their shape coordinates (theta_0 rad, A_phi rad, aspect) outside the
    optimizer's box ``[lb, ub]``."""
    try:
        c = np.asarray(c, dtype=float)
        if c.shape != (3,):
            raise SetpointError(f"setpoints = {c.tolist()}: expected 3 values (theta_0, A_phi, A_theta) rad")
        validate_setpoints(c, box, KiteParams())
    except (SetpointError, ValueError, TypeError) as err:
        return str(err)
    x = shape_from_setpoints(c)
    for name, v, lo, hi, deg in zip(("theta_0", "A_phi", "aspect"), x, lb, ub, (True, True, False)):
        if not lo <= v <= hi:
            f = (lambda a: f"{math.degrees(a):.4g} deg") if deg else (lambda a: f"{a:.4g}")
            return (f"setpoints {degrees(c)}: shape coordinate {name} = {f(v)}: outside the optimizer's box "
                    f"[{f(lo)}, {f(hi)}]")
    return ""
