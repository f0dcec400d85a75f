"""The model side of a GMA iteration: the model's optimum, its point at ``c_k`` and its gradients there
(:class:`ModelSide`)."""
from __future__ import annotations

import numpy as np

from ._nlp import NLPPair
from .modifiers import ModelRealization, Modifiers
from .problem import ModelProblem

__all__ = ["ModelSide"]


class ModelSide:
    """Solves the model for GMA: :meth:`optimum`, :meth:`realize`, :meth:`linearize` and :meth:`values`.

    Args:
        problem: the model problem.
        nlps: its two NLPs (:class:`~kite_rto.gma._nlp.NLPPair`, built on first use).
        settings: the :class:`~kite_rto.gma.ModelSettings`.
    """

    def __init__(self, problem: ModelProblem, nlps: NLPPair, settings):
        self.problem, self._nlps, self.settings = problem, nlps, settings

    def optimum(self) -> np.ndarray:
        """``y(u)`` at the model optimum inside the setpoint box (no modifiers, no trust region)."""
        pr = self.problem
        res = self._nlps.get()[1].solve(Modifiers.zero(0.5 * (pr.c_lb + pr.c_ub), pr.n_g),
                                        radius=np.full(pr.n_c, np.inf), x0=pr.u0)
        if not res.success:
            raise RuntimeError(f"GMA: the model optimization failed ({res.status}); pass c0 explicitly")
        return np.clip(pr.evaluate(res.x[: pr.n_u])[2], pr.c_lb, pr.c_ub)

    def realize(self, c) -> ModelRealization:
        """The model's best realization of ``c`` (n_c,) and its gradients with respect to ``c``: ``grad_c phi_hat``
        from the multipliers of ``y(u) = c``, ``grad_c g_hat`` from central differences of warm re-solves."""
        pr, nlp = self.problem, self._nlps.get()[0]
        c = np.asarray(c, float)
        x0 = nlp.last.x if nlp.last is not None else pr.u0
        res = nlp.solve(c, x0)
        jac = np.full((pr.n_g, pr.n_c), np.nan)
        if not res.success:
            return ModelRealization(res.x, res.f, np.full(pr.n_g, np.nan), np.full(pr.n_c, np.nan), jac,
                                    False, res.status)
        _, g, _ = pr.evaluate(res.x)
        if pr.n_g:
            jac = self._jac_g_hat(c, res)
        return ModelRealization(res.x, res.f, g, nlp.value_gradient(res), jac, True, res.status)

    def linearize(self, c, previous: Modifiers) -> ModelRealization:
        """The model point and gradients the modifiers at ``c`` are computed from (``ModelSettings.point``).

        ``"consistent"``: ``u_k = argmin phi(u)`` s.t. ``y(u) = c`` and the ``previous`` iteration's modified
        constraints (shifted to ``c``), gradients ``grad_u(.) R`` (:meth:`ModelProblem.tangent_right_inverse`);
        :meth:`realize` if that solve fails, and always with ``"realization"`` or without constraints.
        """
        pr = self.problem
        c = np.asarray(c, float)
        if self.settings.point == "realization" or pr.n_g == 0:
            return self.realize(c)
        realization, modified = self._nlps.get()
        x0 = realization.last.x if realization.last is not None else pr.u0
        res = modified.solve(previous.shifted(c), radius=np.zeros(pr.n_c), x0=x0)
        if not res.success:
            out = self.realize(c)
            out.status = f"{out.status} (consistent point failed: {res.status})"
            return out
        u = res.x[: pr.n_u]
        phi, g, _ = pr.evaluate(u)
        J, R = pr.jacobians(u), pr.tangent_right_inverse(u)
        return ModelRealization(u, phi, g, (J["dphi"] @ R).ravel(), J["dg"] @ R, True, res.status)

    def values(self, c, x0) -> tuple:
        """``(phi_hat, g_hat)`` of the model's realization of ``c`` (``min phi s.t. y(u) = c``, started from ``x0``;
        the solver's remembered solution is not replaced), NaN when it fails."""
        pr = self.problem
        res = self._nlps.get()[0].solve(np.asarray(c, float), x0, keep=False)
        if not res.success:
            return np.nan, np.full(pr.n_g, np.nan)
        phi, g, _ = pr.evaluate(res.x)
        return phi, g

    def _jac_g_hat(self, c, base):
        """Central differences of warm-started re-solves, ``h = fd_step * box width``; one-sided where a re-solve
        fails."""
        pr, nlp = self.problem, self._nlps.get()[0]
        jac = np.full((pr.n_g, pr.n_c), np.nan)
        g0 = pr.evaluate(base.x)[1]
        for i in range(pr.n_c):
            h = self.settings.fd_step * pr.c_width[i]
            vals = {}
            for sgn in (1.0, -1.0):
                cc = c.copy()
                cc[i] += sgn * h
                r = nlp.solve(cc, base.x, keep=False)
                if r.success:
                    vals[sgn] = pr.evaluate(r.x)[1]
            if len(vals) == 2:
                jac[:, i] = (vals[1.0] - vals[-1.0]) / (2 * h)
            elif vals:
                sgn, gv = next(iter(vals.items()))
                jac[:, i] = (gv - g0) / (sgn * h)
        nlp.last = base
        return jac
