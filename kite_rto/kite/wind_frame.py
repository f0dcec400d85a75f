"""The kite's state in another frame: the model's wind frame, a turned mean wind, a path centred elsewhere.

The Erhard model (SPEC §2) is written in the wind frame: x along the wind, z up (for a horizontal wind), the
tether's direction ``u = (cos theta, sin theta sin phi, sin theta cos phi)`` and the kite's heading on the sphere
``h = cos psi e_theta - sin psi e_phi`` with ``e_theta = du/dtheta`` and ``e_phi = (0, cos phi, -sin phi)``. When
the wind turns, the kite (its tether and its heading) stays where it is and the angles change: this module maps
``(theta, phi, psi)`` of one frame to those of a rotated one, through the physical vectors ``u`` and ``h``.

A wind from azimuth ``direction`` (rad, from the ground frame's x towards its y, about z up) tilted up by ``tilt``
(rad) has the unit vector ``d = (cos tilt cos direction, cos tilt sin direction, sin tilt)``; its frame has the axes
``e1 = d``, ``e2 = (-sin direction, cos direction, 0)`` (horizontal) and ``e3 = e1 x e2`` (:func:`wind_rotation`).
Pure Python floats: the plant calls it twice per sample when the wind turns.
"""
from __future__ import annotations

import math

__all__ = ["wind_rotation", "transpose", "rotate_state", "rotate_vector", "rotate_motion", "RATE_STEP"]

_sin, _cos, _atan2, _sqrt = math.sin, math.cos, math.atan2, math.sqrt
RATE_STEP = 1e-3
"""s: the short step along the rates whose image in the turned frame gives the rates there (:func:`rotate_motion`)."""


def wind_rotation(direction: float, tilt: float = 0.0) -> tuple:
    """The rotation ``R`` (three rows) with ``p_wind = R p_ground`` for a wind from azimuth ``direction`` tilted up by
    ``tilt`` (rad)."""
    cd, sd, ct, st = _cos(direction), _sin(direction), _cos(tilt), _sin(tilt)
    return ((ct * cd, ct * sd, st), (-sd, cd, 0.0), (-st * cd, -st * sd, ct))


def transpose(rotation: tuple) -> tuple:
    """The inverse rotation (``R^T``)."""
    (a, b, c), (d, e, f), (g, h, i) = rotation
    return ((a, d, g), (b, e, h), (c, f, i))


def rotate_vector(rotation: tuple, v) -> tuple:
    """``R v`` for a 3-vector ``v``."""
    r0, r1, r2 = rotation
    x, y, z = v
    return (r0[0] * x + r0[1] * y + r0[2] * z, r1[0] * x + r1[1] * y + r1[2] * z, r2[0] * x + r2[1] * y + r2[2] * z)


def rotate_state(state, rotation: tuple) -> list:
    """``(theta, phi, psi)`` (rad) of the same tether and heading in the frame ``p' = R p``; theta in [0, pi], phi
    and psi in (-pi, pi]."""
    theta, phi, psi = state[0], state[1], state[2]
    st, ct, sp, cp, ss, cs = _sin(theta), _cos(theta), _sin(phi), _cos(phi), _sin(psi), _cos(psi)
    u = (ct, st * sp, st * cp)
    # h = cos(psi) e_theta - sin(psi) e_phi
    h = (-cs * st, cs * ct * sp - ss * cp, cs * ct * cp + ss * sp)
    ux, uy, uz = rotate_vector(rotation, u)
    hx, hy, hz = rotate_vector(rotation, h)
    theta2 = _atan2(_sqrt(uy * uy + uz * uz), ux)
    phi2 = _atan2(uy, uz)
    st2, ct2, sp2, cp2 = _sin(theta2), _cos(theta2), _sin(phi2), _cos(phi2)
    along_theta = -st2 * hx + ct2 * sp2 * hy + ct2 * cp2 * hz
    along_phi = cp2 * hy - sp2 * hz
    return [theta2, phi2, _atan2(-along_phi, along_theta)]


def rotate_motion(state, rates, rotation: tuple) -> tuple:
    """``(state, rates)`` of the same motion in the frame ``p' = R p``: the state as :func:`rotate_state` turns it,
    the rates (rad/s) from the image of a step of :data:`RATE_STEP` along them (wrapped differences)."""
    turned = rotate_state(state, rotation)
    h = RATE_STEP
    ahead = rotate_state([a + h * r for a, r in zip(state, rates)], rotation)
    return turned, [math.remainder(a - b, math.tau) / h for a, b in zip(ahead, turned)]
