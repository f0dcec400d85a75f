"""The reference figure-eight and its setpoints (SPEC §3).

    theta_ref(s) = theta_0 + A_theta sin(2 s),    phi_ref(s) = A_phi sin(s),    s in [0, 2 pi)

Geometry is on the unit sphere of the model's coordinates, in the local orthonormal frame
``north = d theta`` (towards the zenith), ``east = sin(theta) d phi``. Angles and arc lengths are in rad;
multiply by the tether length ``r`` for metres. The *course* ``chi = atan2(east, north)`` of a direction is
measured from north towards east; a kite flying with ``delta``-free drift neglected has ``chi = -psi``.
The geodesic curvature ``kappa`` (1/rad) is positive when the path turns towards increasing ``chi``; a kite
follows it with ``w_ap g_s delta = -kappa * v`` (v in rad/s), i.e. ``delta = -kappa |d| / (r g_s)``.

The setpoints themselves, their box and the cheap box check are in :mod:`~kite_rto.flight.setpoints` (re-exported
here); :func:`validate_setpoints` adds the trackability check, which needs the path's geometry.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kite.params import KiteParams
from .setpoints import DEFAULT_SETPOINTS, SetpointBox, SetpointError, Setpoints, setpoints_in_box

__all__ = ["Setpoints", "SetpointBox", "SetpointError", "FigureEightPath", "ClosestPoint", "validate_setpoints",
           "setpoints_in_box", "required_turn_radius",
           "DEFAULT_SETPOINTS", "DEFAULT_TURN_MARGIN"]

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class ClosestPoint:
    """Closest path point to a measured position.

    Attributes:
        s: path parameter, in [0, 2 pi).
        theta, phi: the path point, rad.
        cross_track: signed distance, rad of arc; positive when the kite lies on the side of increasing course
            (to the east of a path heading north).
        course: course angle of the path tangent at s, rad.
    """

    s: float
    theta: float
    phi: float
    cross_track: float
    course: float


class FigureEightPath:
    """The figure-eight of :class:`Setpoints` ``c``. All methods take scalar ``s`` (floats, fast) unless noted."""

    def __init__(self, setpoints: Setpoints):
        self.setpoints = setpoints
        self._t0, self._ap, self._at = setpoints.theta_0, setpoints.A_phi, setpoints.A_theta
        # factors of the derivatives, computed once: the same values as 2 * A_theta, -4 * A_theta, -A_phi inline
        self._at2, self._atm4, self._apm = 2 * self._at, -4 * self._at, -self._ap

    # --- geometry ----------------------------------------------------------------------------
    def point(self, s):
        """``(theta, phi)`` at ``s`` (rad); NumPy arrays accepted."""
        if isinstance(s, np.ndarray):
            return self._t0 + self._at * np.sin(2 * s), self._ap * np.sin(s)
        return self._t0 + self._at * math.sin(2 * s), self._ap * math.sin(s)

    def speed(self, s: float) -> float:
        """Arc-length rate ``|dP/ds|`` (rad of arc per unit of s)."""
        th = self._t0 + self._at * math.sin(2 * s)
        return math.hypot(2 * self._at * math.cos(2 * s), math.sin(th) * self._ap * math.cos(s))

    def tangent(self, s: float):
        """Unit tangent ``(north, east)`` in the direction of increasing s."""
        th = self._t0 + self._at * math.sin(2 * s)
        n, e = 2 * self._at * math.cos(2 * s), math.sin(th) * self._ap * math.cos(s)
        v = math.hypot(n, e)
        return n / v, e / v

    def course(self, s: float) -> float:
        """Course ``chi = atan2(east, north)`` of the tangent, rad."""
        th = self._t0 + self._at * math.sin(2 * s)
        return math.atan2(math.sin(th) * self._ap * math.cos(s), 2 * self._at * math.cos(2 * s))

    def curvature(self, s: float) -> float:
        """Geodesic curvature on the sphere, 1/rad (signed, positive towards increasing course).

        From the north/east components ``(n, e) = (theta', sin(theta) phi')`` of dP/ds and their s-derivatives
        ``(dn, de)`` (primes: d/ds): ``(d chi/ds + cos(theta) phi') / |(n, e)|``, ``d chi/ds = (n de - e dn) / |.|^2``.
        """
        s2 = 2 * s
        sin2 = math.sin(s2)
        th = self._t0 + self._at * sin2
        n, dph = self._at2 * math.cos(s2), self._ap * math.cos(s)
        st, ct = math.sin(th), math.cos(th)
        e, dn = st * dph, self._atm4 * sin2
        de = ct * n * dph + st * (self._apm * math.sin(s))
        v2 = n * n + e * e
        dchi = (n * de - e * dn) / v2
        return (dchi + ct * dph) / math.sqrt(v2)

    def turn_radius(self, s: float, r: float) -> float:
        """Radius of the turn at s, m, for a tether of length r (m); inf on straight stretches."""
        k = abs(self.curvature(s))
        return r / k if k > 0 else math.inf

    def max_curvature(self, n: int = 720) -> tuple:
        """``(max |kappa| 1/rad, s where it occurs)`` from a grid of n points refined by a parabola."""
        s = np.arange(n) * (TWO_PI / n)
        k = np.abs([self.curvature(si) for si in s])
        i = int(np.argmax(k))
        km, k0, kp = k[i - 1], k[i], k[(i + 1) % n]
        den = km - 2 * k0 + kp
        ds = 0.5 * (km - kp) / den if den < 0 else 0.0
        si = (s[i] + ds * TWO_PI / n) % TWO_PI
        return max(k0, abs(self.curvature(si))), si

    def min_turn_radius(self, r: float) -> float:
        """Tightest turn radius of the path, m, for a tether of length r (m)."""
        return r / self.max_curvature()[0]

    def effective_turn_radius(self, r: float, E: float, n: int = 720) -> float:
        """Tightest turn radius (m) divided by the kite's speed factor there, to compare with 1/(g_s delta).

        Flying along course chi, the model's velocity is ``(w_ap/r) lam (cos chi, sin chi)`` with
        ``lam = -k cos chi + sqrt(1 - k^2 sin^2 chi)``, ``k = tan(theta)/E`` (slower upwards, faster downwards);
        the steering needed is ``delta = kappa lam / (r g_s)``, so the path is trackable with ``|delta| <= d``
        when ``min_s r / (|kappa| lam) >= 1 / (g_s d)``.
        """
        worst = 0.0
        for si in np.arange(n) * (TWO_PI / n):
            k = math.tan(self._t0 + self._at * math.sin(2 * si)) / E
            chi = self.course(si)
            lam = -k * math.cos(chi) + math.sqrt(max(1.0 - (k * math.sin(chi)) ** 2, 0.0))
            worst = max(worst, abs(self.curvature(si)) * lam)
        return r / worst

    # --- closest point -------------------------------------------------------------------------
    def _refine(self, s: float, theta: float, phi: float, iters: int = 4) -> float:
        """Gauss-Newton on ``|(dn, de)|^2`` from s, step limited to 0.3.

        ``(dn, de) = (theta - theta_ref, sin(theta_ref) (phi - phi_ref))`` is the offset from the path point at s in
        the local metric, ``(ddn, dde)`` its s-derivative. Written out with scalar math (no calls, no tuples):
        this runs twice per controller sample.
        """
        t0, ap, at, at2 = self._t0, self._ap, self._at, self._at2
        sin, cos = math.sin, math.cos
        for _ in range(iters):
            s2 = 2 * s
            th = t0 + at * sin(s2)
            dth = at2 * cos(s2)
            st = sin(th)
            dphi = phi - ap * sin(s)
            dn, de = theta - th, st * dphi
            ddn = -dth
            dde = cos(th) * dth * dphi - st * (ap * cos(s))
            g = dn * ddn + de * dde
            h = ddn * ddn + dde * dde
            if h <= 0.0:
                break
            step = -g / h               # max(-0.3, min(0.3, step)), NaN included (-> 0.3), without the calls
            if not step < 0.3:
                step = 0.3
            elif not step > -0.3:
                step = -0.3
            s += step
            if abs(step) < 1e-10:
                break
        return s % TWO_PI

    def closest_point(self, theta: float, phi: float, s_guess: float | None = None,
                      window: tuple = (-0.6, 0.9), n_grid: int = 64) -> ClosestPoint:
        """Closest path point to ``(theta, phi)`` (rad).

        Without ``s_guess``: a global grid of ``n_grid`` points then Gauss-Newton. With ``s_guess`` (the last
        result, for a kite flying the path): only s in ``s_guess + window`` is searched (a small grid then
        Gauss-Newton), so the crossing at the centre of the eight never makes s jump to the other branch.
        """
        if s_guess is None:
            grid = np.arange(n_grid) * (TWO_PI / n_grid)
        else:
            grid = s_guess + np.linspace(window[0], window[1], 16)
        th, ph = self.point(grid)
        d2 = (theta - th) ** 2 + (np.sin(0.5 * (theta + th)) * (phi - ph)) ** 2
        s0 = float(grid[int(np.argmin(d2))])
        s = self._refine(s0, theta, phi, iters=12)
        if s_guess is not None:  # stay inside the window (the refinement may leave it near the centre)
            rel = (s - s_guess + math.pi) % TWO_PI - math.pi
            if not (window[0] - 0.05 <= rel <= window[1] + 0.05):
                s = s0 % TWO_PI
        return self._closest(s, theta, phi)

    def track(self, theta: float, phi: float, s_prev: float, lost_distance: float = 0.1) -> ClosestPoint:
        """Fast per-sample closest point, warm-started from ``s_prev`` (Gauss-Newton only, no grid).

        Falls back to the windowed search if s jumps by more than 0.5, and to the global search if the
        point is farther than ``lost_distance`` (rad of arc) from the path.
        """
        s = self._refine(s_prev, theta, phi, iters=3)
        rel = (s - s_prev + math.pi) % TWO_PI - math.pi
        if abs(rel) > 0.5:  # lost (large jump): fall back to the windowed search
            cp = self.closest_point(theta, phi, s_guess=s_prev)
        else:
            cp = self._closest(s, theta, phi)
        if abs(cp.cross_track) > lost_distance:  # far off the path (relaunch, new path): global search
            cp = self.closest_point(theta, phi)
        return cp

    def _closest(self, s: float, theta: float, phi: float) -> ClosestPoint:
        """The :class:`ClosestPoint` of ``(theta, phi)`` (rad) for path parameter ``s``."""
        s2 = 2 * s
        th = self._t0 + self._at * math.sin(s2)
        ph = self._ap * math.sin(s)
        st = math.sin(th)
        n, e = self._at2 * math.cos(s2), st * (self._ap * math.cos(s))      # tangent dP/ds (north, east)
        dn, de = theta - th, st * (phi - ph)
        v = math.hypot(n, e)
        # normal to the left of north->east rotation: (-e, n)/v in (north, east)
        cross = (-dn * e + de * n) / v
        return _closest_point(s, th, ph, cross, math.atan2(e, n))


_new = object.__new__


def _closest_point(s: float, theta: float, phi: float, cross_track: float, course: float) -> ClosestPoint:
    """Build a :class:`ClosestPoint` (s; theta, phi, cross_track, course rad) without the frozen dataclass's
    per-field ``object.__setattr__`` (about 2x faster; the controller builds two per sample). The result is an
    ordinary ``ClosestPoint`` (same fields, ``==``, ``hash``, ``repr``)."""
    cp = _new(ClosestPoint)
    cp.__dict__.update(s=s, theta=theta, phi=phi, cross_track=cross_track, course=course)
    return cp


DEFAULT_TURN_MARGIN = 0.95
"""Fraction of delta_max the tightest turn may need (nominal model). Measured (benchmarks/bench_tracking.py):
paths down to ~24 m radius track within 0.25 deg RMS with turbulence, because the curvature peak is short;
0.7 would leave almost no feasible figure-eight of this family."""


def required_turn_radius(model_params: KiteParams, delta_max: float = 1.0,
                         margin: float = DEFAULT_TURN_MARGIN) -> float:
    """Smallest path radius (m) the controller accepts: ``1 / (g_s delta_max margin)``.

    The kite turns at ``psi' = w_ap g_s delta`` while flying at about ``w_ap`` m/s, so its minimum turn radius
    ``1 / (g_s delta)`` does not depend on the wind; ``margin`` keeps steering in reserve for disturbances.
    """
    return 1.0 / (model_params.g_s * delta_max * margin)


def validate_setpoints(c, box: SetpointBox | None = None, model_params: KiteParams | None = None, *,
                       delta_max: float = 1.0, margin: float = DEFAULT_TURN_MARGIN) -> Setpoints:
    """Return ``c`` as :class:`Setpoints` if it is finite, inside ``box`` and trackable; else raise
    :class:`SetpointError` naming the field, the value and the reason.

    Args:
        c: :class:`Setpoints` or a length-3 sequence (rad).
        box: :class:`SetpointBox` (default bounds if None).
        model_params: the controller's model (nominal :class:`KiteParams` if None); uses ``r`` and ``g_s``.
        delta_max: steering limit of the controller (normalized).
        margin: fraction of ``delta_max`` the tightest turn may need.
    """
    model_params = model_params or KiteParams()
    c = setpoints_in_box(c, box)
    r_req = required_turn_radius(model_params, delta_max, margin)
    r_path = FigureEightPath(c).effective_turn_radius(model_params.r, model_params.E)
    if r_path < r_req:
        raise SetpointError(
            f"setpoints {tuple(round(d, 2) for d in c.degrees())} deg: infeasible turn, tightest path radius "
            f"{r_path:.1f} m (divided by the drift speed factor) < {r_req:.1f} m = "
            f"1/(g_s {model_params.g_s:g} * delta_max {delta_max:g} * margin {margin:g})")
    return c
