"""A synchronous offline loop on top of the request/submit interface of :class:`~kite_rto.gma.GMA`."""
from __future__ import annotations

from typing import Callable

import numpy as np

from .gma import GMA
from .records import ExperimentResult, History

__all__ = ["run_offline"]


def run_offline(gma: GMA, plant_fn: Callable, n_iter: int, stop_on_convergence: bool = False) -> History:
    """Run ``n_iter`` GMA iterations against a plant function and return ``gma.history``.

    Args:
        gma: the GMA object (fresh or resumed).
        plant_fn: ``plant_fn(c) -> (cost, constraints)`` with ``c`` shape (n_c,), ``constraints`` shape
            (n_g,); it may also return an :class:`ExperimentResult` (its ``request_id`` is overwritten), to
            pass standard deviations.
        n_iter: number of iterations to complete, ``>= 0``.
        stop_on_convergence: stop early once an iteration reports ``converged``.
    """
    if isinstance(n_iter, bool) or not isinstance(n_iter, int) or n_iter < 0:
        raise ValueError(f"run_offline: n_iter={n_iter!r}: expected an integer >= 0")
    done = 0
    while done < n_iter:
        req = gma.next_request()
        if req is None:
            break
        out = plant_fn(np.array(req.c, dtype=float))
        if isinstance(out, ExperimentResult):
            out.request_id = req.request_id
            result = out
        else:
            cost, constraints = out
            result = ExperimentResult(req.request_id, float(cost), np.atleast_1d(constraints))
        record = gma.submit(result)
        if record is not None:
            done += 1
            if stop_on_convergence and record.converged:
                break
    return gma.history
