"""What an operator did to a run, kept in its database's event log (:meth:`~kite_rto.gma.HistoryStore.events`).

Two kinds of events, written by the optimizer node (lifecycle transitions) and :class:`~.optimizer_run.OptimizerRun`
(manual setpoints):

- ``transition``: ``{"transition": label, "from": state, "to": state, "t": sim s or null}``, one per lifecycle
  transition that succeeded (``configure``, ``activate``, ``deactivate``, ``cleanup``, ``shutdown``);
- ``manual_setpoints``: ``{"c": [theta_0, A_phi, A_theta] rad, "x": shape coordinates, "requests": ids, "t": sim s
  or null}``, stored in the same transaction as the open iteration's new requests.

:func:`was_paused` tells a restarted optimizer whether its run was paused: the last ``activate`` or ``deactivate``
it stored was a ``deactivate`` (a node stopped or shut down while inactive stays paused).
"""
from __future__ import annotations

__all__ = ["MANUAL", "TRANSITION", "transition_event", "was_paused"]

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
