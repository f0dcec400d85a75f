"""Generalized Modifier Adaptation: the iteration, driven by experiment requests and results.

The core never calls the plant. It asks for experiments (:meth:`GMA.next_request`) and is told their results
(:meth:`GMA.submit`). When all experiments of iteration ``k`` are in, it estimates the plant gradients,
computes the modifiers from the model's best realization of ``c_k``, solves the modified problem, filters
the step and records an :class:`IterationRecord`.
"""
from __future__ import annotations

import math
import time
from copy import deepcopy
from types import SimpleNamespace
from dataclasses import dataclass, replace

import numpy as np

from ._nlp import ModifiedNLP, NLPPair, RealizationNLP
from .directional import DirectionalGradient
from .effort import NoiseTest, average, fold_repeats, noise_test, repeat_requests
from .gradients import FiniteDifferenceGradient, GradientEstimate, GradientEstimator, PlantPoint
from .model_secant import model_secant_estimate
from .modifiers import Decision, ModelRealization, Modifiers
from .noise_filter import noise_gain
from .problem import ModelProblem
from .records import ExperimentRequest, ExperimentResult, History, IterationRecord
from .settings import GMASettings, per_setpoint
from .safety import observed_curvature, safe_fraction, step_weights, truncation_bound
from .kkt import kkt_test
from .structure import bound_side, excluded_directions, structure_plan, structure_test

__all__ = ["GMA"]


@dataclass
class _Proposal:
    """The outcome of the modified problem in one iteration: where it points and what GMA decided."""

    decision: Decision
    detail: str
    modifiers: Modifiers
    u_star: np.ndarray
    cost: float
    status: str
    c_star: np.ndarray
    nu: np.ndarray | None = None        # multipliers of the modified constraints (n_g,), >= 0; None when not solved


_NOT_SOLVED = "not solved"


class GMA:
    """Generalized Modifier Adaptation on a :class:`ModelProblem`, through requests and results.

    Args:
        problem: the open-loop model with controlled variables ``y(u)`` and the setpoint box.
        settings: :class:`GMASettings` (defaults if ``None``).
        gradient: plant-gradient strategy (default: forward differences with 1 % of the box width).
        c0: initial setpoints (n_c,); default: ``y(u)`` at the model optimum. Ignored when resuming.
        history: a :class:`History` to resume from; finished experiments are not requested again.
    """

    def __init__(self, problem: ModelProblem, settings: GMASettings | None = None,
                 gradient: GradientEstimator | None = None, c0=None, history: History | None = None):
        self.problem = problem
        self.settings = settings if settings is not None else GMASettings()
        s, n_c, n_g = self.settings, problem.n_c, problem.n_g
        self._width = problem.c_width
        self._K = per_setpoint("filter_gain", s.filter_gain, n_c)
        self._radius0 = per_setpoint("trust_radius", s.trust_radius, n_c)
        self._max_step = per_setpoint("max_step", s.max_step, n_c) * self._width
        self._q = per_setpoint("convexification", s.convexification, n_c)
        self._backoff = per_setpoint("backoff", s.backoff, n_g) if n_g else np.zeros(0)
        self.gradient = gradient if gradient is not None else FiniteDifferenceGradient(0.01 * self._width)
        self._nlps = NLPPair(problem, s)
        if history is not None:
            self.history = deepcopy(history)
            self._resume()
        else:
            c0 = self.model_optimum() if c0 is None else np.asarray(c0, float).ravel()
            if c0.size != n_c:
                raise ValueError(f"GMA: c0 has {c0.size} entries, expected n_c={n_c}")
            if np.any(c0 < problem.c_lb) or np.any(c0 > problem.c_ub):
                raise ValueError(f"GMA: c0={c0.tolist()} outside the setpoint box")
            self.history = History(c0=c0.copy(), meta={"problem": problem.name, "n_u": problem.n_u,
                                                        "n_c": n_c, "n_g": n_g, "settings": s.to_dict()})
            self._k, self._c = 0, c0.copy()
            self._radius, self._prev_step = self._radius0.copy(), np.zeros(n_c)
            self._prev_mod = Modifiers.zero(c0, n_g, self._backoff)
            self._plan()

    # ------------------------------------------------------------------ public interface
    @property
    def realization_nlp(self) -> RealizationNLP:
        """The model's best realization of setpoints (created on first use, see :meth:`prepare`)."""
        return self._nlps.get()[0]

    @property
    def modified_nlp(self) -> ModifiedNLP:
        """The modified problem (created on first use, see :meth:`prepare`)."""
        return self._nlps.get()[1]

    def prepare(self) -> None:
        """Create the two NLPs now (about 3 s for the kite) instead of at the first iteration's end.

        It may run on a worker thread while the first experiments run, provided no other thread calls into CasADi
        meanwhile: CasADi releases the GIL while it builds, and its symbolic objects are not thread-safe. GMA
        itself only calls CasADi after ``prepare`` has returned (a thread that needs the NLPs waits for it)."""
        self._nlps.get()

    @property
    def k(self) -> int:
        """Index of the open iteration (= number of completed iterations)."""
        return self._k

    @property
    def c(self) -> np.ndarray:
        """Current operating point ``c_k`` (n_c,)."""
        return self._c.copy()

    @property
    def records(self) -> list[IterationRecord]:
        """Completed iterations."""
        return self.history.iterations

    @property
    def converged(self) -> bool:
        """True if the last completed iteration met ``tol_c``."""
        return bool(self.records and self.records[-1].converged)

    def pending_requests(self) -> list[ExperimentRequest]:
        """Requests of the open iteration that have not been submitted yet, in order."""
        done = self.history.finished_ids()
        return [deepcopy(q) for q in self.history.pending if q.request_id not in done]

    def next_request(self) -> ExperimentRequest | None:
        """The next experiment to run; the same request until it is submitted (``None`` never happens in
        normal operation, since a new iteration is planned as soon as one completes)."""
        todo = self.pending_requests()
        return todo[0] if todo else None

    def submit(self, result: ExperimentResult) -> IterationRecord | None:
        """Record a finished experiment. Returns the :class:`IterationRecord` if it completed the iteration (not
        when the iteration's last planned experiment leaves the gradient too noisy and GMA asks for repeats,
        ``GMASettings.max_repeats_noise``).

        Raises ``ValueError`` for an unknown or already submitted ``request_id``, or a result of the wrong size.
        """
        rid = result.request_id
        if rid in self.history.finished_ids():
            raise ValueError(f"GMA.submit: experiment {rid!r} was already submitted")
        req = next((q for q in self.history.pending if q.request_id == rid), None)
        if req is None:
            raise ValueError(f"GMA.submit: unknown request_id {rid!r}; pending: "
                             f"{[q.request_id for q in self.pending_requests()]}")
        if result.constraints.size != self.problem.n_g:
            raise ValueError(f"GMA.submit: result {rid!r} has {result.constraints.size} constraints, "
                             f"expected n_g={self.problem.n_g}")
        if not np.isfinite(result.cost) or not np.all(np.isfinite(result.constraints)):
            raise ValueError(f"GMA.submit: result {rid!r} has non-finite measurements")
        self.history.experiments.append((deepcopy(req), deepcopy(result)))
        if self.pending_requests():
            return None
        return self._complete()

    def model_optimum(self) -> np.ndarray:
        """``y(u)`` at the model optimum inside the setpoint box (no modifiers, no trust region)."""
        pr = self.problem
        res = self.modified_nlp.solve(Modifiers.zero(0.5 * (pr.c_lb + pr.c_ub), pr.n_g),
                                      radius=np.full(pr.n_c, np.inf), convexification=np.zeros(pr.n_c),
                                      penalty=None, x0=pr.u0)
        if not res.success:
            raise RuntimeError(f"GMA: the model optimization failed ({res.status}); pass c0 explicitly")
        return np.clip(pr.evaluate(res.x[: pr.n_u])[2], pr.c_lb, pr.c_ub)

    def realize(self, c) -> ModelRealization:
        """The model's best realization of ``c`` (n_c,) and its gradients with respect to ``c``."""
        pr = self.problem
        c = np.asarray(c, float)
        x0 = self.realization_nlp.last.x if self.realization_nlp.last is not None else pr.u0
        res = self.realization_nlp.solve(c, x0)
        jac = np.full((pr.n_g, pr.n_c), np.nan)
        if not res.success:
            return ModelRealization(res.x, res.f, np.full(pr.n_g, np.nan), np.full(pr.n_c, np.nan), jac,
                                    False, res.status)
        _, g, _ = pr.evaluate(res.x)
        if pr.n_g:
            jac = self._jac_g_hat(c, res)
        return ModelRealization(res.x, res.f, g, self.realization_nlp.value_gradient(res), jac, True, res.status)

    def linearize(self, c) -> ModelRealization:
        """The model point and gradients used for the modifiers at ``c`` (see ``GMASettings.model_point``).

        ``"consistent"``: ``u_k = argmin phi(u)`` s.t. ``y(u) = c`` and the previous iteration's modified
        constraints (shifted to ``c``), gradients ``grad_u(.) R`` (see
        :meth:`ModelProblem.tangent_right_inverse`); falls back to :meth:`realize` if that solve fails.
        """
        pr = self.problem
        c = np.asarray(c, float)
        if self.settings.model_point == "realization" or pr.n_g == 0:
            return self.realize(c)
        x0 = self.realization_nlp.last.x if self.realization_nlp.last is not None else pr.u0
        res = self.modified_nlp.solve(self._prev_mod.shifted(c), radius=np.zeros(pr.n_c),
                                      convexification=np.zeros(pr.n_c),
                                      penalty=self.settings.constraint_penalty, x0=x0)
        if not res.success:
            out = self.realize(c)
            out.status = f"{out.status} (consistent point failed: {res.status})"
            return out
        u = res.x[: pr.n_u]
        phi, g, _ = pr.evaluate(u)
        J, R = pr.jacobians(u), pr.tangent_right_inverse(u)
        return ModelRealization(u, phi, g, (J["dphi"] @ R).ravel(), J["dg"] @ R, True, res.status)

    # ------------------------------------------------------------------ internals
    def _jac_g_hat(self, c, base):
        """Central differences of warm-started re-solves, ``h = model_fd_step * box width``; one-sided
        where a re-solve fails."""
        pr = self.problem
        jac = np.full((pr.n_g, pr.n_c), np.nan)
        g0 = pr.evaluate(base.x)[1]
        for i in range(pr.n_c):
            h = self.settings.model_fd_step * self._width[i]
            vals = {}
            for sgn in (1.0, -1.0):
                cc = c.copy()
                cc[i] += sgn * h
                r = self.realization_nlp.solve(cc, base.x, keep=False)
                if r.success:
                    vals[sgn] = pr.evaluate(r.x)[1]
            if len(vals) == 2:
                jac[:, i] = (vals[1.0] - vals[-1.0]) / (2 * h)
            elif vals:
                sgn, gv = next(iter(vals.items()))
                jac[:, i] = (gv - g0) / (sgn * h)
        self.realization_nlp.last = base
        return jac

    def _points(self, exclude_iteration: int | None = None) -> list[PlantPoint]:
        """The finished experiments as plant points (repeats averaged with their original), in order."""
        pairs = [(q, r) for q, r in self.history.experiments if q.iteration != exclude_iteration]
        return [_averaged(q, rs) for q, rs in fold_repeats(pairs)]

    def _plan(self) -> None:
        """Plan the experiments of iteration ``k``: the nominal point, then the strategy's perturbations."""
        self.history.pending = self._requests(self._c, f"k{self._k}")

    def _requests(self, c: np.ndarray, tag: str) -> list[ExperimentRequest]:
        """The requests of the open iteration at operating point ``c`` (nominal first), ids ``<tag>-<j>-...``."""
        pr, s, k = self.problem, self.settings, self._k
        past = self._points(exclude_iteration=k)
        lead = {}
        if getattr(self.gradient, "lead", False) and self.history.iterations:   # the last step: c - c_(k-1)
            lead = {"toward": c - np.asarray(self.history.iterations[-1].c_k, float)}
        pert = [np.asarray(x, float)
                for x in self.gradient.plan_iteration(c, pr.c_lb, pr.c_ub, past, self._alternation_index(), **lead)]
        struct = (structure_plan(c, self._excluded(), s.structure_step, pr.c_lb, pr.c_ub)
                  if self._structure_due() else [])
        plan = [(c.copy(), "nominal")] + [(x, "perturbation") for x in pert] + [(x, "structure") for x in struct]
        return [ExperimentRequest(f"{tag}-{j}-{purpose}", x, purpose, k, s.settle_time, s.averaging_at(k))
                for j, (x, purpose) in enumerate(plan)]

    def _alternation_index(self) -> int:
        """The iteration index the gradient estimator plans with: ``k``, or with a finite
        ``GMASettings.alternate_within`` the number of completed iterations since the last step longer than that."""
        within = self.settings.alternate_within
        if math.isinf(within):
            return self._k
        n = 0
        for rec in reversed(self.history.iterations):
            if self._step_widths(rec) > within:
                break
            n += 1
        return n

    def _step_widths(self, record: IterationRecord) -> float:
        """The largest entry of ``record``'s step, in box widths (how ``alternate_within``, ``structure_stall`` and
        ``model_secant_within`` measure a step)."""
        return float(np.max(np.abs(record.step) / self._width))

    def _excluded(self) -> np.ndarray:
        """(n_c, m) the directions the gradient estimator leaves to the model (none unless directional)."""
        if isinstance(self.gradient, DirectionalGradient):
            return excluded_directions(self.gradient.U, self._width)
        return np.zeros((self.problem.n_c, 0))

    def _structure_due(self) -> bool:
        """Whether the open iteration runs the structure check (``GMASettings.structure_check_every``,
        ``structure_stall``): only when some direction is left to the model."""
        s = self.settings
        if not s.structure_check or self._excluded().shape[1] == 0:
            return False
        if s.structure_check_every > 0 and self._k % s.structure_check_every == 0:
            return True
        return self._stalled()

    def _stalled(self) -> bool:
        """The last completed iteration's step was at most ``structure_stall`` box widths in every setpoint."""
        s, recs = self.settings, self.history.iterations
        return bool(s.structure_stall > 0 and recs
                    and self._step_widths(recs[-1]) <= s.structure_stall)

    def plan_at(self, c) -> list[ExperimentRequest]:
        """An operator's operating point: the requests the open iteration ``k`` would have at ``c`` (n_c,), inside
        the setpoint box, without changing anything (pass them to :meth:`replace_plan` once they are stored).

        Ids are ``k<k>m<n>-<j>-nominal|perturbation``, ``n`` = 1 + the operator points already given in iteration
        ``k``, so they never repeat a stored id. ``ValueError`` names a ``c`` of the wrong size, not finite or
        outside the box."""
        pr = self.problem
        c = np.asarray(c, float).ravel()
        if c.size != pr.n_c or not np.all(np.isfinite(c)):
            raise ValueError(f"GMA.plan_at: c = {c.tolist()}: expected {pr.n_c} finite values")
        if np.any(c < pr.c_lb) or np.any(c > pr.c_ub):
            raise ValueError(f"GMA.plan_at: c = {c.tolist()}: outside the setpoint box [{pr.c_lb.tolist()}, "
                             f"{pr.c_ub.tolist()}]")
        k = self._k
        ids = [q.request_id for q, _ in self.history.experiments] + [q.request_id for q in self.history.pending]
        moves = {i.split("-")[0] for i in ids if i.startswith(f"k{k}m")}
        return self._requests(c, f"k{k}m{len(moves) + 1}")

    def replace_plan(self, requests: list[ExperimentRequest]) -> None:
        """Continue the open iteration from the nominal point of ``requests`` (from :meth:`plan_at`): it becomes
        ``c_k``; experiments of the iteration finished at the old point stay in the history, unused by it."""
        if not requests or requests[0].purpose != "nominal" or any(q.iteration != self._k for q in requests):
            raise ValueError(f"GMA.replace_plan: expected the requests of iteration {self._k}, nominal first "
                             f"(from plan_at), got {[q.request_id for q in requests]}")
        self._c = np.asarray(requests[0].c, float).copy()
        self.history.pending = deepcopy(requests)

    def _resume(self) -> None:
        h, n_c, n_g = self.history, self.problem.n_c, self.problem.n_g
        for rec in h.iterations:                     # directions the structure check restored, in order
            if rec.restored_directions and isinstance(self.gradient, DirectionalGradient):
                self.gradient = self.gradient.with_directions(np.asarray(rec.restored_directions, float).T)
        if h.iterations:
            last = h.iterations[-1]
            self._k, self._c = last.k + 1, last.c_next.copy()
            self._radius, self._prev_step = last.trust_radius_next.copy(), last.step.copy()
            if last.modified_status == _NOT_SOLVED or not np.all(np.isfinite(last.u_star)):
                prev = [r for r in h.iterations if np.all(np.isfinite(r.u_star))]
                last = prev[-1] if prev else None
            self._prev_mod = (Modifiers(last.c_k.copy(), last.eps.copy(), last.lam.copy(), last.mu.copy(),
                                        last.backoff.copy())
                              if last is not None else Modifiers.zero(h.c0, n_g, self._backoff))
        else:
            self._k, self._c = 0, np.asarray(h.c0, float).copy()
            self._radius, self._prev_step = self._radius0.copy(), np.zeros(n_c)
            self._prev_mod = Modifiers.zero(self._c, n_g, self._backoff)
        if self._c.size != n_c:
            raise ValueError(f"GMA: history has {self._c.size} setpoints, the problem has n_c={n_c}")
        if not h.pending or h.pending[0].iteration != self._k:
            self._plan()
            return
        if h.pending[0].purpose == "nominal":       # the open iteration's point (an operator's, see replace_plan)
            self._c = np.asarray(h.pending[0].c, float).copy()
        if not self.pending_requests():
            self._complete()

    def _complete(self) -> IterationRecord | None:
        """Close iteration ``k``: gradients, modifiers, the modified problem, the filtered step, the record.
        ``None`` (nothing closed) when the gradient experiments must be flown again (:meth:`_ask_repeats`)."""
        if self._ask_repeats():
            return None
        self.prepare()          # before any CasADi call here: a worker thread may still be building the NLPs
        t0 = time.perf_counter()
        pr, s, k, c_k = self.problem, self.settings, self._k, self._c.copy()
        ordered = self._experiments_of(k)
        groups = fold_repeats(ordered)
        nominal = _averaged(*groups[0])
        new = [_averaged(q, rs) for q, rs in groups[1:] if q.purpose != "structure"]
        struct = [_averaged(q, rs) for q, rs in groups[1:] if q.purpose == "structure"]
        model = self.linearize(c_k)
        est = self._estimate(c_k, nominal, new, model)
        notes = [est.notes] if est.notes else []
        noise = self._noise_test(groups)
        if noise is not None:
            notes.append(noise.describe())
        est, restored = self._check_structure(c_k, nominal, new, struct, model, est, notes)
        mods, spread = self._modifiers(c_k, nominal, model, est, notes)
        radius_abs = self._radius * self._width
        prop = self._propose(mods, spread, nominal, model, est, radius_abs, notes)
        if s.structure_kkt and struct and prop.nu is not None and self._stalled():
            restored = restored + self._kkt_release(c_k, nominal, struct, prop.nu, restored, notes)
        radius_used = self._radius.copy()
        back = self._undo_target(c_k, nominal, notes)
        if back is not None:        # the plant measured the last step as a loss: go back, trust the model less
            step, c_next, decision, detail = back - c_k, back, Decision.UNDONE, ""
            self._shrink_radius(step != 0)
        else:
            step, c_next, decision, detail = self._step(c_k, prop, nominal, model, est, radius_abs, notes)
        rec = IterationRecord(
            k=k, c_k=c_k, cost=nominal.cost, constraints=nominal.constraints, grad_cost=est.cost,
            jac_constraints=est.constraints.reshape(pr.n_g, pr.n_c), gradient_quality=est.quality,
            gradient_method=est.method, phi_hat=model.phi, g_hat=model.g, grad_phi_hat=model.grad_phi,
            jac_g_hat=model.jac_g, u_hat=model.u, model_status=model.status, eps=mods.eps, lam=mods.lam,
            mu=mods.mu, backoff=prop.modifiers.backoff, u_star=prop.u_star, modified_cost=prop.cost,
            modified_status=prop.status, c_star=prop.c_star, step=step, c_next=c_next, trust_radius=radius_used,
            trust_radius_next=self._radius.copy(), converged=decision is Decision.CONVERGED,
            decision=decision.describe(detail), notes=notes, solve_time=time.perf_counter() - t0,
            experiment_ids=[q.request_id for q, _ in ordered], restored_directions=restored,
            gradient_experiments=sum(len(rs) for q, rs in groups if q.purpose in ("nominal", "perturbation")),
            grad_cost_std=None if est.cost_std is None else np.asarray(est.cost_std, float).copy())
        self.history.iterations.append(rec)
        self._k, self._c = k + 1, c_next
        if decision.moved or decision is Decision.UNDONE:
            self._prev_step = step
        self._plan()
        return rec

    def _step(self, c_k, prop: _Proposal, nominal: PlantPoint, model: ModelRealization, est: GradientEstimate,
              radius_abs: np.ndarray, notes: list[str]) -> tuple:
        """``(step, c_next, decision, detail)`` towards the modified problem's solution: filtered, bounded, made
        safe (``safe_curvature``), the trust region adapted; ``CONVERGED`` when the unscaled step met ``tol_c``."""
        pr, s = self.problem, self.settings
        step = np.clip(self._K * (prop.c_star - c_k), -self._max_step, self._max_step)
        c_next = np.clip(c_k + step, pr.c_lb, pr.c_ub)
        step = c_next - c_k
        unscaled, alpha = step.copy(), 1.0
        if prop.decision is Decision.STEP and pr.n_g and s.safe_curvature is not None:
            safe_est, model_jac = est, np.asarray(model.jac_g, float).reshape(pr.n_g, pr.n_c)
            if s.safe_filtered and np.all(np.isfinite(model_jac)):     # the modified problem's own Jacobian
                safe_est = replace(est, constraints=model_jac + prop.modifiers.mu.reshape(pr.n_g, pr.n_c))
            alpha = self._safe_alpha(step, nominal, safe_est, notes, model_jac)
            step = alpha * step
            c_next = c_k + step
        self._adapt_trust_region(step, prop.c_star - c_k, radius_abs)
        if alpha < 1.0 and s.safe_shrink:   # the modified problem disagrees with the measured plant: trust it less
            self._shrink_radius()
        decision, detail = prop.decision, prop.detail
        if decision is Decision.STEP and bool(np.all(np.abs(unscaled) <= s.tol_c * self._width)):
            decision, detail = Decision.CONVERGED, ""
        return step, c_next, decision, detail

    def _undo_target(self, c_k, nominal: PlantPoint, notes: list[str]) -> np.ndarray | None:
        """``c_{k-1}`` when the measured step test (``GMASettings.reject_sigma``) undoes the step that led to
        ``c_k`` (noted), else ``None``: GMA's own step led there, ``c_{k-1}`` met its measured constraints, and the
        nominal cost rose by more than ``reject_sigma`` standard errors of the difference (from the pooled noise,
        :meth:`_pooled_cost_variance`, and each nominal experiment's averaging)."""
        z, recs = self.settings.reject_sigma, self.history.iterations
        if z is None or not recs:
            return None
        prev = recs[-1]
        if prev.outcome is not Decision.STEP or not np.array_equal(prev.c_next, c_k) or np.any(prev.constraints > 0):
            return None
        unit = self._pooled_cost_variance()
        if unit is None:
            return None
        rise, s = nominal.cost - prev.cost, self.settings
        se = math.sqrt(unit / s.averaging_at(prev.k) + unit / s.averaging_at(self._k))
        if not rise > z * se:
            return None
        notes.append(f"step undone: the cost measured at c_k is {rise:.4g} above c_(k-1)'s ({rise / se:.3g} "
                     f"standard errors of the difference, > {z:g})")
        return prev.c_k.copy()

    def _experiments_of(self, k: int) -> list:
        """The finished ``(request, result)`` pairs of iteration ``k``, in planned order (nominal first)."""
        results = {q.request_id: (q, r) for q, r in self.history.experiments if q.iteration == k}
        return [results[q.request_id] for q in self.history.pending]

    def _noise_test(self, groups) -> NoiseTest | None:
        """The noise test of the open iteration's gradient experiments (:mod:`~kite_rto.gma.effort`), ``None``
        when ``max_repeats_noise`` is 0 or there is nothing to test."""
        s = self.settings
        grad = [(q, rs) for q, rs in groups if q.purpose in ("nominal", "perturbation")]
        if s.max_repeats_noise == 0 or not grad or grad[0][0].purpose != "nominal":
            return None
        pts = [_averaged(q, rs) for q, rs in grad]
        return noise_test(pts[0], pts[1:], s.noise_ratio, len(grad[0][1]))

    def _ask_repeats(self) -> bool:
        """Effort matched to noise: while the open iteration's cost changes are noisy and its points have been
        flown at most ``max_repeats_noise`` times again, add one more flight of the nominal and of every
        perturbation to the plan. True when requests were added that are not finished yet (on a resume, the
        repeats may already be in the history: the same decisions are taken again, without flying)."""
        while True:
            groups = fold_repeats(self._experiments_of(self._k))
            test = self._noise_test(groups)
            if test is None or not test.noisy or test.flights > self.settings.max_repeats_noise:
                return False
            grad = [(q, rs) for q, rs in groups if q.purpose in ("nominal", "perturbation")]
            tag = self.history.pending[0].request_id.split("-")[0]
            self.history.pending.extend(repeat_requests(grad, len(self.history.pending), tag))
            if self.pending_requests():
                return True

    def _kkt_release(self, c_k, nominal: PlantPoint, struct: list[PlantPoint], nu: np.ndarray,
                     restored: list, notes: list[str]) -> list:
        """The measured-KKT test (:mod:`~kite_rto.gma.kkt`) on each structure experiment that leaves a bound at a
        stalled iterate; a wrong multiplier sign adds the direction to the estimator from the next iteration on.
        Directions the mismatch test restored in this iteration are not added again. Returns the added columns."""
        if not isinstance(self.gradient, DirectionalGradient):
            return []
        pr, s = self.problem, self.settings
        done = [np.asarray(d, float) for d in restored]
        hits = []
        for pt in struct:
            test = kkt_test(c_k, nominal, pt, nu, pr.c_lb, pr.c_ub, s.structure_sigma)
            if test is None:
                continue
            notes.append(test.describe())
            if test.wrong_sign and not any(abs(_cosine(d, test.dc)) > 1 - 1e-9 for d in done):
                hits.append(self._restored_column(test.dc))
        if not hits:
            return []
        self.gradient = self.gradient.with_directions(np.column_stack(hits))
        notes.append(f"measured KKT: {len(hits)} held direction(s) released, measured from the next iteration on")
        return [d.tolist() for d in hits]

    def _estimate(self, c_k, nominal: PlantPoint, new: list[PlantPoint], model: ModelRealization
                  ) -> GradientEstimate:
        """The plant gradients at ``c_k`` from this iteration's experiments and the earlier ones."""
        past = self._points(exclude_iteration=self._k)
        est = self.gradient.estimate_at(c_k, nominal, new, past, model)
        if not (self.settings.model_secant and self._secant_near() and model.success and est.quality > 0
                and np.all(np.isfinite(est.cost)) and np.all(np.isfinite(est.constraints))):
            return est
        est, note = model_secant_estimate(self.gradient, est, c_k, nominal, new, past, model,
                                          lambda c: self._model_values(c, model.u),
                                          self.settings.model_secant_constraints, self.settings.model_secant_cost)
        est.notes = "; ".join(n for n in (est.notes, note) if n)
        return est

    def _secant_near(self) -> bool:
        """Whether the previous iteration's step was within ``model_secant_within`` box widths (always with
        ``inf``; never at ``k = 0`` otherwise). Read from the stored records, so a resumed run decides alike."""
        within = self.settings.model_secant_within
        if math.isinf(within):
            return True
        its = self.history.iterations
        return bool(its) and self._step_widths(its[-1]) <= within

    def _model_values(self, c, x0) -> tuple:
        """``(phi_hat, g_hat)`` of the model's realization of ``c`` (``min phi s.t. y(u) = c``, started from
        ``x0``; the solver's remembered solution is not replaced), NaN when it fails: the model side of
        ``model_secant``."""
        pr = self.problem
        res = self.realization_nlp.solve(np.asarray(c, float), x0, keep=False)
        if not res.success:
            return np.nan, np.full(pr.n_g, np.nan)
        phi, g, _ = pr.evaluate(res.x)
        return phi, g

    def _check_structure(self, c_k, nominal: PlantPoint, new: list[PlantPoint], struct: list[PlantPoint],
                         model: ModelRealization, est: GradientEstimate, notes: list[str]):
        """The measured structure check (:mod:`~kite_rto.gma.structure`): test each structure experiment against
        the estimate; add the directions with a significant mismatch to the directional estimator and, when
        this iteration's points span the enlarged set, re-estimate. Returns ``(estimate, restored directions)``."""
        s = self.settings
        if not struct:
            return est, []
        if not (np.all(np.isfinite(est.cost)) and np.all(np.isfinite(est.constraints))):
            notes.append("structure check skipped: no usable gradient estimate")
            return est, []
        hits = []
        for pt in struct:
            test = structure_test(c_k, nominal, pt, est, s.structure_sigma, s.structure_rel_tol)
            if not np.any(test.dc):
                continue
            notes.append(test.describe())
            if test.significant and isinstance(self.gradient, DirectionalGradient):
                hits.append((pt, self._restored_column(test.dc)))
        if not hits:
            return est, []
        self.gradient = self.gradient.with_directions(np.column_stack([d for _, d in hits]))
        again = self._estimate(c_k, nominal, new + [pt for pt, _ in hits], model)
        if again.quality > 0 and np.all(np.isfinite(again.cost)):
            notes.append(f"structure check: {len(hits)} direction(s) restored, gradient re-estimated "
                         f"({again.method})")
            est = again
        else:
            notes.append(f"structure check: {len(hits)} direction(s) restored from the next iteration on")
        return est, [d.tolist() for _, d in hits]

    def _safe_alpha(self, step: np.ndarray, nominal: PlantPoint, est: GradientEstimate, notes: list[str],
                    model_jac: np.ndarray | None = None) -> float:
        """The largest ``alpha`` in [0, 1] such that ``alpha * step`` keeps the predicted plant constraints within
        ``safe_tolerance`` (:mod:`~kite_rto.gma.safety`); noted when it is below 1. ``model_jac`` is the model's own
        constraint Jacobian at ``c_k``: with ``GMASettings.safe_model_slope`` (always, or where the step
        extrapolates the estimate) each constraint's change is predicted with the worse of the estimated and the
        model's slope."""
        s, n_g, w = self.settings, self.problem.n_g, self._width
        if not np.all(np.isfinite(est.constraints)):
            notes.append("safe step: no finite constraint gradient, step not taken")
            return 0.0
        g_std = np.zeros(n_g) if nominal.constraints_std is None else np.asarray(nominal.constraints_std, float)
        slope_std = np.zeros(n_g)
        if est.cost_std is not None and nominal.cost_std:   # same design: the cost's derivative std, rescaled
            slope_std = float(np.abs(step) @ np.asarray(est.cost_std, float)) * g_std / nominal.cost_std
        recs = self.history.iterations
        stds = [getattr(pt, "constraints_std", None) for pt in self._nominal_results(recs)] + [
            nominal.constraints_std]
        current = SimpleNamespace(c_k=self._c, c_next=self._c, constraints=nominal.constraints,
                                  jac_constraints=est.constraints)
        seen = observed_curvature(list(recs) + [current], stds, w, s.safe_sigma, s.safe_adapt_min_step, n_g,
                                  s.safe_both_ends)
        M = np.maximum(per_setpoint("safe_curvature", s.safe_curvature, n_g), seen)
        tol = per_setpoint("safe_tolerance", s.safe_tolerance, n_g)
        trunc = np.zeros(n_g)
        if s.safe_truncation and est.displacements is not None:
            trunc = M * truncation_bound(est.displacements, step, w)
        change = est.constraints.reshape(n_g, -1) @ step
        slope = change + trunc
        mode = s.safe_model_slope
        usable = model_jac is not None and bool(np.all(np.isfinite(model_jac)))
        use_model = usable and (mode is True or (mode == "extrapolated" and _extrapolates(est, step, w)))
        if use_model:
            model_change = model_jac @ step
            slope = np.maximum(slope, model_change)
        elif usable and mode == "terms" and _extrapolates(est, step, w):
            use_model = True
            model_change = _pessimistic_terms(est, model_jac, step, w, n_g)
            slope = model_change + trunc
        alpha, j = safe_fraction(nominal.constraints, g_std, slope, slope_std, M,
                                 float(np.sum((step / w) ** 2)), s.safe_sigma, tol)
        if j is not None:
            notes.append(f"safe step: scaled by {alpha:.3g} (g[{j}] = {nominal.constraints[j]:+.4g}, predicted "
                         f"change {float(change[j]):+.4g}, "
                         + (f"truncation bound {trunc[j]:+.4g}, " if s.safe_truncation else "")
                         + (f"model's change {float(model_change[j]):+.4g}, " if use_model else "")
                         + f"curvature bound {M[j]:.4g})" + ("; trust region shrunk" if s.safe_shrink else ""))
        return alpha

    def _pooled_cost_variance(self) -> float | None:
        """The variance of one experiment's cost per unit of averaging, pooled over every finished experiment
        (``cost_std^2`` times the request's ``averaging``, averaged): a standard error from a few laps is itself
        uncertain, and the plant's noise is taken as stationary (as the noise-matched filter does). ``None`` when
        no experiment carried a ``cost_std``."""
        v = [r.cost_std ** 2 * q.averaging for q, r in self.history.experiments if r.cost_std is not None]
        return float(np.mean(v)) if v else None

    def _restored_column(self, dc: np.ndarray) -> np.ndarray:
        """The estimator column for a restored direction ``dc``: scaled so that its perturbation
        (``step * column``) is as long, in box widths, as the existing directions' on average."""
        U, w = self.gradient.U, self._width
        size = float(np.mean(np.max(np.abs(U) / w[:, None], axis=0)))
        return dc * size / float(np.max(np.abs(dc) / w))

    def _modifiers(self, c_k, nominal: PlantPoint, model: ModelRealization, est: GradientEstimate,
                   notes: list[str]) -> tuple:
        """``(Modifiers, sigma)``: plant minus model at ``c_k``, gradient modifiers filtered with ``modifier_filter``
        or the noise-matched filter (noted), and the filtered cost modifier's standard deviation per setpoint (n_c,)
        (``GMASettings.cost_sigma``)."""
        eps = nominal.constraints - model.g
        lam = est.cost - model.grad_phi
        mu = est.constraints - model.jac_g
        s = self.settings
        b = s.modifier_filter
        prev = None if b == 1.0 and s.modifier_drift is None else next(
            (r for r in reversed(self.history.iterations) if _finite_modifiers(r)), None)
        own_std = np.zeros(self.problem.n_c) if est.cost_std is None else np.asarray(est.cost_std, float)
        spread = own_std
        if prev is not None and np.all(np.isfinite(lam)) and np.all(np.isfinite(mu)):
            chain = self._noise_chain(c_k, est)
            b_mu = None
            spread = own_std * np.sqrt(b / (2.0 - b))     # the fixed filter's stationary std
            if chain is not None:
                b, P = noise_gain(*chain, s.modifier_drift, self._width)
                spread = np.sqrt(P)
                notes.append(f"modifiers filtered by noise (gain {np.round(b, 3).tolist()})")
                b_mu = self._constraint_gains(chain, nominal)
                if b_mu is not None:
                    notes.append(f"constraint modifiers filtered by their own noise (gain "
                                 f"{np.round(b_mu, 3).tolist()})")
            else:
                notes.append(f"modifiers filtered (b = {b:g})")
            lam = (1.0 - b) * prev.lam + b * lam
            b_mu = b if b_mu is None else b_mu
            mu = (1.0 - b_mu) * prev.mu.reshape(mu.shape) + b_mu * mu
        return Modifiers(c_k, eps, lam, mu, self._backoff.copy()), spread

    def _nominal_results(self, records) -> list:
        """The nominal :class:`ExperimentResult` of each of ``records`` (``None`` where it has none)."""
        results = {q.request_id: r for q, r in self.history.experiments}
        return [results.get(r.experiment_ids[0]) if r.experiment_ids else None for r in records]

    def _constraint_gains(self, chain, nominal: PlantPoint) -> np.ndarray | None:
        """(n_g, n_c) the gains of ``mu`` with ``GMASettings.constraint_drift``: :func:`noise_gain` over the
        cost's chain with each constraint's own standard deviations (the gradient's ``cost_std`` rescaled by the
        constraint's measured standard deviation over the cost's, per iteration) and drift bound; ``None`` when
        the setting is off or some iteration of the chain lacks those standard deviations."""
        s, pr = self.settings, self.problem
        if s.constraint_drift is None or not pr.n_g:
            return None
        points, cost_stds = chain
        recs = self.history.iterations[len(self.history.iterations) - (len(points) - 1):]
        nominals = self._nominal_results(recs) + [nominal]
        ratios = []
        for pt in nominals:
            if pt is None or not pt.cost_std or pt.constraints_std is None:
                return None
            ratios.append(np.asarray(pt.constraints_std, float).reshape(pr.n_g) / pt.cost_std)
        drift = per_setpoint("constraint_drift", s.constraint_drift, pr.n_g)
        gains = [noise_gain(points, [sd * r[j] for sd, r in zip(cost_stds, ratios)], drift[j], self._width)[0]
                 for j in range(pr.n_g)]
        return np.array(gains).reshape(pr.n_g, pr.n_c)

    def _noise_chain(self, c_k, est: GradientEstimate):
        """``(points, stds)`` of the noise-matched modifier filter (:mod:`~kite_rto.gma.noise_filter`): the
        iterations since the last one without finite modifiers or a standard deviation, then ``est``; ``None``
        when the filter is off (``modifier_drift`` unset) or ``est`` has no standard deviation."""
        if self.settings.modifier_drift is None or est.cost_std is None:
            return None
        points, stds = [c_k], [np.asarray(est.cost_std, float)]
        for r in reversed(self.history.iterations):
            if r.grad_cost_std is None or not _finite_modifiers(r):
                break
            points.insert(0, r.c_k)
            stds.insert(0, np.asarray(r.grad_cost_std, float))
        return points, stds

    def _propose(self, mods: Modifiers, spread: np.ndarray, nominal: PlantPoint, model: ModelRealization,
                 est: GradientEstimate, radius_abs: np.ndarray, notes: list[str]) -> _Proposal:
        """Solve the modified problem at ``mods.c`` inside the trust region, or say why GMA holds; ``spread`` is
        the filtered cost modifier's standard deviation (n_c,) of the pessimistic cost.

        A failed solve shrinks the trust radius; a solved one becomes the next consistent model point."""
        pr, s, c_k = self.problem, self.settings, mods.c
        hold = _Proposal(Decision.HOLD_NO_REALIZATION, "", mods, np.full(pr.n_u, np.nan), np.nan, _NOT_SOLVED,
                         c_k.copy())
        if not model.success:
            notes.append(f"realization status {model.status}")
            return hold
        if not (np.all(np.isfinite(mods.lam)) and np.all(np.isfinite(mods.mu)) and est.quality > 0):
            return replace(hold, decision=Decision.HOLD_BAD_GRADIENT)
        if pr.n_g and s.backoff_std_factor > 0 and nominal.constraints_std is not None:
            mods = replace(mods, backoff=mods.backoff + s.backoff_std_factor * nominal.constraints_std)
        pessimism = None
        if s.cost_sigma > 0 and s.cost_sigma_after <= self._k and (s.cost_sigma_until is None
                                                                  or self._k < s.cost_sigma_until):
            pessimism = s.cost_sigma * np.nan_to_num(spread, nan=0.0, posinf=0.0)
            notes.append(f"pessimistic cost: {s.cost_sigma:g} x sigma {np.round(spread, 4).tolist()}")

        def solve(radius):
            return self.modified_nlp.solve(mods, radius=radius, convexification=self._q,
                                           penalty=s.constraint_penalty, x0=model.u, spread=pessimism)
        res = self._hold_bounds(c_k, spread, radius_abs, solve, solve(radius_abs), notes)
        if not res.success:
            self._shrink_radius()
            return replace(hold, decision=Decision.HOLD_SOLVE_FAILED, modifiers=mods, cost=res.f, status=res.status)
        self._prev_mod = replace(mods, c=c_k.copy(), eps=mods.eps.copy(), mu=mods.mu.copy(),
                                 backoff=mods.backoff.copy())
        u_star = res.x[: pr.n_u]
        c_star = np.clip(pr.evaluate(u_star)[2], pr.c_lb, pr.c_ub)
        at_bound = np.abs(c_star - c_k) >= 0.999 * radius_abs
        if pr.n_g and res.x.size > pr.n_u and np.any(res.x[pr.n_u:] > 1e-8):
            notes.append("soft constraints violated in the modified problem")
        detail = f"trust region active on c{np.flatnonzero(at_bound).tolist()}" if at_bound.any() else ""
        return _Proposal(Decision.STEP, detail, mods, u_star, res.f, res.status, c_star,
                         np.maximum(res.lam_g[: pr.n_g], 0.0))

    def _hold_bounds(self, c_k, spread, radius_abs, solve, res, notes: list[str]):
        """The modified problem with the setpoints at a bound of the box held there (zero trust radius) where
        holding is not measurably wrong (``GMASettings.bound_sigma``), else ``res``, the problem solved without
        holding (``solve(radius)`` solves it with other trust radii). Holding is wrong where the held problem's
        multiplier of that setpoint (the modified Lagrangian's descent into the box at the held solution: the
        measured-KKT test at the box's bounds) exceeds ``bound_sigma`` standard deviations of the filtered cost
        modifier (``spread``); such setpoints are released and the rest solved again, once. Nothing is held before
        ``bound_sigma_after`` or after a failed ``res``, nor, with ``bound_sigma_start`` False, at the bound the
        run started on (``history.c0``)."""
        pr, s = self.problem, self.settings
        if s.bound_sigma is None or self._k < s.bound_sigma_after or not res.success:
            return res
        side = bound_side(c_k, pr.c_lb, pr.c_ub, 1e-9)
        if not s.bound_sigma_start:
            side = np.where(side == bound_side(self.history.c0, pr.c_lb, pr.c_ub, 1e-9), 0, side)
        held = side != 0
        limit = s.bound_sigma * np.nan_to_num(np.asarray(spread, float), nan=np.inf)
        for _ in range(2):
            if not held.any():
                break
            kept = solve(np.where(held, 0.0, radius_abs))
            if not kept.success:
                break
            inward = -side * np.asarray(kept.lam_g[pr.n_g: pr.n_g + pr.n_c], float)   # > 0: wants into the box
            keep = held & (inward < limit)
            if np.array_equal(keep, held):
                notes.append(f"bound held: c{np.flatnonzero(held).tolist()} stay at their bounds (the modified "
                             f"Lagrangian's descent into the box, {np.round(inward[held], 4).tolist()}, is below "
                             f"{s.bound_sigma:g} standard deviations)")
                return kept
            held = keep
        self.modified_nlp.last = res         # the next warm start as without the held solves
        return res

    def _shrink_radius(self, where=True) -> None:
        """Multiply the trust radius by ``trust_shrink`` (not below ``trust_radius_min``) in the setpoints
        ``where`` is true (a bool or a per-setpoint mask)."""
        s = self.settings
        self._radius = np.where(where, np.maximum(self._radius * s.trust_shrink, s.trust_radius_min), self._radius)

    def _adapt_trust_region(self, step, proposed, radius_abs) -> None:
        """Per setpoint: shrink on a sign change of the step, grow when the bound was hit without one."""
        s = self.settings
        if not s.trust_adapt:
            return
        flip = step * self._prev_step < 0
        hit = (np.abs(proposed) >= 0.999 * radius_abs) & ~flip
        self._shrink_radius(flip)
        self._radius = np.where(hit, np.minimum(self._radius * s.trust_grow, self._radius0), self._radius)


def _pessimistic_terms(est: GradientEstimate, model_jac: np.ndarray, step: np.ndarray, width: np.ndarray,
                       n_g: int) -> np.ndarray:
    """(n_g,) each constraint's predicted change over ``step``, term by term: the step is ``sum_i a_i p_i + r``
    over the fitted points ``p_i`` (:func:`~kite_rto.gma.safety.step_weights`) plus a remainder ``r`` outside
    their span; a term with ``a_i >= 0`` (interpolated) and the remainder are predicted with the estimated
    Jacobian, a term with ``a_i < 0`` (a difference taken on the other side of ``c_k``, extrapolated across it) with
    the worse (larger) of the estimated and the model's Jacobian."""
    J = est.constraints.reshape(n_g, -1)
    P = np.asarray(est.displacements, float).reshape(-1, step.size)
    a = step_weights(P, step, width)
    change = J @ (step - P.T @ a)
    for a_i, p_i in zip(a, P):
        measured = a_i * (J @ p_i)
        change = change + (np.maximum(measured, a_i * (model_jac @ p_i)) if a_i < -1e-9 else measured)
    return change


def _extrapolates(est: GradientEstimate, step: np.ndarray, width: np.ndarray) -> bool:
    """The estimate predicts the change over ``step`` with a negative weight on some fitted point
    (:func:`~kite_rto.gma.safety.step_weights`): a difference taken on the other side of ``c_k`` than the step."""
    if est.displacements is None or not np.any(step):
        return False
    return bool(np.any(step_weights(est.displacements, step, width) < -1e-9))


def _finite_modifiers(record: IterationRecord) -> bool:
    """The record's gradient modifiers ``lam`` and ``mu`` are finite (usable by the modifier filters)."""
    return bool(np.all(np.isfinite(record.lam)) and np.all(np.isfinite(record.mu)))


def _plant_point(request: ExperimentRequest, result: ExperimentResult) -> PlantPoint:
    """A finished experiment as the gradient estimators see it."""
    return PlantPoint(request.c, result.cost, result.constraints, result.cost_std, result.constraints_std)


def _averaged(request: ExperimentRequest, results: list[ExperimentResult]) -> PlantPoint:
    """An experiment and its repeats as one plant point (:func:`~kite_rto.gma.effort.average`)."""
    return average([_plant_point(request, r) for r in results])


def _cosine(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(a @ b / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-300))
