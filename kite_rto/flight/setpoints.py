"""The setpoints of the figure-eight (:class:`Setpoints`), the box the controller accepts (:class:`SetpointBox`)
and the check that setpoints lie in it (:func:`setpoints_in_box`; :func:`~kite_rto.flight.path.validate_setpoints`
also checks that the figure is trackable).

Sign of ``A_theta``: positive values fly *up* through the centre (s = 0 and pi, theta increasing) and turn
downwards at the outer ends of the lobes; negative values fly the mirror pattern (down through the centre,
turning upwards at the ends). Both are valid paths; :class:`SetpointBox` defaults to positive values only,
so that the optimizer works in a convex box that stays away from the degenerate A_theta = 0 (a line).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

__all__ = ["Setpoints", "SetpointBox", "SetpointError", "setpoints_in_box", "DEFAULT_SETPOINTS"]


class SetpointError(ValueError):
    """Setpoints that the path controller refuses; the message names the field, the value and the reason."""


@dataclass(frozen=True)
class Setpoints:
    """Shape of the figure-eight, rad.

    Attributes:
        theta_0: centre angle between tether and the downwind axis, rad.
        A_phi: azimuth half-width, rad (> 0).
        A_theta: elevation half-height, rad; its sign chooses the lobe direction (module docstring).
    """

    theta_0: float
    A_phi: float
    A_theta: float

    def as_array(self) -> np.ndarray:
        """``[theta_0, A_phi, A_theta]``, rad, shape (3,)."""
        return np.array([self.theta_0, self.A_phi, self.A_theta], dtype=float)

    @classmethod
    def from_array(cls, c) -> "Setpoints":
        """From a length-3 sequence ``[theta_0, A_phi, A_theta]`` (rad)."""
        c = np.asarray(c, dtype=float).ravel()
        if c.size != 3:
            raise SetpointError(f"Setpoints.from_array: expected 3 values (theta_0, A_phi, A_theta), got {c.size}")
        return cls(float(c[0]), float(c[1]), float(c[2]))

    @classmethod
    def from_degrees(cls, theta_0: float, A_phi: float, A_theta: float) -> "Setpoints":
        """Convenience constructor from degrees."""
        return cls(math.radians(theta_0), math.radians(A_phi), math.radians(A_theta))

    def degrees(self) -> tuple:
        """``(theta_0, A_phi, A_theta)`` in degrees."""
        return tuple(math.degrees(v) for v in (self.theta_0, self.A_phi, self.A_theta))

    @staticmethod
    def names() -> list[str]:
        return [f.name for f in fields(Setpoints)]


DEFAULT_SETPOINTS = Setpoints.from_degrees(35.0, 45.0, 7.0)
"""Default operating point (rad): wide figure-eight near the real kite's optimum, trackable with margin."""


@dataclass(frozen=True)
class SetpointBox:
    """Bounds (rad) of the setpoints the controller accepts; inside them
    :func:`~kite_rto.flight.path.validate_setpoints` also checks that the figure is trackable.

    The Lissajous figure has two tight turns: at the lobe ends (radius about ``4 A_theta^2 / (sin theta_0 A_phi)``)
    and at the tops/bottoms of the lobes (about ``(sin theta_0 A_phi)^2 / (8 A_theta)``), in rad of arc; the
    exact tightest radius lies between them (:meth:`~kite_rto.flight.path.FigureEightPath.min_turn_radius`).
    Narrow, flat or tall figures are therefore untrackable: the model optimum quoted in SPEC §2, (22, 15, 4) deg,
    needs a 4.6 m turn while the nominal kite's minimum radius is 1/g_s = 25 m. The trackable set is a band around
    ``A_theta ~ sqrt(sin theta_0 A_phi)``, not a box: the optimizer therefore works in the coordinates of
    :class:`~kite_rto.flight.shape.ShapeBox`, whose every point is trackable, and this box is the bounding box of
    the default one: theta_0 in [30, 40] deg, A_phi in [42, 62] deg, A_theta in [5.5, 10.6] deg (positive: up
    through the centre). Points of it outside the band (e.g. (30, 42, 10) deg) fail
    :func:`~kite_rto.flight.path.validate_setpoints`.
    """

    theta_0: tuple = (math.radians(30.0), math.radians(40.0))
    A_phi: tuple = (math.radians(42.0), math.radians(62.0))
    A_theta: tuple = (math.radians(5.5), math.radians(10.6))

    def __post_init__(self):
        for name in Setpoints.names():
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise SetpointError(f"SetpointBox.{name} = {(lo, hi)!r}: expected finite bounds with low <= high")
        if self.A_phi[0] <= 0.0:
            raise SetpointError(f"SetpointBox.A_phi = {self.A_phi!r}: the lower bound must be > 0")
        if self.theta_0[0] - max(abs(v) for v in self.A_theta) <= 0.0 or self.theta_0[1] >= math.pi / 2:
            raise SetpointError(f"SetpointBox.theta_0 = {self.theta_0!r}: the path must stay within (0, 90) deg")

    def lower(self) -> np.ndarray:
        return np.array([self.theta_0[0], self.A_phi[0], self.A_theta[0]])

    def upper(self) -> np.ndarray:
        return np.array([self.theta_0[1], self.A_phi[1], self.A_theta[1]])

    def corners(self) -> list[Setpoints]:
        """The 8 corners of the box."""
        return [Setpoints(a, b, c) for a in self.theta_0 for b in self.A_phi for c in self.A_theta]


def setpoints_in_box(c, box: SetpointBox | None = None) -> Setpoints:
    """Return ``c`` as :class:`Setpoints` if it is finite and inside ``box`` (default bounds if None); else raise
    :class:`SetpointError` naming the field, the value and the box. The cheap part of :func:`validate_setpoints`
    (a few µs; the trackability check there takes about a millisecond)."""
    box = box or SetpointBox()
    if not isinstance(c, Setpoints):
        try:
            c = Setpoints.from_array(c)
        except (TypeError, ValueError) as err:
            raise SetpointError(f"setpoints {c!r}: {err}") from None
    for name in Setpoints.names():
        v = getattr(c, name)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise SetpointError(f"setpoint {name} = {v!r}: expected a finite number (rad)")
        lo, hi = getattr(box, name)
        if not lo <= v <= hi:
            raise SetpointError(f"setpoint {name} = {v:.6g} rad ({math.degrees(v):.3g} deg): outside the box "
                                f"[{lo:.6g}, {hi:.6g}] rad ([{math.degrees(lo):.3g}, {math.degrees(hi):.3g}] deg)")
    return c
