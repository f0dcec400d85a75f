"""Shape coordinates of the figure-eight and the optimizer's box in them (:class:`ShapeBox`).

Shape coordinates ``x = (theta_0, A_phi, aspect)`` replace ``A_theta`` by ``aspect = A_theta / sqrt(sin theta_0
A_phi)``: the trackable figure-eights, a curved band in setpoints (:class:`~kite_rto.flight.path.SetpointBox`),
are nearly a slab in shape coordinates, so a box in them holds only trackable figures.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from .path import SetpointBox, SetpointError

__all__ = ["ShapeBox", "shape_from_setpoints", "setpoints_from_shape"]


def _sqrt_sin(theta_0, A_phi):
    if isinstance(theta_0, (ca.SX, ca.MX)) or isinstance(A_phi, (ca.SX, ca.MX)):
        return ca.sqrt(ca.sin(theta_0) * A_phi)
    return np.sqrt(np.sin(theta_0) * A_phi)


def shape_from_setpoints(c):
    """Setpoints ``(theta_0, A_phi, A_theta)`` (rad) -> shape coordinates ``(theta_0, A_phi, aspect)``.

    ``aspect = A_theta / sqrt(sin theta_0 A_phi)`` (dimensionless): the lobe-end turn radius is about
    ``4 aspect^2 r``, whatever the size of the figure. NumPy arrays (shape (3,)) or CasADi 3-vectors.
    """
    if isinstance(c, (ca.SX, ca.MX)):
        return ca.vertcat(c[0], c[1], c[2] / _sqrt_sin(c[0], c[1]))
    c = np.asarray(c, dtype=float).ravel()
    return np.array([c[0], c[1], c[2] / _sqrt_sin(c[0], c[1])])


def setpoints_from_shape(x):
    """Shape coordinates ``(theta_0, A_phi, aspect)`` -> setpoints ``(theta_0, A_phi, A_theta)`` (rad)."""
    if isinstance(x, (ca.SX, ca.MX)):
        return ca.vertcat(x[0], x[1], x[2] * _sqrt_sin(x[0], x[1]))
    x = np.asarray(x, dtype=float).ravel()
    return np.array([x[0], x[1], x[2] * _sqrt_sin(x[0], x[1])])


@dataclass(frozen=True)
class ShapeBox:
    """The optimizer's box in shape coordinates ``x = (theta_0 rad, A_phi rad, aspect)`` (see
    :func:`shape_from_setpoints`): a box whose every point is a trackable figure-eight.

    In setpoints the trackable set is a curved band; in ``aspect`` it is nearly a slab: the lobe-end turn
    depends on the aspect only, and the top/bottom turns loosen as the figure grows. The default
    (theta_0 30-40 deg, A_phi 42-62 deg, aspect 0.16-0.22, i.e. A_theta 5.5-10.6 deg) passes
    :func:`validate_setpoints` on a 7x7x7 grid with the default margin (``test/flight/test_path.py``); its bounding
    box in setpoints is the default :class:`SetpointBox`.
    """

    theta_0: tuple = (math.radians(30.0), math.radians(40.0))
    A_phi: tuple = (math.radians(42.0), math.radians(62.0))
    aspect: tuple = (0.16, 0.22)

    def __post_init__(self):
        for name in ("theta_0", "A_phi", "aspect"):
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 < lo < hi):
                raise SetpointError(f"ShapeBox.{name} = {(lo, hi)!r}: expected finite bounds 0 < low < high")
        if self.theta_0[1] >= math.pi / 2:
            raise SetpointError(f"ShapeBox.theta_0 = {self.theta_0!r}: the upper bound must be < 90 deg")

    def lower(self) -> np.ndarray:
        return np.array([self.theta_0[0], self.A_phi[0], self.aspect[0]])

    def upper(self) -> np.ndarray:
        return np.array([self.theta_0[1], self.A_phi[1], self.aspect[1]])

    def grid(self, n: int = 2) -> list[np.ndarray]:
        """The n x n x n grid of shape points spanning the box (n = 2: the 8 corners)."""
        axes = [np.linspace(lo, hi, n) for lo, hi in zip(self.lower(), self.upper())]
        return [np.array([a, b, c]) for a in axes[0] for b in axes[1] for c in axes[2]]

    def from_unit(self, z) -> np.ndarray:
        """Setpoints (rad) of the point ``z`` in box-normalized shape coordinates ([0, 1]^3 spans the box)."""
        return setpoints_from_shape(self.lower() + np.asarray(z, dtype=float) * (self.upper() - self.lower()))

    def to_unit(self, c) -> np.ndarray:
        """Box-normalized shape coordinates of setpoints ``c`` (rad); inverse of :meth:`from_unit`."""
        return (shape_from_setpoints(c) - self.lower()) / (self.upper() - self.lower())

    def setpoint_box(self) -> SetpointBox:
        """The bounding :class:`SetpointBox` (A_theta grows with theta_0 < 90 deg and with A_phi)."""
        lo, hi = setpoints_from_shape(self.lower()), setpoints_from_shape(self.upper())
        return SetpointBox(theta_0=(lo[0], hi[0]), A_phi=(lo[1], hi[1]), A_theta=(lo[2], hi[2]))
