"""Trust region: the modified problem is solved inside ``|y(u) - c_k| <= Delta`` (per setpoint), and ``Delta``
adapts to how far the model can be trusted.

Per setpoint, the radius shrinks by ``shrink`` when the step changes sign (the iterate oscillates), when the
modified problem has no solution, or when the plant measured a step as a loss (:mod:`~kite_rto.gma.undo`), and
grows by ``grow`` (up to the initial radius) when the step keeps its sign and reached the bound. Every GMA run in
this repository uses it (a model that is wrong far from ``c_k`` otherwise sends the first step to the box's edge).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._checks import Scalar, check_bool, check_range, per_setpoint
from .mechanism import Iteration, Mechanism
from .modifiers import Decision

__all__ = ["TrustRegion"]


@dataclass(frozen=True)
class TrustRegion:
    """Settings of the trust region; radii relative to the setpoint box width.

    Attributes:
        radius: initial half-width, box widths, ``> 0`` (``inf``: unbounded); scalar or one per setpoint.
        min_radius: the smallest radius adaptation leaves, box widths, ``> 0`` and ``<= radius``.
        shrink: factor in ``(0, 1)`` applied where the model was not to be trusted.
        grow: factor ``>= 1`` applied where a step of unchanged sign reached the bound.
        adapt: shrink on a sign change and grow at the bound (False: only failures and undone steps shrink).
    """

    radius: Scalar = 0.25
    min_radius: float = 0.01
    shrink: float = 0.5
    grow: float = 2.0
    adapt: bool = True

    def __post_init__(self):
        n = type(self).__name__
        check_range(n, "radius", self.radius, 0.0, None, low_open=True, inf_ok=True)
        check_range(n, "min_radius", self.min_radius, 0.0, None, low_open=True)
        check_range(n, "shrink", self.shrink, 0.0, 1.0, low_open=True, high_open=True)
        check_range(n, "grow", self.grow, 1.0, None)
        check_bool(n, "adapt", self.adapt)
        if np.any(np.asarray(self.radius, dtype=float) < self.min_radius):
            raise ValueError(f"{n}.min_radius={self.min_radius!r}: expected <= radius={self.radius!r}")

    def build(self, problem) -> "TrustRegionMechanism":
        return TrustRegionMechanism(self, problem.n_c, problem.c_width)


class TrustRegionMechanism(Mechanism):
    """The trust region's state: the radius per setpoint (box widths) and the last step taken."""

    def __init__(self, settings: TrustRegion, n_c: int, width: np.ndarray):
        self.settings = settings
        self._width = width
        self._radius0 = per_setpoint("TrustRegion.radius", settings.radius, n_c)
        self.radius = self._radius0.copy()
        self._prev_step = np.zeros(n_c)

    def resume(self, history) -> None:
        recs = history.iterations
        if recs:
            self.radius = np.asarray(recs[-1].trust_radius_next, float).copy()
            moved = [r for r in recs if r.outcome.moved or r.outcome is Decision.UNDONE]
            self._prev_step = np.asarray(moved[-1].step, float).copy() if moved else np.zeros_like(self.radius)

    def trust_radius(self) -> np.ndarray:
        return self.radius

    def shrink(self, where=True) -> None:
        s = self.settings
        self.radius = np.where(where, np.maximum(self.radius * s.shrink, s.min_radius), self.radius)

    def adapt(self, it: Iteration) -> None:
        s = self.settings
        if it.target is None and s.adapt:
            flip = it.step * self._prev_step < 0
            hit = (np.abs(it.proposed) >= 0.999 * it.radius) & ~flip
            self.shrink(flip)
            self.radius = np.where(hit, np.minimum(self.radius * s.grow, self._radius0), self.radius)
        if it.decision.moved or it.decision is Decision.UNDONE:
            self._prev_step = it.step
