"""The Erhard & Strauch (2013) kite model, written once in CasADi symbols (SPEC §2, seed eqs. 2.4.1-2.4.7).

States ``x = (theta, phi, psi)`` in rad: angle between tether and the downwind x axis, azimuth, and kite
orientation (psi = 0 flies towards the zenith). Input ``delta``: normalized steering deflection in [-1, 1].
Parameters: the vector of :class:`~kite_rto.kite.params.KiteParams` fields (``KiteParams.as_vector()``).

The same :class:`KiteModel` object serves the plant simulation (numeric :class:`casadi.Function` objects),
the controller (its inversion of psi') and the optimizer (symbolic expressions for the periodic OCP).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from .params import KiteParams
from .pyfunc import to_python

__all__ = ["KiteModel", "STATE_NAMES", "OUTPUT_NAMES", "STEP_OUTPUT_NAMES", "MIN_WIND_HEIGHT", "shared_model"]

STATE_NAMES = ("theta", "phi", "psi")
OUTPUT_NAMES = ("tension", "altitude", "w_ap", "x", "y", "z")
"""Outputs of ``f_outputs``, in order: line tension N, altitude m, apparent wind w_ap m/s, position x, y, z m."""
STEP_OUTPUT_NAMES = OUTPUT_NAMES + ("theta_dot", "phi_dot", "psi_dot")
"""Second result of ``step_py``, in order: :data:`OUTPUT_NAMES` then the state derivative, rad/s."""
MIN_WIND_HEIGHT = 0.5
"""Heights below this (m) use the wind of this height, so the power law stays defined at the ground."""


def _unpack(p):
    names = KiteParams.names()
    return {n: p[i] for i, n in enumerate(names)}


_MODEL = None


def shared_model() -> "KiteModel":
    """One :class:`KiteModel` per process (building it compiles the CasADi graphs once)."""
    global _MODEL
    if _MODEL is None:
        _MODEL = KiteModel()
    return _MODEL


@dataclass(frozen=True)
class KiteExpressions:
    """Symbolic expressions of the model for one symbolic state ``x``, input ``delta`` and parameters ``p``."""

    x: ca.SX
    delta: ca.SX
    p: ca.SX
    rhs: ca.SX          # d(theta, phi, psi)/dt, rad/s
    tension: ca.SX      # line tension T, N
    altitude: ca.SX     # z, m
    position: ca.SX     # Cartesian (x, y, z), m, anchor frame (x downwind, z up)
    wind: ca.SX         # wind speed at the kite, m/s
    w_ap: ca.SX         # apparent wind projected normal to the tether, m/s
    glide: ca.SX        # effective glide ratio E - c_E delta^2

    def named(self, names) -> ca.SX:
        """The outputs called ``names`` (from :data:`STEP_OUTPUT_NAMES`) stacked in that order."""
        by_name = {"tension": self.tension, "altitude": self.altitude, "w_ap": self.w_ap,
                   "x": self.position[0], "y": self.position[1], "z": self.position[2],
                   "theta_dot": self.rhs[0], "phi_dot": self.rhs[1], "psi_dot": self.rhs[2]}
        return ca.vertcat(*[by_name[n] for n in names])


class KiteModel:
    """The kite equations as CasADi expressions and compiled numeric functions.

    Numeric functions (all take ``x`` shape (3,), ``delta`` scalar, ``p`` shape (n_p,)):
      * ``f_rhs(x, delta, p) -> xdot`` (rad/s)
      * ``f_outputs(x, delta, p) -> y``, the outputs :data:`OUTPUT_NAMES`
      * ``f_step(x, delta, p, dt) -> x_next``: one classical RK4 step of ``dt`` seconds.
    and their pure-Python translations ``step_py`` / ``state_step_py`` / ``rhs_py`` for per-sample use in loops.
    """

    n_x = 3
    n_p = len(KiteParams.names())

    def __init__(self):
        self.expr = self.expressions(ca.SX.sym("x", 3), ca.SX.sym("delta"), ca.SX.sym("p", self.n_p))
        e = self.expr
        self.f_rhs = ca.Function("kite_rhs", [e.x, e.delta, e.p], [e.rhs], ["x", "delta", "p"], ["xdot"])
        self.f_outputs = ca.Function("kite_outputs", [e.x, e.delta, e.p], [e.named(OUTPUT_NAMES)],
                                     ["x", "delta", "p"], ["y"])
        dt = ca.SX.sym("dt")
        x_next = self.rk4(self.f_rhs, e.x, e.delta, e.p, dt)
        self.f_step = ca.Function("kite_rk4", [e.x, e.delta, e.p, dt], [x_next],
                                  ["x", "delta", "p", "dt"], ["x_next"])
        # Fast pure-Python translations of the same graphs (see pyfunc.py for why).
        after = self.expressions(x_next, e.delta, e.p)
        step_out = ca.cse([x_next, after.named(STEP_OUTPUT_NAMES)])
        self.step_py = to_python(ca.Function("kite_step_py", [e.x, e.delta, e.p, dt], step_out))
        """``step_py(x, delta, p, dt) -> (x_next[3], outputs :data:`STEP_OUTPUT_NAMES` at x_next)``,
        plain Python floats/lists; one RK4 step with the input held."""
        self.state_step_py = to_python(ca.Function("kite_state_step_py", [e.x, e.delta, e.p, dt], [ca.cse(x_next)]))
        """``state_step_py(x, delta, p, dt) -> (x_next[3],)``: ``step_py``'s first result alone (the same graph,
        so bit for bit the same numbers) at about 60 % of its cost; the controller's dead-time prediction."""
        self.rhs_py = to_python(ca.Function("kite_rhs_py", [e.x, e.delta, e.p],
                                            ca.cse([e.rhs, ca.vertcat(e.w_ap, e.wind)])))
        """``rhs_py(x, delta, p) -> (xdot[3], [w_ap, wind])``, plain Python floats/lists."""

    @staticmethod
    def expressions(x, delta, p) -> KiteExpressions:
        """Build the model's expressions for symbolic (SX or MX) ``x``, ``delta`` and ``p``."""
        k = _unpack(p)
        theta, phi, psi = x[0], x[1], x[2]
        glide = k["E"] - k["c_E"] * delta**2
        position = k["r"] * ca.vertcat(ca.cos(theta), ca.sin(theta) * ca.sin(phi),
                                       ca.sin(theta) * ca.cos(phi))
        z = position[2]
        wind = k["w_ref"] * (ca.fmax(z, MIN_WIND_HEIGHT) / k["z_ref"]) ** k["shear"]
        w_ap = wind * glide * ca.cos(theta)
        theta_dot = w_ap / k["r"] * (ca.cos(psi) - ca.tan(theta) / glide)
        phi_dot = -w_ap / (k["r"] * ca.sin(theta)) * ca.sin(psi)
        psi_dot = w_ap * k["g_s"] * delta + phi_dot * ca.cos(theta)
        tension = 0.5 * k["rho"] * k["area"] * wind**2 * (glide + 1) * ca.sqrt(glide**2 + 1) * ca.cos(theta)**2
        return KiteExpressions(x, delta, p, ca.vertcat(theta_dot, phi_dot, psi_dot), tension, z,
                               position, wind, w_ap, glide)

    @staticmethod
    def rk4(f, x, delta, p, dt):
        """One classical Runge-Kutta step of ``f(x, delta, p)`` over ``dt`` (input held constant)."""
        k1 = f(x, delta, p)
        k2 = f(x + dt / 2 * k1, delta, p)
        k3 = f(x + dt / 2 * k2, delta, p)
        k4 = f(x + dt * k3, delta, p)
        return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    # Convenience numeric wrappers (NumPy in, NumPy out) -------------------------------------------
    def rhs(self, x, delta, params: KiteParams) -> np.ndarray:
        """State derivative, rad/s, shape (3,)."""
        return np.asarray(self.f_rhs(x, delta, params.as_vector())).ravel()

    def outputs(self, x, delta, params: KiteParams) -> dict:
        """Tension (N), altitude (m), apparent wind w_ap (m/s) and Cartesian position (m)."""
        y = dict(zip(OUTPUT_NAMES, np.asarray(self.f_outputs(x, delta, params.as_vector())).ravel()))
        return {"tension": y["tension"], "altitude": y["altitude"], "w_ap": y["w_ap"],
                "position": np.array([y["x"], y["y"], y["z"]])}

    def zenith_equilibrium(self, params: KiteParams, psi: float = 0.0) -> float:
        """theta (rad) at which a kite held at orientation ``psi`` with delta = 0 settles: atan(E cos psi)."""
        return float(np.arctan(params.E * np.cos(psi)))
