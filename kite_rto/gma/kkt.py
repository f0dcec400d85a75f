"""The measured-KKT test at a held bound (issue #14 item 2; ``GMASettings.structure_kkt``).

At a stalled iterate ``c_k`` where DMA holds a setpoint at its bound (no privileged direction moves it), the
model claims that the bound's multiplier is positive: the plant's Lagrangian ``L_p = phi_p + nu^T g_p`` grows when
the setpoint leaves the bound. A structure experiment (:func:`~kite_rto.gma.structure_plan`) that moves the
setpoint off the bound, by ``dc`` into the box, measures

    dL = phi_p(c_k + dc) - phi_p(c_k) + nu^T (g_p(c_k + dc) - g_p(c_k))  ~  grad L_p^T dc,

with ``nu >= 0`` the modified problem's constraint multipliers at ``c_k`` (the estimate of the plant's). At a plant
KKT point ``grad L_p^T dc`` is the bound's multiplier times the distance moved off it, ``>= 0``. A ``dL`` below
``-sigma`` standard errors has the wrong sign: the plant wants to leave the bound, and GMA restores the
direction. The second-order term ``0.5 dc^T H dc`` of a convex Lagrangian makes ``dL`` larger, so the test errs on
the side of holding.

The mismatch test (:func:`~kite_rto.gma.structure_test`) checks the cost and each constraint separately against a
threshold with a relative part; it can pass while their combination, the Lagrangian, has already changed sign (a
constraint slope wrong by less than ``structure_rel_tol`` at a bound where the cost and ``nu`` times the constraint
nearly cancel). This test looks at the sign, in standard errors only.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .gradients import PlantPoint
from .structure import bound_side

__all__ = ["KKTTest", "kkt_test"]


@dataclass
class KKTTest:
    """One measured-KKT test (:func:`kkt_test`).

    Attributes:
        dc: the displacement flown, ``c - c_k`` (n_c,), setpoint units.
        held: indices of the setpoints that ``dc`` moves off the bound they sit at.
        sides: (len(held),) -1 lower / +1 upper bound of each.
        change: the measured Lagrangian change ``dL``, cost units.
        std: its standard error, cost units (0 without measured standard deviations).
        threshold: ``sigma * std``: ``dL < -threshold`` is a wrong sign.
        wrong_sign: the plant wants to leave the bound.
    """

    dc: np.ndarray
    held: list[int]
    sides: list[int]
    change: float
    std: float
    threshold: float
    wrong_sign: bool

    def describe(self) -> str:
        """One line for ``IterationRecord.notes``."""
        where = ", ".join(f"c[{i}] ({'lower' if s < 0 else 'upper'})" for i, s in zip(self.held, self.sides))
        verdict = ("multiplier sign wrong, the plant leaves the bound: direction restored" if self.wrong_sign
                   else "multiplier sign agrees")
        return (f"measured KKT at the held bound {where} along dc={np.round(self.dc, 6).tolist()}: Lagrangian "
                f"change {self.change:+.4g} (std {self.std:.3g}, threshold -{self.threshold:.3g}): {verdict}")


def kkt_test(c_k, nominal: PlantPoint, point: PlantPoint, nu, c_lb, c_ub, sigma: float,
             tol: float = 1e-6) -> KKTTest | None:
    """The sign of the plant Lagrangian's change from ``nominal`` (at ``c_k``) to ``point``; ``None`` unless the
    move takes some setpoint that sits within ``tol`` box widths of a bound off it.

    Args:
        nu: (n_g,) constraint multipliers (negative entries count as 0).
        sigma: significance in standard errors; the standard error combines both points' ``cost_std`` and
            ``constraints_std`` (``nu``-weighted), 0 where they are not given.
    """
    c_k = np.asarray(c_k, float)
    lb, ub = np.asarray(c_lb, float), np.asarray(c_ub, float)
    dc = np.asarray(point.c, float) - c_k
    side = bound_side(c_k, lb, ub, tol)
    held = np.flatnonzero((side != 0) & (side * dc < 0))
    if held.size == 0:
        return None
    nu = np.maximum(np.asarray(nu, float).ravel(), 0.0)
    d_cost = point.cost - nominal.cost
    d_g = float(nu @ (np.asarray(point.constraints, float) - np.asarray(nominal.constraints, float)))

    def var(s, n):
        return np.zeros(n) if s is None else np.broadcast_to(np.square(np.asarray(s, float)), (n,))

    v = float(np.sum(var(nominal.cost_std, 1) + var(point.cost_std, 1)))
    v += float(nu ** 2 @ (var(nominal.constraints_std, nu.size) + var(point.constraints_std, nu.size)))
    change, std = d_cost + d_g, float(np.sqrt(v))
    threshold = sigma * std
    wrong = change < -threshold - 1e-12 * (abs(d_cost) + abs(d_g))      # rounding is not a sign
    return KKTTest(dc, held.tolist(), side[held].astype(int).tolist(), float(change), std, float(threshold),
                   bool(wrong))
