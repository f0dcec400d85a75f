"""Leaving a bound of the setpoint box only on measured evidence.

Near an optimum on or close to a bound of the box the measured slope there is mostly noise, and a model without
curvature in that setpoint turns it into a step to the trust region's edge. From iteration ``after`` on, the
setpoints at a bound that an earlier step reached (not the bounds the run started on: those are the model's claim,
which the measurements must be able to overrule) are held there (zero trust radius in them) while the held
modified problem's multiplier of each, the modified Lagrangian's descent into the box, constraints included, is
below ``sigma`` standard deviations of the filtered cost modifier; a setpoint above it is released and the rest
solved again, once. Measured on the kite: fewer runs that lose the optimum again at a bound (docs/history.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._checks import check_int, check_range
from .mechanism import Iteration, Mechanism

__all__ = ["BoundHold", "bound_side"]


@dataclass(frozen=True)
class BoundHold:
    """Settings of the bound hold.

    Attributes:
        sigma: standard deviations of the filtered cost modifier the descent into the box must exceed, ``>= 0``.
        after: the first iteration that holds bounds (integer ``>= 0``): before it the filtered modifier has too
            few estimates for its standard deviation to measure the noise.
    """

    sigma: float = 2.0
    after: int = 2

    def __post_init__(self):
        n = type(self).__name__
        check_range(n, "sigma", self.sigma, 0.0, None)
        check_int(n, "after", self.after, 0)

    def build(self, problem) -> "BoundHoldMechanism":
        return BoundHoldMechanism(self)


def bound_side(c, lb, ub, tol) -> np.ndarray:
    """(n_c,) -1 / 0 / +1: ``c`` within ``tol`` box widths of its lower bound / inside / within ``tol`` of its upper
    bound."""
    w = ub - lb
    return np.where(c <= lb + tol * w, -1, np.where(c >= ub - tol * w, 1, 0))


class BoundHoldMechanism(Mechanism):
    """Replaces the modified problem's solution by the held one where holding is not measurably wrong."""

    def __init__(self, settings: BoundHold):
        self.settings = settings

    def solve(self, it: Iteration, solve) -> None:
        s, pr, res = self.settings, it.problem, it.result
        if it.k < s.after or not res.success:
            return
        side = bound_side(it.c_k, pr.c_lb, pr.c_ub, 1e-9)
        side = np.where(side == bound_side(it.history.c0, pr.c_lb, pr.c_ub, 1e-9), 0, side)
        held = side != 0
        limit = s.sigma * np.nan_to_num(np.asarray(it.modifier_std, float), nan=np.inf)
        for _ in range(2):
            if not held.any():
                return
            kept = solve(np.where(held, 0.0, it.radius))
            if not kept.success:
                return
            inward = -side * np.asarray(kept.lam_g[pr.n_g: pr.n_g + pr.n_c], float)   # > 0: wants into the box
            keep = held & (inward < limit)
            if np.array_equal(keep, held):
                it.notes.append(f"bound held: c{np.flatnonzero(held).tolist()} stay at their bounds (the modified "
                                f"Lagrangian's descent into the box, {np.round(inward[held], 4).tolist()}, is below "
                                f"{s.sigma:g} standard deviations)")
                it.result = kept
                return
            held = keep
