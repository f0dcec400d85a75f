"""Generalized Modifier Adaptation: the iteration, driven by experiment requests and results.

The core never calls the plant. It asks for experiments (:meth:`GMA.next_request`) and is told their results
(:meth:`GMA.submit`). When all experiments of iteration ``k`` are in, it estimates the plant gradients, computes
the modifiers from the model's point at ``c_k``, solves the modified problem, filters the step, decides, and records
an :class:`IterationRecord`. The optional mechanisms of :class:`GMASettings` take part at the named points of
:mod:`~kite_rto.gma.mechanism`.
"""
from __future__ import annotations

import time
from copy import deepcopy
from dataclasses import replace

import numpy as np

from ._checks import per_setpoint
from ._nlp import ModifiedNLP, NLPPair, RealizationNLP
from .gradients import FiniteDifferenceGradient, GradientEstimator, PlantPoint
from .mechanism import Iteration, Mechanism, Solution
from .model_side import ModelSide
from .modifiers import Decision, ModelRealization, Modifiers
from .problem import ModelProblem
from .records import ExperimentRequest, ExperimentResult, History, IterationRecord
from .settings import GMASettings

__all__ = ["GMA"]

_NOT_SOLVED = "not solved"


class GMA:
    """Generalized Modifier Adaptation on a :class:`ModelProblem`, through requests and results.

    Args:
        problem: the open-loop model with controlled variables ``y(u)`` and the setpoint box.
        settings: :class:`GMASettings` (defaults if ``None``).
        gradient: plant-gradient strategy (default: forward differences with 1 % of the box width).
        c0: initial setpoints (n_c,); default: ``y(u)`` at the model optimum. Ignored when resuming.
        history: a :class:`History` to resume from; finished experiments are not requested again.
        mechanisms: further :class:`~kite_rto.gma.Mechanism` objects, called after those of ``settings``.
    """

    def __init__(self, problem: ModelProblem, settings: GMASettings | None = None,
                 gradient: GradientEstimator | None = None, c0=None, history: History | None = None,
                 mechanisms=()):
        self.problem = problem
        self.settings = s = settings if settings is not None else GMASettings()
        n_c, n_g = problem.n_c, problem.n_g
        self._width = problem.c_width
        self._K = per_setpoint("GMASettings.filter_gain", s.filter_gain, n_c)
        self._backoff = per_setpoint("GMASettings.backoff", s.backoff, n_g) if n_g else np.zeros(0)
        self.gradient = gradient if gradient is not None else FiniteDifferenceGradient(0.01 * self._width)
        self._nlps = NLPPair(problem, s.model)
        self._model = ModelSide(problem, self._nlps, s.model)
        self._extra = list(mechanisms)
        self.mechanisms: list[Mechanism] = s.build(problem) + self._extra
        if history is not None:
            self.history = deepcopy(history)
            self._resume()
            return
        c0 = self.model_optimum() if c0 is None else np.asarray(c0, float).ravel()
        if c0.size != n_c:
            raise ValueError(f"GMA: c0 has {c0.size} entries, expected n_c={n_c}")
        if np.any(c0 < problem.c_lb) or np.any(c0 > problem.c_ub):
            raise ValueError(f"GMA: c0={c0.tolist()} outside the setpoint box")
        self.history = History(c0=c0.copy(), meta={"problem": problem.name, "n_u": problem.n_u, "n_c": n_c,
                                                    "n_g": n_g, "settings": s.to_dict()})
        self._k, self._c = 0, c0.copy()
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
        """Create the two NLPs now (seconds for an OCP) instead of at the first iteration's end.

        It may run on a worker thread while the first experiments run, provided no other thread calls into CasADi
        meanwhile: CasADi releases the GIL while it builds, and its symbolic objects are not thread-safe. GMA
        itself only calls CasADi after ``prepare`` has returned (a thread that needs the NLPs waits for it)."""
        self._nlps.get()

    def model_optimum(self) -> np.ndarray:
        """``y(u)`` at the model optimum inside the setpoint box (no modifiers, no trust region)."""
        return self._model.optimum()

    def realize(self, c) -> ModelRealization:
        """The model's best realization of ``c`` (n_c,) and its gradients with respect to ``c``."""
        return self._model.realize(c)

    def linearize(self, c) -> ModelRealization:
        """The model point and gradients the modifiers at ``c`` (n_c,) are computed from
        (:attr:`ModelSettings.point <kite_rto.gma.ModelSettings.point>`)."""
        return self._model.linearize(c, self._prev_mod)

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
        """The next experiment to run; the same request until it is submitted (a new iteration is planned as soon
        as one completes, so there always is one)."""
        todo = self.pending_requests()
        return todo[0] if todo else None

    def submit(self, result: ExperimentResult) -> IterationRecord | None:
        """Record a finished experiment; returns the :class:`IterationRecord` if it completed the iteration.

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
        return None if self.pending_requests() else self._complete()

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

    # ------------------------------------------------------------------ planning and resuming
    def _points(self, exclude_iteration: int | None = None) -> list[PlantPoint]:
        """The finished experiments as plant points, in order."""
        return [_plant_point(q, r) for q, r in self.history.experiments if q.iteration != exclude_iteration]

    def _plan(self) -> None:
        """Plan the experiments of iteration ``k``: the nominal point, then the strategy's perturbations."""
        self.history.pending = self._requests(self._c, f"k{self._k}")

    def _watcher(self) -> Mechanism | None:
        """The mechanism that has the open iteration fly its nominal point alone (None: the iteration learns)."""
        return next((m for m in self.mechanisms if m.perturb() is False), None)

    def _requests(self, c: np.ndarray, tag: str) -> list[ExperimentRequest]:
        """The requests of the open iteration at operating point ``c`` (nominal first), ids ``<tag>-<j>-...``."""
        pr, k = self.problem, self._k
        pert = [] if self._watcher() is not None else self.gradient.plan(c, pr.c_lb, pr.c_ub,
                                                                          self._points(exclude_iteration=k))
        plan = [(c.copy(), "nominal")] + [(np.asarray(x, float), "perturbation") for x in pert]
        effort = self.settings.effort_at(k)
        return [ExperimentRequest(f"{tag}-{j}-{purpose}", x, purpose, k, effort) for j, (x, purpose) in enumerate(plan)]

    def _resume(self) -> None:
        h, n_c, n_g = self.history, self.problem.n_c, self.problem.n_g
        for m in self.mechanisms:
            m.resume(h)
        if h.iterations:
            last = h.iterations[-1]
            self._k, self._c = last.k + 1, last.c_next.copy()
            solved = [r for r in h.iterations if r.modified_status != _NOT_SOLVED and np.all(np.isfinite(r.u_star))]
            ref = solved[-1] if solved else None
            self._prev_mod = (Modifiers(ref.c_k.copy(), ref.eps.copy(), ref.lam.copy(), ref.mu.copy(),
                                        ref.backoff.copy())
                              if ref is not None else Modifiers.zero(h.c0, n_g, self._backoff))
        else:
            self._k, self._c = 0, np.asarray(h.c0, float).copy()
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

    # ------------------------------------------------------------------ one iteration
    def _call(self, hook: str, it: Iteration, *args) -> None:
        for m in self.mechanisms:
            getattr(m, hook)(it, *args)

    def _relative_radius(self) -> np.ndarray:
        """The trust region's half-widths, box widths (``inf`` without one)."""
        radii = [r for m in self.mechanisms if (r := m.trust_radius()) is not None]
        return np.min(radii, axis=0) if radii else np.full(self.problem.n_c, np.inf)

    def _shrink(self, where=True) -> None:
        for m in self.mechanisms:
            m.shrink(where)

    def _complete(self) -> IterationRecord:
        """Close iteration ``k``: gradients, modifiers, the modified problem, the filtered step, the record."""
        t0 = time.perf_counter()
        pr, k, c_k = self.problem, self._k, self._c.copy()
        results = {q.request_id: (q, r) for q, r in self.history.experiments if q.iteration == k}
        ordered = [results[q.request_id] for q in self.history.pending]
        points = [_plant_point(q, r) for q, r in ordered]
        watcher = self._watcher()
        if watcher is not None and len(points) == 1:
            return self._watched(watcher, k, c_k, points[0], ordered, t0)
        self.prepare()          # before any CasADi call here: a worker thread may still be building the NLPs
        model = self.linearize(c_k)
        it = Iteration(k, c_k, points[0], points[1:], self._points(exclude_iteration=k), model, pr,
                       self._since_watch(), self.gradient, lambda c: self._model.values(c, model.u),
                       nominal_id=ordered[0][0].request_id)
        it.estimate = self.gradient.estimate(c_k, it.nominal, it.new, it.past, model)
        self._call("estimate", it)
        it.notes = [it.estimate.notes] if it.estimate.notes else []
        est = it.estimate
        it.modifiers = Modifiers(c_k, it.nominal.constraints - model.g, est.cost - model.grad_phi,
                                 est.constraints - model.jac_g, self._backoff.copy())
        it.modifier_std = np.zeros(pr.n_c) if est.cost_std is None else np.asarray(est.cost_std, float)
        self._call("modify", it)
        it.radius = self._relative_radius() * self._width
        it.decision, it.solution = self._propose(it)
        radius_used = self._relative_radius().copy()
        self._call("revise", it, self._shrink)
        if it.target is not None:        # a mechanism rejected c_k: go back, trust the model less
            it.step, c_next, it.decision, detail = it.target - c_k, it.target, Decision.UNDONE, ""
        else:
            c_next, detail = self._step(it)
        self._call("adapt", it)
        rec = IterationRecord(
            k=k, c_k=c_k, cost=it.nominal.cost, constraints=it.nominal.constraints, grad_cost=est.cost,
            jac_constraints=est.constraints.reshape(pr.n_g, pr.n_c), gradient_quality=est.quality,
            gradient_method=est.method, phi_hat=model.phi, g_hat=model.g, grad_phi_hat=model.grad_phi,
            jac_g_hat=model.jac_g, u_hat=model.u, model_status=model.status, eps=it.modifiers.eps,
            lam=it.modifiers.lam, mu=it.modifiers.mu, backoff=it.modifiers.backoff, u_star=it.solution.u_star,
            modified_cost=it.solution.cost, modified_status=it.solution.status, c_star=it.solution.c_star,
            step=it.step, c_next=c_next, trust_radius=radius_used, trust_radius_next=self._relative_radius().copy(),
            converged=it.decision is Decision.CONVERGED, decision=it.decision.describe(detail), notes=it.notes,
            solve_time=time.perf_counter() - t0, experiment_ids=[q.request_id for q, _ in ordered],
            grad_cost_std=None if est.cost_std is None else np.asarray(est.cost_std, float).copy())
        self.history.iterations.append(rec)
        self._k, self._c = k + 1, c_next
        self._plan()
        return rec

    def _since_watch(self) -> History:
        """The history the mechanisms see: the run since the last watched iteration (the whole run when none)."""
        recs = self.history.iterations
        last = next((i for i in range(len(recs) - 1, -1, -1) if recs[i].outcome is Decision.WATCHED), None)
        return self.history if last is None else replace(self.history, iterations=recs[last + 1:])

    def _watched(self, watcher: Mechanism, k: int, c_k: np.ndarray, nominal: PlantPoint, ordered,
                 t0: float) -> IterationRecord:
        """Close a watched iteration: ``c_k`` measured alone, tested by ``watcher``, kept; the record repeats the
        last learning iteration's gradients and modifiers. When ``watcher`` finds a change, the mechanisms of
        :class:`GMASettings` are built anew (those passed as ``mechanisms`` keep their state)."""
        last = self.history.iterations[-1]
        why = watcher.watch(nominal)
        notes = [f"change detected, learning again: {why}"] if why else ["settled point watched"]
        if why:                 # another plant: GMA's own mechanisms start afresh (the trust region at its start)
            self.mechanisms = self.settings.build(self.problem) + self._extra
        rec = replace(last, k=k, c_k=c_k, cost=nominal.cost, constraints=nominal.constraints.copy(),
                      step=np.zeros_like(c_k), c_next=c_k.copy(), c_star=c_k.copy(), converged=False,
                      decision=Decision.WATCHED.describe("change detected" if why else ""), notes=notes,
                      trust_radius=self._relative_radius().copy(), trust_radius_next=self._relative_radius().copy(),
                      solve_time=time.perf_counter() - t0, experiment_ids=[q.request_id for q, _ in ordered])
        self.history.iterations.append(rec)
        self._k, self._c = k + 1, c_k.copy()
        self._plan()
        return rec

    def _propose(self, it: Iteration) -> tuple[Decision, Solution]:
        """Solve the modified problem at ``c_k`` inside the trust region, or say why GMA holds. A failed solve
        shrinks the trust region; a solved one becomes the next consistent model point."""
        pr, mods, c_k = self.problem, it.modifiers, it.c_k
        hold = Solution(np.full(pr.n_u, np.nan), c_k.copy(), np.nan, _NOT_SOLVED)
        if not it.model.success:
            it.notes.append(f"realization status {it.model.status}")
            return Decision.HOLD_NO_REALIZATION, hold
        if not (np.all(np.isfinite(mods.lam)) and np.all(np.isfinite(mods.mu)) and it.estimate.quality > 0):
            return Decision.HOLD_BAD_GRADIENT, hold

        def solve(radius):
            return self.modified_nlp.solve(mods, radius=radius, x0=it.model.u)
        it.result = solve(it.radius)
        self._call("solve", it, solve)
        res = it.result
        if not res.success:
            self._shrink()
            return Decision.HOLD_SOLVE_FAILED, replace(hold, cost=res.f, status=res.status)
        self.modified_nlp.last = res            # the next warm start: the solution GMA goes on from
        self._prev_mod = replace(mods, c=c_k.copy(), eps=mods.eps.copy(), mu=mods.mu.copy(),
                                 backoff=mods.backoff.copy())
        u_star = res.x[: pr.n_u]
        c_star = np.clip(pr.evaluate(u_star)[2], pr.c_lb, pr.c_ub)
        return Decision.STEP, Solution(u_star, c_star, res.f, res.status)

    def _step(self, it: Iteration) -> tuple[np.ndarray, str]:
        """``(c_next, detail)``: the filtered step towards the solution, clipped to the box and shortened by the
        ``limit`` hooks; the decision becomes ``CONVERGED`` when the unshortened step met ``tol_c``."""
        pr, c_k = self.problem, it.c_k
        it.proposed = it.solution.c_star - c_k
        c_next = np.clip(c_k + self._K * it.proposed, pr.c_lb, pr.c_ub)
        it.step = c_next - c_k
        unscaled = it.step.copy()
        fractions = [f for m in self.mechanisms if (f := m.limit(it)) is not None]
        if fractions:
            it.step = min(fractions) * it.step
            c_next = c_k + it.step
        at_bound = np.abs(it.proposed) >= 0.999 * it.radius
        detail = f"trust region active on c{np.flatnonzero(at_bound).tolist()}" \
            if it.decision is Decision.STEP and at_bound.any() else ""
        if it.decision is Decision.STEP and bool(np.all(np.abs(unscaled) <= self.settings.tol_c * self._width)):
            it.decision, detail = Decision.CONVERGED, ""
        return c_next, detail


def _plant_point(request: ExperimentRequest, result: ExperimentResult) -> PlantPoint:
    """A finished experiment as the gradient estimators see it."""
    return PlantPoint(request.c, result.cost, result.constraints, result.cost_std, result.constraints_std)
