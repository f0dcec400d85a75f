"""The two NLPs of a GMA iteration, built once with parameters and warm-started on every call.

* :class:`RealizationNLP` -- the model's best realization of setpoints ``c``:
  ``min phi(u) s.t. y(u) = c, h(u) = 0, g_in(u) <= 0, lbu <= u <= ubu``.
* :class:`ModifiedNLP` -- the modified problem of GMA with trust region and back-off.

Each wraps two IPOPT instances: a warm-started one (previous primal and dual solution, small barrier parameter)
and a cold one used as a fallback when the warm solve fails. Creating the four instances takes about 3 s (CasADi
differentiates the NLPs), so :class:`NLPPair` creates them on first use, or ahead of it on a worker thread.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from .modifiers import Modifiers
from .problem import ModelProblem

__all__ = ["NLPResult", "RealizationNLP", "ModifiedNLP", "NLPPair"]

_WARM = {"warm_start_init_point": "yes", "warm_start_bound_push": 1e-9, "warm_start_slack_bound_push": 1e-9,
         "warm_start_mult_bound_push": 1e-9, "mu_init": 1e-5}


@dataclass
class NLPResult:
    """Outcome of one solve: primal ``x``, multipliers ``lam_g``/``lam_x``, status and timing (s)."""

    x: np.ndarray
    f: float
    g: np.ndarray
    lam_g: np.ndarray
    lam_x: np.ndarray
    success: bool
    status: str
    iterations: int
    solve_time: float
    warm: bool


class _TwoSolvers:
    """A warm and a cold ``nlpsol('ipopt')`` on the same NLP, and the last good solution."""

    def __init__(self, name: str, nlp: dict, settings, tol: float):
        base = {"print_level": 0, "sb": "yes", "max_iter": settings.max_iter, "tol": tol}
        base.update(settings.ipopt_options)
        opts = {"print_time": False, "error_on_fail": False}
        self._cold = ca.nlpsol(f"{name}_cold", "ipopt", nlp, {**opts, "ipopt": base})
        self._warm = ca.nlpsol(f"{name}_warm", "ipopt", nlp, {**opts, "ipopt": {**base, **_WARM}})
        self.last: NLPResult | None = None

    def solve(self, x0, p, lbx, ubx, lbg, ubg, *, warm: bool = True, keep: bool = True) -> NLPResult:
        args = dict(p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        res = None
        if warm and self.last is not None and self.last.success:
            res = self._call(self._warm, True, x0=self.last.x, lam_x0=self.last.lam_x, lam_g0=self.last.lam_g,
                             **args)
        if res is None or not res.success:
            res = self._call(self._cold, False, x0=x0, **args)
        if keep and res.success:
            self.last = res
        return res

    @staticmethod
    def _call(solver, warm, **kwargs) -> NLPResult:
        t0 = time.perf_counter()
        out = solver(**kwargs)
        dt = time.perf_counter() - t0
        st = solver.stats()
        flat = {k: np.asarray(v, dtype=float).ravel() for k, v in out.items()}
        return NLPResult(x=flat["x"], f=float(flat["f"][0]), g=flat["g"], lam_g=flat["lam_g"],
                         lam_x=flat["lam_x"], success=bool(st.get("success", False)),
                         status=str(st.get("return_status", "unknown")), iterations=int(st.get("iter_count", -1)),
                         solve_time=dt, warm=warm)


class _WarmStarted:
    """An NLP wrapper whose :attr:`last` result (the warm start of the next solve) lives in its ``_nlp``."""

    _nlp: _TwoSolvers

    @property
    def last(self) -> NLPResult | None:
        return self._nlp.last

    @last.setter
    def last(self, value: NLPResult | None) -> None:
        self._nlp.last = value


class RealizationNLP(_WarmStarted):
    """``min_u phi(u) s.t. y(u) = c`` (+ equalities, inner constraints, bounds), parameter ``c`` (n_c,)."""

    def __init__(self, problem: ModelProblem, settings):
        """``settings``: the :class:`~kite_rto.gma.ModelSettings` (IPOPT's iteration limit and options)."""
        self.problem = problem
        pr = problem
        c = type(pr.u).sym("c", pr.n_c)
        g = ca.vertcat(pr.outputs - c, pr.equalities, pr.inner_constraints)
        n_h, n_in = pr.equalities.numel(), pr.inner_constraints.numel()
        self._lbg = np.r_[np.zeros(pr.n_c + n_h), -np.inf * np.ones(n_in)]
        self._ubg = np.zeros(pr.n_c + n_h + n_in)
        self._nlp = _TwoSolvers(f"{pr.name}_realize", {"x": pr.u, "p": c, "f": pr.cost, "g": g}, settings, 1e-10)

    def solve(self, c, x0=None, *, keep: bool = True) -> NLPResult:
        """Solve for setpoints ``c`` (n_c,). ``lam_g[:n_c]`` are the multipliers of ``y(u) = c``."""
        pr = self.problem
        x0 = pr.u0 if x0 is None else x0
        return self._nlp.solve(x0, np.asarray(c, float), pr.lbu, pr.ubu, self._lbg, self._ubg, keep=keep)

    def value_gradient(self, res: NLPResult) -> np.ndarray:
        """``grad_c phi_hat`` (n_c,) from the multipliers: ``d/dc [phi + lam^T (y - c)] = -lam``."""
        return -res.lam_g[: self.problem.n_c]



class ModifiedNLP(_WarmStarted):
    """The modified problem of GMA, all modifiers as parameters.

    ``min_u phi(u) + lam^T d``
    ``s.t.  g(u) + eps + mu d + b <= 0,  max(c_lb, c_k - Delta) <= y(u) <= min(c_ub, c_k + Delta),``
    ``h(u) = 0,  g_in(u) <= 0,  lbu <= u <= ubu``, with ``d = y(u) - c_k``.

    The multipliers ``lam_g`` are those of the modified constraints (n_g), of ``y(u)`` (n_c) and of the internal
    constraints, in this order.
    """

    def __init__(self, problem: ModelProblem, settings):
        self.problem = pr = problem
        sym = type(pr.u).sym
        n_c, n_g = pr.n_c, pr.n_g
        c_k, eps, lam = sym("c_k", n_c), sym("eps", n_g), sym("lam", n_c)
        mu, b = sym("mu", n_g, n_c), sym("b", n_g)
        d = pr.outputs - c_k
        f = pr.cost + ca.dot(lam, d)
        g = ca.vertcat(pr.constraints + eps + ca.mtimes(mu, d) + b, pr.outputs, pr.equalities,
                       pr.inner_constraints)
        p = ca.vertcat(c_k, eps, lam, ca.vec(mu), b)
        n_h, n_in = pr.equalities.numel(), pr.inner_constraints.numel()
        self._lbg_tail = np.r_[np.zeros(n_h), -np.inf * np.ones(n_in)]
        self._ubg_tail = np.zeros(n_h + n_in)
        self._nlp = _TwoSolvers(f"{pr.name}_modified", {"x": pr.u, "p": p, "f": f, "g": g}, settings, 1e-9)

    def solve(self, modifiers: Modifiers, *, radius, x0) -> NLPResult:
        """Solve the modified problem around ``c_k = modifiers.c``.

        Args:
            modifiers: the :class:`Modifiers` (``eps``, ``lam``, ``mu`` (n_g, n_c), ``backoff``) at ``c_k``.
            radius: trust-region half-widths (n_c,), setpoint units (``inf`` = none, 0 = ``y(u) = c_k``).
            x0: cold-start guess (n_u,) (the model's realization of ``c_k``).
        """
        pr, m = self.problem, modifiers
        n_g = pr.n_g
        c_k = np.asarray(m.c, float)
        p = np.r_[c_k, m.eps, m.lam, np.asarray(m.mu, float).reshape(n_g, pr.n_c).ravel(order="F"), m.backoff]
        lby = np.maximum(pr.c_lb, c_k - radius)
        uby = np.minimum(pr.c_ub, c_k + radius)
        lbg = np.r_[-np.inf * np.ones(n_g), lby, self._lbg_tail]
        ubg = np.r_[np.zeros(n_g), uby, self._ubg_tail]
        return self._nlp.solve(np.asarray(x0, float), p, pr.lbu, pr.ubu, lbg, ubg)


class NLPPair:
    """GMA's :class:`RealizationNLP` and :class:`ModifiedNLP`, created together on first use.

    :meth:`get` is thread-safe: a worker thread may call it ahead of need (:meth:`kite_rto.gma.GMA.prepare`)
    while another thread that needs the NLPs waits for that build instead of starting a second one.
    """

    def __init__(self, problem: ModelProblem, settings):
        self._args = (problem, settings)
        self._lock = threading.Lock()
        self._pair: tuple[RealizationNLP, ModifiedNLP] | None = None

    def get(self) -> tuple[RealizationNLP, ModifiedNLP]:
        """The two NLPs, created now (in this order) if they do not exist yet."""
        with self._lock:
            if self._pair is None:
                self._pair = (RealizationNLP(*self._args), ModifiedNLP(*self._args))
            return self._pair

    @property
    def built(self) -> bool:
        """True once the NLPs exist."""
        return self._pair is not None
