"""The kite's open-loop model as a GMA :class:`ModelProblem`: one periodic lap, by multiple shooting (SPEC §4).

Decision vector ``u`` (length ``4 N + 1``), in this order:

* ``X``: the states ``(theta, phi, psi)`` (rad) at the ``N`` shooting nodes ``t_k = k T / N``, node-major;
* ``delta``: the ``N`` piecewise-constant steering values (normalized, ``|delta| <= delta_max``);
* ``T``: the lap period, s.

Equalities (model-internal, never modified): RK4 continuity ``x_{k+1} = F(x_k, delta_k, T/N)`` with
``x_N = x_0`` (periodicity of theta, phi *and* psi: a figure-eight turns both ways, psi does not wrap), and
the phase fix ``phi_0 = 0``; the bound ``psi_0 in [-pi, 0]`` makes phi increase there.

Cost ``phi(u) = -(1/T) integral of the line tension over the lap / cost_unit`` (default kN; the integral is an
RK4 quadrature on the same substeps as the states), plus a small cyclic steering-rate penalty
``delta_rate_weight * sum (delta_{k+1} - delta_k)^2`` against chattering (~0.5 kN at the optimum).

Constraint ``g(u) = (h_min - softmin_k z_k) / constraint_unit`` (default metres), with
``softmin(z) = h_min - s log sum exp(-(z_k - h_min) / s)`` over the node altitudes
``z_k = r sin(theta_k) cos(phi_k)``. The soft-min lies below the node minimum by between 0 and ``s ln N``
(1.8 m for s = 0.5 m, N = 40); measured: 0.35-0.45 m on the optimum and interior laps (``softmin_bias``).
The node minimum lies 0.1-0.2 m above the continuous one for N = 40. GMA's ``eps`` modifier absorbs both.

Outputs ``y(u) = project_samples(theta_nodes, phi_nodes)``, the setpoints ``(theta_0, A_phi, A_theta)`` (rad)
of the lap: nodes are uniform in time over one period, exactly as the plant samples a flown lap.

Initial guess (:func:`path_guess`): the reference figure-eight of a setpoint ``c`` is inverted through the
kinematics (for each path tangent the psi that flies along it, the speed that follows, the time spent on each
piece of path), resampled uniformly in time, and delta is read off ``psi' = w_ap g_s delta + phi' cos theta``.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..kite.model import KiteModel
from ..kite.params import KiteParams, check_range
from ..flight.shape import setpoints_from_shape, shape_from_setpoints
from ..flight.projection import project_samples

from ..gma import ModelProblem
from .experiment import H_MIN

__all__ = ["KiteOCPSettings", "KiteModelProblem", "model_problem", "path_guess", "unpack", "reference_altitudes",
           "ALTITUDES",
           "DEFAULT_C_LB", "DEFAULT_C_UB", "DEFAULT_C_GUESS"]

_DEG = math.pi / 180.0
ALTITUDES = ("lap", "reference")
"""What the OCP's altitude constraint bounds (:attr:`KiteOCPSettings.altitude`)."""
DEFAULT_C_LB = np.array([15.0, 8.0, 1.0]) * _DEG
"""Default safe setpoint box, lower corner (theta_0, A_phi, A_theta), rad."""
DEFAULT_C_UB = np.array([45.0, 50.0, 12.0]) * _DEG
"""Default safe setpoint box, upper corner, rad."""
DEFAULT_C_GUESS = np.array([25.0, 20.0, 5.0]) * _DEG
"""Setpoints whose figure-eight seeds the default initial guess ``u0``, rad."""


@dataclass(frozen=True)
class KiteOCPSettings:
    """Discretization and bounds of the periodic lap OCP.

    Attributes:
        n_intervals: N, shooting intervals per lap (= nodes, uniform in time), >= 8.
        substeps: RK4 substeps per interval, >= 1.
        delta_max: steering bound |delta| <= delta_max (< 1 leaves the path controller some authority).
        period_bounds: (T_min, T_max), s.
        theta_bounds: (min, max) of theta at the nodes, rad.
        phi_max: |phi| bound at the nodes, rad.
        psi_bound: |psi| bound at the nodes, rad (psi does not wrap; this only keeps the solver sane).
        cost_unit: N per unit of cost (1000: phi in kN).
        constraint_unit: m per unit of constraint (1: g in metres).
        softmin_sharpness: s, m; soft-min bias is at most s ln N below the node minimum.
        delta_rate_weight: w, cost units per unit^2; adds ``w sum_k (delta_{k+1} - delta_k)^2`` (cyclic) to
            the cost, which suppresses chattering of the piecewise-constant steering (0 disables it). At 0.3
            it costs < 0.1 % of the mean tension at the optimum and makes warm starts converge in a few steps.
        altitude: what the altitude constraint bounds. ``"lap"``: the soft minimum of the model lap's node
            altitudes. ``"reference"``: the soft minimum of the altitude of the reference figure-eight of the
            lap's setpoints ``y(u)`` (:func:`reference_altitudes`), a function of ``y(u)`` alone: the model can
            then not keep the altitude by bending its lap in ways the plant's path controller does not fly, and
            the controller's tracking error is plant-model mismatch for GMA's modifiers (``docs/theory.md``).
        reference_samples: samples of the reference figure-eight per lap for ``altitude = "reference"``, >= 16.
    """

    n_intervals: int = 40
    substeps: int = 2
    delta_max: float = 0.8
    period_bounds: tuple[float, float] = (1.0, 60.0)
    theta_bounds: tuple[float, float] = (5.0 * _DEG, 75.0 * _DEG)
    phi_max: float = 80.0 * _DEG
    psi_bound: float = 2.5 * math.pi
    cost_unit: float = 1000.0
    constraint_unit: float = 1.0
    softmin_sharpness: float = 0.5
    delta_rate_weight: float = 0.3
    altitude: str = "reference"
    reference_samples: int = 64

    def __post_init__(self):
        name = type(self).__name__
        if self.altitude not in ALTITUDES:
            raise ValueError(f"{name}.altitude = {self.altitude!r}: expected one of {ALTITUDES}")
        if isinstance(self.reference_samples, bool) or not isinstance(self.reference_samples, int) \
                or self.reference_samples < 16:
            raise ValueError(f"{name}.reference_samples = {self.reference_samples!r}: expected an int >= 16")
        if not isinstance(self.n_intervals, int) or self.n_intervals < 8:
            raise ValueError(f"{name}.n_intervals = {self.n_intervals!r}: expected an int >= 8")
        if not isinstance(self.substeps, int) or self.substeps < 1:
            raise ValueError(f"{name}.substeps = {self.substeps!r}: expected an int >= 1")
        check_range(name, "delta_max", self.delta_max, 0.0, 1.0, low_open=True)
        for f in ("cost_unit", "constraint_unit", "softmin_sharpness"):
            check_range(name, f, getattr(self, f), 0.0, low_open=True)
        check_range(name, "delta_rate_weight", self.delta_rate_weight, 0.0)
        check_range(name, "phi_max", self.phi_max, 0.0, math.pi / 2, low_open=True)
        check_range(name, "psi_bound", self.psi_bound, math.pi, low_open=True)
        lo, hi = self.period_bounds
        check_range(name, "period_bounds[0]", lo, 0.0, low_open=True)
        check_range(name, "period_bounds[1]", hi, lo, low_open=True)
        lo, hi = self.theta_bounds
        check_range(name, "theta_bounds[0]", lo, 0.0, math.pi / 2, low_open=True)
        check_range(name, "theta_bounds[1]", hi, lo, math.pi / 2, low_open=True, high_open=True)


@dataclass
class KiteModelProblem(ModelProblem):
    """A :class:`ModelProblem` that remembers the kite it was built from (for :func:`unpack` and reports).

    Extra attributes: ``params``, ``settings``, ``h_min`` (m); symbolic ``mean_tension`` (N, without the
    steering-rate regularization) and ``node_altitudes`` (m, shape (N,)), functions of ``u``.
    """

    params: KiteParams = field(default_factory=KiteParams)
    settings: KiteOCPSettings = field(default_factory=KiteOCPSettings)
    h_min: float = H_MIN
    mean_tension: ca.SX | None = None
    node_altitudes: ca.SX | None = None


def unpack(u, settings: KiteOCPSettings) -> dict:
    """Split a numeric ``u`` into ``states`` (N, 3) rad, ``delta`` (N,), ``period`` s and node times ``t`` (N,) s."""
    n = settings.n_intervals
    u = np.asarray(u, dtype=float).ravel()
    if u.size != 4 * n + 1:
        raise ValueError(f"unpack: u has {u.size} entries, expected 4 N + 1 = {4 * n + 1}")
    period = float(u[-1])
    return {"states": u[:3 * n].reshape(n, 3), "delta": u[3 * n:4 * n].copy(), "period": period,
            "t": np.arange(n) * period / n}


def _interval_map(model: KiteModel, params: KiteParams, settings: KiteOCPSettings) -> ca.Function:
    """``F(x, delta, h) -> (x_end, integral of tension dt)`` over one interval of h s, RK4 with substeps."""
    x, delta, h = ca.SX.sym("x", 3), ca.SX.sym("delta"), ca.SX.sym("h")
    p = ca.DM(params.as_vector())

    def f(xq, d, _p):
        e = model.expressions(xq[:3], d, p)
        return ca.vertcat(e.rhs, e.tension)

    xq = ca.vertcat(x, 0)
    dt = h / settings.substeps
    for _ in range(settings.substeps):
        xq = KiteModel.rk4(f, xq, delta, p, dt)
    return ca.Function("kite_interval", [x, delta, h], [xq[:3], xq[3]], ["x", "delta", "h"], ["xf", "q"])


def _softmin(z, h_ref: float, s: float):
    """Smooth minimum of the entries of ``z`` (m), shifted by ``h_ref`` so exp() stays in range."""
    return h_ref - s * ca.log(ca.sum1(ca.exp(-(z - h_ref) / s)))


def reference_altitudes(c, r: float, n: int):
    """Altitudes (m) ``z(s) = r sin(theta_0 + A_theta sin 2s) cos(A_phi sin s)`` of the reference figure-eight of
    setpoints ``c = (theta_0, A_phi, A_theta)`` (rad) at ``n`` points ``s = 2 pi i / n``; ``c`` numeric (returns a
    NumPy array (n,)) or a CasADi 3-vector (returns an (n, 1) expression). ``r``: tether length, m."""
    s = 2 * np.pi * np.arange(n) / n
    if isinstance(c, (ca.SX, ca.MX)):
        theta = c[0] + c[2] * ca.DM(np.sin(2 * s))
        return r * ca.sin(theta) * ca.cos(c[1] * ca.DM(np.sin(s)))
    th0, a_phi, a_th = (float(v) for v in np.asarray(c, dtype=float).ravel())
    return r * np.sin(th0 + a_th * np.sin(2 * s)) * np.cos(a_phi * np.sin(s))


def model_problem(params: KiteParams | None = None, settings: KiteOCPSettings | None = None,
                  c_lb=None, c_ub=None, c_guess=None, name: str = "kite_lap",
                  shape: bool = False, h_min: float = H_MIN) -> KiteModelProblem:
    """Build the periodic-lap OCP of the open-loop kite as a :class:`ModelProblem` (all fields symbolic SX).

    Args:
        params: model parameters (nominal :class:`KiteParams` by default).
        settings: discretization and bounds (:class:`KiteOCPSettings` defaults).
        c_lb, c_ub: the plant's safe setpoint box (theta_0, A_phi, A_theta), rad (``DEFAULT_C_LB/UB``).
        c_guess: setpoints whose figure-eight seeds ``u0`` (:data:`DEFAULT_C_GUESS`).
        name: label of the problem.
        shape: outputs in shape coordinates ``y = (theta_0, A_phi, aspect)`` (:func:`shape_from_setpoints`)
            instead of setpoints; ``c_lb``, ``c_ub`` and ``c_guess`` are then shape coordinates too (and required).
        h_min: the minimum altitude of the constraint, m (the run's :attr:`ExperimentSpec.h_min
            <kite_rto.rto.experiment.ExperimentSpec>`).
    """
    if shape and (c_lb is None or c_ub is None or c_guess is None):
        raise ValueError("model_problem(shape=True): give c_lb, c_ub and c_guess in shape coordinates")
    params = params or KiteParams()
    settings = settings or KiteOCPSettings()
    c_lb = DEFAULT_C_LB if c_lb is None else np.asarray(c_lb, dtype=float)
    c_ub = DEFAULT_C_UB if c_ub is None else np.asarray(c_ub, dtype=float)
    c_guess = DEFAULT_C_GUESS if c_guess is None else np.asarray(c_guess, dtype=float)
    n = settings.n_intervals
    model = KiteModel()
    F = _interval_map(model, params, settings)

    u = ca.SX.sym("u", 4 * n + 1)
    X = ca.reshape(u[:3 * n], 3, n)          # column k = x_k
    delta = u[3 * n:4 * n]
    period = u[4 * n]
    xf, q = F.map(n)(X, delta.T, period / n)
    defects = xf - ca.horzcat(X[:, 1:], X[:, 0])
    equalities = ca.vertcat(ca.vec(defects), X[1, 0])
    mean_tension = ca.sum2(q) / period                                        # N
    theta, phi = X[0, :].T, X[1, :].T
    z = params.r * ca.sin(theta) * ca.cos(phi)
    setpoints = project_samples(theta, phi)
    z_bound = z if settings.altitude == "lap" else reference_altitudes(setpoints, params.r,
                                                                       settings.reference_samples)
    z_soft = _softmin(z_bound, h_min, settings.softmin_sharpness)

    lbu, ubu = _bounds(settings)
    return KiteModelProblem(
        u=u, cost=-mean_tension / settings.cost_unit + settings.delta_rate_weight * ca.sumsqr(
            delta - ca.vertcat(delta[1:], delta[0])),
        constraints=(h_min - z_soft) / settings.constraint_unit,
        outputs=shape_from_setpoints(setpoints) if shape else setpoints,
        lbu=lbu, ubu=ubu, c_lb=c_lb, c_ub=c_ub,
        u0=path_guess(params, settings, setpoints_from_shape(c_guess) if shape else c_guess),
        equalities=equalities, inner_constraints=None, name=name, params=params, settings=settings, h_min=h_min,
        mean_tension=mean_tension, node_altitudes=z)


def _bounds(settings: KiteOCPSettings) -> tuple[np.ndarray, np.ndarray]:
    n = settings.n_intervals
    xlo = np.tile([settings.theta_bounds[0], -settings.phi_max, -settings.psi_bound], n)
    xhi = np.tile([settings.theta_bounds[1], settings.phi_max, settings.psi_bound], n)
    xlo[2], xhi[2] = -math.pi, 0.0                   # psi_0: phi increases through phi_0 = 0
    dlo, dhi = np.full(n, -settings.delta_max), np.full(n, settings.delta_max)
    lbu = np.concatenate([xlo, dlo, [settings.period_bounds[0]]])
    ubu = np.concatenate([xhi, dhi, [settings.period_bounds[1]]])
    return lbu, ubu


@functools.lru_cache(maxsize=4)
def _outputs_map(n: int) -> ca.Function:
    """The model's output function mapped over n samples (cached: building a KiteModel takes ~40 ms)."""
    return KiteModel().f_outputs.map(n)


def path_guess(params: KiteParams, settings: KiteOCPSettings, c, n_fine: int = 2000) -> np.ndarray:
    """A decision vector ``u`` that flies the reference figure-eight of setpoints ``c`` (rad), by inversion.

    Along ``theta = theta_0 + A_theta sin 2s``, ``phi = A_phi sin s``, the heading psi that moves the kite
    along the tangent is solved from ``theta' = (w_ap/r)(cos psi - tan(theta)/E)``,
    ``phi' = -(w_ap/(r sin theta)) sin psi``; that fixes the speed ``ds/dt``, hence the time of each path piece
    and the period. States are resampled uniformly in time; delta is the interval average of
    ``(psi' - phi' cos theta) / (w_ap g_s)``, clipped to ``delta_max``. Not dynamically exact: a start for IPOPT.
    """
    th0, a_phi, a_th = (float(v) for v in np.asarray(c, dtype=float).ravel())
    s = np.linspace(0.0, 2 * np.pi, n_fine, endpoint=False)
    theta, phi = th0 + a_th * np.sin(2 * s), a_phi * np.sin(s)
    d_up, d_right = 2 * a_th * np.cos(2 * s), np.sin(theta) * a_phi * np.cos(s)   # tangent, rad per unit s
    kappa = np.tan(theta) / params.E                              # glide ratio at delta = 0
    a2 = d_up**2 + d_right**2
    mu = (-kappa * d_up + np.sqrt((kappa * d_up)**2 - a2 * (kappa**2 - 1.0))) / a2
    psi = np.unwrap(np.arctan2(-mu * d_right, kappa + mu * d_up))
    w_ap = np.asarray(_outputs_map(n_fine)(np.vstack([theta, phi, psi]), 0.0, params.as_vector()))[2]
    sdot = mu * w_ap / params.r                                  # ds/dt, 1/s
    ds = 2 * np.pi / n_fine
    dt = ds * 0.5 * (1.0 / sdot + 1.0 / np.roll(sdot, -1))
    t = np.concatenate([[0.0], np.cumsum(dt)])
    period = t[-1]
    # psi' and phi' along the path, then delta from the psi equation
    dpsi_ds = (np.roll(psi, -1) - np.roll(psi, 1)) / (2 * ds)   # periodic: a figure-eight's net turn is 0
    psi_dot, phi_dot = dpsi_ds * sdot, a_phi * np.cos(s) * sdot
    delta_fine = (psi_dot - phi_dot * np.cos(theta)) / (w_ap * params.g_s)
    n = settings.n_intervals
    tk = np.arange(n) * period / n
    per = lambda v: np.concatenate([v, v[:1]])  # noqa: E731  (close the lap for interpolation)
    X = np.column_stack([np.interp(tk, t, per(theta)), np.interp(tk, t, per(phi)),
                         np.interp(tk, t, per(psi))])
    t_mid = tk + 0.5 * period / n
    delta = np.clip(np.interp(t_mid, t, per(delta_fine)), -0.99 * settings.delta_max, 0.99 * settings.delta_max)
    period = float(np.clip(period, *settings.period_bounds))
    return np.concatenate([X.ravel(), delta, [period]])

