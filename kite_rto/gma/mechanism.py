"""The hook protocol between the GMA iteration and its optional mechanisms (:class:`Mechanism`, :class:`Iteration`).

:class:`~kite_rto.gma.GMA` closes an iteration in a fixed order of named points. At each point it calls the same
hook of every active mechanism, in the order of the fields of :class:`~kite_rto.gma.GMASettings`; a hook reads and
may replace parts of the open :class:`Iteration`:

1. ``estimate``: the plant-gradient estimate ``it.estimate`` is in; a hook may correct it (model secant).
2. ``modify``: the modifiers ``it.modifiers`` (plant minus model at ``c_k``) are in; a hook may filter them and
   set ``it.modifier_std``, the standard deviation of the filtered cost modifier (modifier filters).
3. ``trust_radius``: the box ``|y(u) - c_k| <= radius`` the modified problem is solved in (trust region).
4. ``solve``: the modified problem is solved; a hook may solve it again with other radii and replace
   ``it.solution`` (bound hold).
5. ``revise``: before the step, a hook may reject the iteration's point and set ``it.target`` (undo).
6. ``limit``: the filtered step ``it.step`` towards the solution; a hook returns the fraction of it to take
   (safe step); the smallest fraction is taken.
7. ``adapt``: after the decision (``it.decision``, ``it.step``); a hook learns from it (trust region).

Between iterations, ``perturb()`` decides whether the next iteration learns (nominal point and perturbations) or
flies its nominal point alone, which ``watch(nominal)`` then tests (:class:`~kite_rto.gma.Settle`); a watched
iteration calls none of the hooks above, and the iterations before the last watch are not in ``it.history`` (a
change ended it: what was learned before describes another plant).

``shrink(where)`` is the one event between mechanisms: the plant disagreed with the model in the setpoints
``where`` (a failed solve, an undone step); the trust region narrows there. ``resume(history)`` restores a
mechanism's state from stored records, so a resumed run decides as the uninterrupted one.

A mechanism is built from its settings object (``settings.build(problem)``); its state lives in the mechanism and
in the :class:`~kite_rto.gma.IterationRecord` s it can be restored from.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .gradients import GradientEstimate, GradientEstimator, PlantPoint
from .modifiers import Decision, ModelRealization, Modifiers
from .problem import ModelProblem
from .records import History

__all__ = ["Mechanism", "Iteration", "Solution"]


@dataclass
class Solution:
    """The modified problem's outcome: the model input ``u_star`` (n_u,), ``c_star = y(u_star)`` clipped to the box
    (n_c,), the modified cost and the solver status (NaN and ``"not solved"`` when GMA held without solving)."""

    u_star: np.ndarray
    c_star: np.ndarray
    cost: float
    status: str


@dataclass
class Iteration:
    """What is known about the open iteration ``k``: the hooks' shared workspace (see the module docstring).

    Attributes:
        k: the iteration index.
        c_k: the operating point (n_c,), setpoint units.
        nominal: the plant measured at ``c_k``.
        new: this iteration's perturbation results, in planned order.
        past: the finished experiments of earlier iterations, in order.
        model: the model's linearization at ``c_k``.
        problem: the model problem (box, sizes).
        history: the run so far (earlier records and experiments); read only.
        estimator: the plant-gradient estimator.
        model_values: ``c -> (phi_hat, g_hat)``, the model's best realization of ``c`` (NaN where it fails).
        nominal_id: the request id of the nominal experiment.
        estimate: the plant-gradient estimate (after ``estimate``).
        modifiers: the modifiers at ``c_k`` (after ``modify``).
        modifier_std: standard deviation of the (filtered) cost modifier per setpoint (n_c,), cost units per
            setpoint unit; the estimate's own ``cost_std`` (zeros without one) unless a filter sets it.
        radius: the trust region's half-widths (n_c,), setpoint units (``inf`` without a trust region).
        result: the modified problem's solver result (:class:`~kite_rto.gma._nlp.NLPResult`) during ``solve``.
        decision: what GMA decided (:class:`~kite_rto.gma.Decision`), from ``solve`` on.
        solution: the modified problem's :class:`Solution` (after ``solve``).
        target: the next operating point a ``revise`` hook chose instead of the step (``None``: the step).
        step: the filtered step from ``c_k`` (n_c,), setpoint units (after ``limit``).
        proposed: the unfiltered step to the solution, ``c_star - c_k`` (n_c,).
        notes: free text recorded with the iteration.
    """

    k: int
    c_k: np.ndarray
    nominal: PlantPoint
    new: list
    past: list
    model: ModelRealization
    problem: ModelProblem
    history: History
    estimator: GradientEstimator
    model_values: Callable[[np.ndarray], tuple]
    nominal_id: str = ""
    estimate: GradientEstimate | None = None
    modifiers: Modifiers | None = None
    modifier_std: np.ndarray | None = None
    radius: np.ndarray | None = None
    result: object | None = None
    decision: Decision | None = None
    solution: Solution | None = None
    target: np.ndarray | None = None
    step: np.ndarray | None = None
    proposed: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def width(self) -> np.ndarray:
        """The setpoint box's width (n_c,), setpoint units."""
        return self.problem.c_width

    def nominal_result(self, record):
        """The stored :class:`~kite_rto.gma.ExperimentResult` of ``record``'s nominal experiment (``None`` if
        absent)."""
        if not record.experiment_ids:
            return None
        want = record.experiment_ids[0]
        return next((r for q, r in self.history.experiments if q.request_id == want), None)


class Mechanism:
    """Base of GMA's mechanisms: every hook does nothing (see the module docstring for when each is called)."""

    def resume(self, history: History) -> None:
        """Restore the state an uninterrupted run would have after ``history``'s records."""

    def estimate(self, it: Iteration) -> None:
        """Correct ``it.estimate``."""

    def modify(self, it: Iteration) -> None:
        """Filter ``it.modifiers`` (and set ``it.modifier_std``)."""

    def trust_radius(self) -> np.ndarray | None:
        """Half-widths (n_c,) of the box the modified problem is solved in, box widths; ``None``: no limit."""
        return None

    def solve(self, it: Iteration, solve: Callable[[np.ndarray], object]) -> None:
        """Revise ``it.solution``; ``solve(radius)`` solves the modified problem with other half-widths."""

    def revise(self, it: Iteration, shrink: Callable) -> None:
        """Set ``it.target`` to reject the step (``shrink(where)``: tell the trust region)."""

    def limit(self, it: Iteration) -> float | None:
        """The fraction in [0, 1] of ``it.step`` to take (``None``: no opinion)."""
        return None

    def adapt(self, it: Iteration) -> None:
        """Learn from the iteration's step."""

    def shrink(self, where) -> None:
        """The plant disagreed with the model in the setpoints ``where`` (a bool or a mask (n_c,))."""

    def perturb(self) -> bool | None:
        """False: the next iteration flies its nominal point alone and is watched (:meth:`watch`) instead of
        learning; ``None``: no opinion."""
        return None

    def watch(self, nominal: PlantPoint) -> str:
        """A watched iteration's nominal measurement; returns ``""`` to keep watching, else why learning starts
        again. Called only on a mechanism whose :meth:`perturb` said False."""
        return ""
