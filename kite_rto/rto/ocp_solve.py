"""Solve the kite's lap OCP directly (IPOPT): its own optimum, and its best way of flying given setpoints.

These helpers serve tests, benchmarks and reports. The GMA library builds its own solvers from the
:class:`~kite_rto.rto.ocp.KiteModelProblem`'s symbolic fields; these use the same fields, so both see
the same model. Solvers are built once per problem and cached (keyed by the problem object's identity).
"""
from __future__ import annotations

import time
import weakref
from dataclasses import dataclass

import casadi as ca
import numpy as np

from .ocp import KiteModelProblem, path_guess, unpack

__all__ = ["OCPSolution", "OCPSolveError", "solve_model_optimum", "realize_setpoints"]

_IPOPT = {"print_level": 0, "sb": "yes", "tol": 1e-8, "max_iter": 500}
_WARM = {"warm_start_init_point": "yes", "mu_init": 1e-4}


class OCPSolveError(RuntimeError):
    """IPOPT did not converge; the message carries its return status."""


@dataclass
class OCPSolution:
    """A solved lap.

    Attributes:
        u: decision vector, shape (4 N + 1,).
        c: controlled variables y(u) = (theta_0, A_phi, A_theta), rad.
        cost: phi(u) (default units: kN, negative).
        g: g(u), constraint units (default m); h_min - soft-min altitude.
        mean_tension_kn: mean line tension over the lap, kN.
        min_altitude: minimum node altitude, m.
        softmin_bias: node minimum minus soft-min altitude, m (>= 0).
        period: lap period T, s.
        delta: steering per interval, shape (N,).
        states: (theta, phi, psi) at the nodes, shape (N, 3), rad.
        t: node times, s, shape (N,).
        iterations, solve_time (s), status: IPOPT's report.
        lam_x, lam_g: multipliers (for warm starts; lam_g's last n_c entries belong to y(u) = c in
            :func:`realize_setpoints`, and equal -d phi_hat / d c).
    """

    u: np.ndarray
    c: np.ndarray
    cost: float
    g: float
    mean_tension_kn: float
    min_altitude: float
    softmin_bias: float
    period: float
    delta: np.ndarray
    states: np.ndarray
    t: np.ndarray
    iterations: int
    solve_time: float
    status: str
    lam_x: np.ndarray
    lam_g: np.ndarray


class _Solvers:
    """The two NLPs of one problem, each cold and warm: optimum (g <= 0, y in box) and realization (y = c)."""

    def __init__(self, problem: KiteModelProblem):
        pr = problem
        self.problem = pr
        c = ca.SX.sym("c", pr.n_c)
        n_eq, n_in = pr.equalities.numel(), pr.inner_constraints.numel()
        self.opt_nlp = {"x": pr.u, "f": pr.cost,
                        "g": ca.vertcat(pr.equalities, pr.inner_constraints, pr.constraints, pr.outputs)}
        self.opt_bounds = (np.concatenate([np.zeros(n_eq), np.full(n_in + pr.n_g, -np.inf), pr.c_lb]),
                           np.concatenate([np.zeros(n_eq + n_in + pr.n_g), pr.c_ub]))
        self.real_nlp = {"x": pr.u, "p": c, "f": pr.cost,
                         "g": ca.vertcat(pr.equalities, pr.inner_constraints, pr.outputs - c)}
        self.real_bounds = (np.concatenate([np.zeros(n_eq), np.full(n_in, -np.inf), np.zeros(pr.n_c)]),
                            np.zeros(n_eq + n_in + pr.n_c))
        self._cache = {}
        self.report = ca.Function("report", [pr.u], [pr.cost, pr.constraints, pr.outputs, pr.mean_tension,
                                                     pr.node_altitudes])

    def get(self, kind: str, warm: bool):
        key = (kind, warm)
        if key not in self._cache:
            nlp = self.opt_nlp if kind == "opt" else self.real_nlp
            opts = dict(_IPOPT, **(_WARM if warm else {}))
            self._cache[key] = ca.nlpsol(f"{self.problem.name}_{kind}", "ipopt", nlp,
                                         {"ipopt": opts, "print_time": False})
        return self._cache[key]


_SOLVERS: dict[int, tuple[weakref.ref, _Solvers]] = {}


def _solvers(problem: KiteModelProblem) -> _Solvers:
    entry = _SOLVERS.get(id(problem))
    if entry is None or entry[0]() is not problem:
        entry = (weakref.ref(problem), _Solvers(problem))
        _SOLVERS[id(problem)] = entry
        weakref.finalize(problem, _SOLVERS.pop, id(problem), None)
    return entry[1]


def _run(s: _Solvers, kind: str, bounds, p, warm: OCPSolution | None, check: bool,
         cold_x0=None, spent: float = 0.0) -> OCPSolution:
    """Solve once; a failed warm start is retried cold from ``cold_x0()`` (or ``u0``), adding its time."""
    pr = s.problem
    solver = s.get(kind, warm is not None)
    args = {"lbx": pr.lbu, "ubx": pr.ubu, "lbg": bounds[0], "ubg": bounds[1]}
    if p is not None:
        args["p"] = p
    if warm is None:
        args["x0"] = pr.u0 if cold_x0 is None else cold_x0()
    else:
        args.update(x0=warm.u, lam_x0=warm.lam_x)
        if warm.lam_g.size == bounds[0].size:
            args["lam_g0"] = warm.lam_g
    t0 = time.perf_counter()
    sol = solver(**args)
    elapsed = time.perf_counter() - t0 + spent
    stats = solver.stats()
    if warm is not None and not stats["success"]:   # a warm start at a bang-bang vertex can stall: go cold
        return _run(s, kind, bounds, p, None, check, cold_x0, elapsed)
    if check and not stats["success"]:
        raise OCPSolveError(f"{pr.name}: IPOPT {kind} solve failed: {stats['return_status']}")
    return _solution(pr, s, sol, stats, elapsed)


def _solution(pr: KiteModelProblem, s: _Solvers, sol, stats, elapsed) -> OCPSolution:
    u = np.asarray(sol["x"]).ravel()
    cost, g, y, tension, z = (np.asarray(v).ravel() for v in s.report(u))
    parts = unpack(u, pr.settings)
    z_min = float(np.min(z))
    st = pr.settings
    g_m = float(g[0]) * st.constraint_unit
    return OCPSolution(
        u=u, c=y, cost=float(cost[0]), g=float(g[0]),
        mean_tension_kn=float(tension[0]) / 1000.0, min_altitude=z_min,
        softmin_bias=z_min - (pr.h_min - g_m), period=parts["period"], delta=parts["delta"],
        states=parts["states"], t=parts["t"], iterations=int(stats["iter_count"]), solve_time=elapsed,
        status=str(stats["return_status"]), lam_x=np.asarray(sol["lam_x"]).ravel(),
        lam_g=np.asarray(sol["lam_g"]).ravel())


def solve_model_optimum(problem: KiteModelProblem, warm: OCPSolution | None = None,
                        check: bool = True) -> OCPSolution:
    """The model's own optimum: ``min phi(u)`` s.t. dynamics, ``g(u) <= 0``, ``c_lb <= y(u) <= c_ub``, bounds.

    Starts from ``problem.u0``, or warm from a previous solution of the same problem. Raises
    :class:`OCPSolveError` if IPOPT fails and ``check`` is true.
    """
    s = _solvers(problem)
    return _run(s, "opt", s.opt_bounds, None, warm, check)


def realize_setpoints(problem: KiteModelProblem, c, warm: OCPSolution | None = None,
                      check: bool = True) -> OCPSolution:
    """The model's best lap with the given setpoints: ``min phi(u)`` s.t. dynamics, ``y(u) = c``, bounds.

    ``g(u) <= 0`` is *not* imposed (GMA's u_hat(c)). ``c`` = (theta_0, A_phi, A_theta), rad. Starts from the
    figure-eight of ``c`` (:func:`path_guess`) or warm from ``warm`` (any earlier solution of this problem;
    if that warm start fails, it is retried cold, and ``solve_time`` includes both attempts).
    """
    c = np.asarray(c, dtype=float).ravel()
    if c.size != problem.n_c:
        raise ValueError(f"realize_setpoints: c has {c.size} entries, expected {problem.n_c}")
    s = _solvers(problem)
    return _run(s, "real", s.real_bounds, c, warm, check,
                lambda: path_guess(problem.params, problem.settings, c))
