"""Settings of the GMA iteration: filter, trust region, convexification, back-off, solver options.

Distances in setpoint space (trust radius, step bound, convergence tolerance, model finite-difference step)
are **relative to the width of the setpoint box** ``c_ub - c_lb`` of the :class:`~kite_rto.gma.ModelProblem`,
so that one set of defaults works for setpoints of any unit. Per-setpoint values may be given as sequences of
length ``n_c``; their length is checked when a :class:`~kite_rto.gma.GMA` is built.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Sequence

import numpy as np

__all__ = ["GMASettings", "per_setpoint"]

Scalar = float | Sequence[float]


def _check(name: str, value, low=None, high=None, *, low_open=False, high_open=False, inf_ok=False):
    """Raise ``ValueError`` naming field, value and range unless every entry of ``value`` is in range."""
    entries = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
    lo = "(" if low_open else "["
    hi = ")" if high_open else "]"
    expected = f"{lo}{'-inf' if low is None else low}, {'inf' if high is None else high}{hi}"
    for v in entries:
        bad = math.isnan(v) or (math.isinf(v) and not inf_ok)
        if low is not None and (v < low or (low_open and v == low)):
            bad = True
        if high is not None and (v > high or (high_open and v == high)):
            bad = True
        if bad:
            raise ValueError(f"GMASettings.{name}={value!r}: expected every value in {expected}")
    if entries.size == 0:
        raise ValueError(f"GMASettings.{name}={value!r}: expected a number or a non-empty sequence")


def _check_bool(name: str, value) -> None:
    """Raise ``ValueError`` naming the field and value unless ``value`` is True or False."""
    if not isinstance(value, bool):
        raise ValueError(f"GMASettings.{name}={value!r}: expected True or False")


def _check_int(name: str, value, low: int, extra: str = "") -> None:
    """Raise ``ValueError`` naming the field and value unless ``value`` is an integer ``>= low`` (not a bool)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise ValueError(f"GMASettings.{name}={value!r}: expected an integer >= {low}{extra}")


def per_setpoint(name: str, value, n: int) -> np.ndarray:
    """Broadcast a scalar-or-sequence setting to shape ``(n,)``; ``ValueError`` on a length mismatch."""
    arr = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
    if arr.size == 1:
        return np.full(n, float(arr[0]))
    if arr.size != n:
        raise ValueError(f"GMASettings.{name}={value!r}: expected a scalar or {n} values, got {arr.size}")
    return arr.copy()


@dataclass
class GMASettings:
    """Validated settings of :class:`~kite_rto.gma.GMA`. Invalid values raise ``ValueError``.

    Attributes:
        filter_gain: input filter ``K`` in ``c_{k+1} = c_k + K (c*_{k+1} - c_k)``; scalar or one gain per
            setpoint, each in ``(0, 1]``. 1 = no filtering.
        modifier_filter: first-order filter ``b`` on the gradient modifiers,
            ``lambda_k = (1 - b) lambda_{k-1} + b lambda_k^measured`` (and ``mu`` likewise), in ``(0, 1]``;
            1 = no filtering. Averages noisy plant-gradient estimates over iterations (Marchetti et al. 2009);
            ``eps_k`` is never filtered.
        modifier_drift: ``None`` (default): the fixed filter ``modifier_filter``. A number ``q >= 0`` replaces it
            by a filter matched to the gradient noise (:mod:`~kite_rto.gma.noise_filter`): per setpoint, a
            Kalman gain from the estimates' standard deviations (pooled over the iterations) and the filtered
            modifier's variance, which grows by ``(q |step / w|)^2`` per step; ``q`` bounds the plant-model
            curvature mismatch, cost units per squared box width. Needs the estimates' ``cost_std`` (without it
            the fixed filter applies).
        constraint_drift: ``None`` (default): the constraint-gradient modifiers ``mu`` get the cost's gain. A
            number ``q_g >= 0`` (scalar or one per constraint) gives each constraint's ``mu`` a gain of its own
            from the same filter, fed with that constraint's noise (the gradient's standard deviation times the
            constraint's measured standard deviation over the cost's: same experiments, same design) and drift
            bound ``q_g``, constraint units per squared box width. A constraint measured more precisely than the
            cost then follows its measurements, so the modified problem and the safe step predict it alike.
            Needs ``modifier_drift``.
        cost_sigma: ``z >= 0``, a pessimistic modified cost: ``z |sigma * d|`` is added to it, ``d`` the step in
            setpoints and ``sigma`` the standard deviation of the filtered cost-gradient modifier per setpoint
            (``sqrt(P)`` of the noise-matched filter; the estimate's own ``cost_std`` without that filter,
            scaled by ``sqrt(b / (2 - b))`` for a fixed filter ``b``). The step then goes only where the
            modified gradient exceeds ``z`` of its standard deviations, and no further than the model's
            curvature allows against that margin: at a converged point noise no longer moves the iterate,
            and as the filter averages more iterations ``sigma`` falls and a real gradient gets through.
            0 (default) = off; needs the estimates' ``cost_std`` (a component without one gets ``sigma = 0``).
        cost_sigma_after: iterations ``k < cost_sigma_after`` solve without the pessimistic cost (integer
            ``>= 0``; 0 = from the first). 1 keeps the first step, from the model optimum on a single gradient
            estimate, what it is without it, and makes the pessimism apply once the filter has something to average.
        cost_sigma_until: iterations ``k >= cost_sigma_until`` solve without the pessimistic cost again (integer
            ``> cost_sigma_after``); ``None`` (default) = every iteration from ``cost_sigma_after`` on. With
            ``cost_sigma_after = 1`` and ``cost_sigma_until = 2`` only the step from iteration 1 is pessimistic:
            the one that follows a long first step on the first gradient measured at the new point.
        reject_sigma: measured step test (issue #14 item 3, a trust region that adapts to the plant's own
            measurements; ``docs/gma.md``, *Undoing a step*): ``None`` = off (default). A number ``z >= 0``: when the
            nominal cost measured at ``c_k`` exceeds the one measured at ``c_{k-1}`` by more than ``z`` standard
            errors of their difference (from the experiments' ``cost_std``, pooled over the run and scaled by each
            request's ``averaging``; without them nothing is undone), ``c_{k-1}``'s measured constraints held
            (``g <= 0``) and GMA's own step led from ``c_{k-1}`` to ``c_k``, the step is undone: the next operating
            point is ``c_{k-1}`` and the trust radius shrinks by ``trust_shrink`` in the setpoints that moved. The
            gradient measured at ``c_k`` still enters the modifiers. A step back is not tested in turn.
        trust_radius: initial trust-region half-width of the box ``|y(u) - c_k| <= Delta`` imposed in the
            modified problem, relative to the setpoint box width; ``> 0``, ``inf`` disables the trust region.
        trust_adapt: adapt the trust radius per setpoint: shrink it by ``trust_shrink`` when the step in that
            setpoint changes sign (oscillation), grow it by ``trust_grow`` (up to ``trust_radius``) when the
            step keeps its sign and reached the bound.
        trust_shrink: shrink factor, in ``(0, 1)``.
        trust_grow: growth factor, ``>= 1``.
        trust_radius_min: lower limit of the adapted radius (relative), ``> 0``.
        max_step: bound on the filtered step ``|c_{k+1} - c_k|`` per setpoint (relative), ``> 0``; ``inf`` = none.
        convexification: diagonal of ``Q`` in the added cost ``0.5 (y(u) - c_k)^T Q (y(u) - c_k)``, in cost
            units per setpoint unit squared, ``>= 0``. Vanishes at a fixed point, so it does not move the
            converged point; it makes the modified problem more convex and the steps shorter.
        backoff: constant tightening ``b`` of the modified constraints, ``g + eps + mu (y - c_k) + b <= 0``, in
            constraint units, ``>= 0``; scalar or one per constraint.
        backoff_std_factor: adds this many measured standard deviations (``ExperimentResult.constraints_std``)
            to the back-off, ``>= 0``.
        constraint_penalty: ``None`` = hard modified constraints. A number ``rho > 0`` makes them soft with an
            exact L1 penalty ``rho * sum(s)``, so that the modified problem stays feasible inside a small
            trust region; ``rho`` must exceed the constraint multipliers.
        tol_c: convergence tolerance on ``|c_{k+1} - c_k|`` (relative), ``> 0``.
        model_fd_step: step of the central differences of re-solves giving ``grad_c g_hat`` (relative),
            in ``(0, 0.1]``.
        model_point: where the model is linearized at ``c_k``. ``"consistent"`` (default): the model's best
            realization of ``c_k`` under the previous iteration's modified constraints, gradients
            ``grad_u(.) R`` with ``R`` a right inverse of ``dy/du`` in the tangent space of the active internal
            constraints; at a fixed point this is the modified problem's own solution, so converged points
            are plant KKT points even when ``g`` depends on model inputs that ``y`` does not fix.
            ``"realization"``: SPEC §5 literally, ``u_hat = argmin phi s.t. y(u) = c_k``, ``grad_c phi_hat``
            from the multipliers of ``y(u) = c_k`` and ``grad_c g_hat`` from central differences of re-solves;
            exact when the modified constraints are inactive at the plant optimum or depend on ``u`` only
            through ``y(u)``.
        model_secant: take the gradient modifiers from the model's own difference quotients over the points the
            plant flew (:mod:`~kite_rto.gma.model_secant`): ``lambda = secant_p - secant_hat`` instead of
            ``secant_p - grad phi_hat``, so that the finite differences' truncation error cancels up to the
            plant-model curvature mismatch; one model solve per point used. Off by default.
        model_secant_constraints: with ``model_secant``, correct the constraints' gradient modifiers too (False:
            the cost's only, the constraints keep ``secant_p - grad g_hat``).
        model_secant_cost: with ``model_secant``, correct the cost gradient (False: only the constraints' Jacobian;
            the cost keeps the plant's quotients, for a model whose cost curves unlike the plant's).
        model_secant_within: with ``model_secant``, correct only in iterations whose operating point the previous
            iteration reached with a step of at most this length (largest entry, relative to the setpoint box
            width; ``> 0``); ``inf`` (default) = every iteration, from ``k = 0``. With a finite value iteration 0,
            with no previous step, is never corrected. The truncation error matters where GMA stops moving,
            within about a perturbation of the point where the plant's *secant* vanishes; further away it is
            small against the gradient, and the correction adds the plant-model curvature mismatch to every step.
        alternate_within: when an estimator alternates the side of its perturbations (``alternate`` of
            :class:`~kite_rto.gma.FiniteDifferenceGradient` and :class:`~kite_rto.gma.DirectionalGradient`), count
            its iterations from the last step longer than this (largest entry, relative to the setpoint box width;
            ``> 0``): the first iteration after a long step perturbs forward, the next one backward, and so on,
            so that sides alternate only where the iterate stays and the perturbations of the first, long steps
            are all forward. ``inf`` (default) = GMA's iteration index (every odd iteration backward). Read from
            the stored records, so a resumed run plans alike.
        settle_time: hint copied into every :class:`ExperimentRequest` (generic units, e.g. s or laps), ``>= 0``.
        averaging: averaging-length hint copied into every request (generic units), ``> 0``.
        averaging_schedule: effort matched to the iteration (issue #14 item 4): multipliers of ``averaging`` by
            iteration, the last one holding for every later iteration; each ``> 0``. Empty (default) = every
            request gets ``averaging``. At the model optimum the plant gradient is large against its noise; near
            the plant optimum it shrinks to the noise, so later iterations need longer averaging: ``(1, 2)``
            averages twice as long from iteration 1 on. The plant side decides what the hint means (the kite
            flies ``n_laps * request.averaging / averaging`` laps).
        structure_check_every: measured structure check (issue #14 item 2, ``docs/gma.md``): every this many
            iterations (at ``k = 0, N, 2N, ...``) one extra experiment along each direction the gradient
            estimator leaves to the model (for a :class:`~kite_rto.gma.DirectionalGradient`: the complement of
            its directions, including setpoints held at a robustly active bound); a significant mismatch adds
            the direction to the estimator. Integer ``>= 0``; 0 = off (default, off until the scenario campaign
            of #14 decides).
        structure_stall: also check in the iteration after a step whose every component was at most this
            fraction of the box width (a stalled or converged iterate), ``>= 0``; 0 = off.
        structure_step: length of a structure experiment, relative to the box width, in ``(0, 1]``.
        structure_sigma: significance: a residual counts when it exceeds this many of its standard deviations
            (from ``cost_std``/``constraints_std`` of the measurements and the estimate's ``cost_std``) plus
            ``structure_rel_tol`` times the predicted change, ``>= 0``.
        structure_rel_tol: relative part of the threshold (covers the curvature over the step), ``>= 0``.
        structure_kkt: measured-KKT test at held bounds (issue #14 item 2, ``docs/gma.md``): in an iteration the
            stall trigger (``structure_stall``, required ``> 0``) checks, a structure experiment that moves a
            setpoint off the bound it sits at measures the change of the plant's Lagrangian
            ``phi_p + nu^T g_p`` (``nu``: the modified problem's multipliers); a decrease of more than
            ``structure_sigma`` standard errors means the bound's multiplier has the wrong sign (the plant wants
            to leave the bound): the direction is restored from the next iteration on. Off by default.
        safe_curvature: safe steps (issue #14 item 3, :mod:`~kite_rto.gma.safety`): ``None`` = off (default, off
            until the scenario campaign of #14 decides). Otherwise a prior bound ``M`` on the plant constraints'
            curvature, constraint units per squared box width, ``>= 0``, scalar or one per constraint: the
            filtered step is shortened so that every constraint, predicted from its measured value and gradient
            with ``safe_sigma`` standard deviations and ``0.5 M |d/w|^2``, stays within ``safe_tolerance``.
            ``M`` grows to the largest curvature the measured steps show.
        safe_sigma: standard deviations of the measured constraint and of the predicted change, ``>= 0``.
        safe_tolerance: how far the plant's constraints may be exceeded, constraint units, ``>= 0``; scalar or
            one per constraint.
        safe_filtered: predict the constraints' change over the step with the modified problem's Jacobian
            (model plus the filtered ``mu``, the one the step was chosen with) instead of this iteration's raw
            estimate; with a modifier filter the two differ, and the raw one can veto every step the filtered one
            proposes. Off by default.
        safe_truncation: add the gradient estimate's own truncation error to the predicted change: the
            differences over the points ``p_i`` (box widths) the estimate fits carry second-order errors up to
            ``0.5 M |p_i|^2`` each, which move the predicted change over the step ``d = sum a_i p_i`` by up to
            ``0.5 M sum |a_i| |p_i|^2`` (``docs/gma.md``, *Safe steps*). Matters where a perturbation was taken
            on the other side of ``c_k`` than the step (at a bound) or is longer than it. Off by default.
        safe_both_ends: the curvature bound ``M`` also learns from each past step's end: the gradient estimated at
            ``c_{k+1}`` predicting the constraints at ``c_k`` (the bound holds from either end;
            :func:`~kite_rto.gma.safety.observed_curvature`). A gradient whose secants over its perturbations
            disagree with the last step's measured change then shortens its own step. Off by default.
        safe_model_slope: predict each constraint's change over the step with the worse (larger) of the
            estimated plant slope and the model's own ``jac_g @ step`` at ``c_k``: a measured secant taken on the
            other side of ``c_k`` than the step, through a curved region, can flip the sign the model has right,
            and the step then runs into the constraint it was predicted to leave. ``"extrapolated"``: only when
            the estimate extrapolates, i.e. some fitted point's weight in the step is negative
            (:func:`~kite_rto.gma.safety.step_weights`: a difference taken on the other side of ``c_k``).
            ``"terms"``: only for the part of the step that extrapolates: the step is split into the fitted
            points' terms ``a_i p_i``, and only a term with ``a_i < 0`` takes the worse of the two slopes; the
            other terms keep the estimate, where a measured difference is better evidence than the model. Off
            (False) by default.
        safe_shrink: shrink the trust radius (by ``trust_shrink``) whenever a safe step shortens the filtered
            step (True, default); False leaves the radius to ``trust_adapt``: the safe step already limits that
            step, and shrinking as well compounds, over iterations, to the smallest radius.
        safe_adapt_min_step: steps shorter than this (largest component, box widths) do not update ``M``
            (their gradient error over the step would look like curvature), ``>= 0``.
        noise_ratio: effort matched to noise (issue #14 item 4, :mod:`~kite_rto.gma.effort`): the nominal and
            perturbation experiments of an iteration are flown again while the standard error of some
            perturbation's measured cost change exceeds this fraction of the change's size, ``> 0``.
        max_repeats_noise: how many times at most each of them is flown again (their results are averaged,
            the standard errors shrink as ``1 / sqrt(n)``); integer ``>= 0``, 0 = off (default). Needs the
            results' ``cost_std``.
        bound_sigma: leave a bound of the box only on measured evidence: ``None`` = off (default). A number
            ``z >= 0``: from iteration ``bound_sigma_after`` on, the setpoints at a bound of the box are held there
            (zero trust radius in them) when the held modified problem's multiplier of each (the modified
            Lagrangian's descent into the box, constraints included) is below ``z`` standard deviations of the
            filtered cost modifier; a setpoint above it is released and the rest solved again, once. Near an
            optimum on or close to a bound the measured slope there is mostly noise, and a model without
            curvature in that setpoint turns it into a step to the trust region's edge. Needs the estimates'
            ``cost_std`` (without it nothing is held).
        bound_sigma_after: the first iteration of ``bound_sigma`` (integer ``>= 0``): at the model optimum the
            plant gradient is significant only with the model's help.
        bound_sigma_start: ``bound_sigma`` also holds a setpoint at the bound the run started on (``c0``, the
            model optimum by default): True (default). False holds only the bounds the iterates have reached by a
            step; a bound the start sits on is the model's claim, which the unheld modified problem then tests at
            every iteration (issue #14 item 2), at the price of steps into the box on noise where the claim is right.
        max_ipopt_iter: IPOPT iteration limit per solve, ``>= 1``.
        ipopt_options: extra IPOPT options (without the ``ipopt.`` prefix), e.g. ``{"tol": 1e-9}``.
    """

    filter_gain: Scalar = 0.5
    modifier_filter: float = 1.0
    modifier_drift: float | None = None
    constraint_drift: Scalar | None = None
    cost_sigma: float = 0.0
    cost_sigma_after: int = 0
    cost_sigma_until: int | None = None
    reject_sigma: float | None = None
    trust_radius: Scalar = 0.25
    trust_adapt: bool = True
    trust_shrink: float = 0.5
    trust_grow: float = 2.0
    trust_radius_min: float = 0.01
    max_step: Scalar = math.inf
    convexification: Scalar = 0.0
    backoff: Scalar = 0.0
    backoff_std_factor: float = 0.0
    constraint_penalty: float | None = None
    tol_c: float = 1e-4
    model_fd_step: float = 1e-4
    model_point: str = "consistent"
    model_secant: bool = False
    model_secant_constraints: bool = True
    model_secant_cost: bool = True
    model_secant_within: float = math.inf
    alternate_within: float = math.inf
    settle_time: float = 0.0
    averaging: float = 1.0
    averaging_schedule: tuple = ()
    structure_check_every: int = 0
    structure_stall: float = 0.0
    structure_step: float = 0.1
    structure_sigma: float = 3.0
    structure_rel_tol: float = 0.2
    structure_kkt: bool = False
    safe_curvature: Scalar | None = None
    safe_sigma: float = 2.0
    safe_tolerance: Scalar = 0.0
    safe_adapt_min_step: float = 0.01
    safe_shrink: bool = True
    safe_filtered: bool = False
    safe_truncation: bool = False
    safe_both_ends: bool = False
    safe_model_slope: bool | str = False
    noise_ratio: float = 0.5
    max_repeats_noise: int = 0
    bound_sigma: float | None = None
    bound_sigma_after: int = 2
    bound_sigma_start: bool = True
    max_ipopt_iter: int = 1000
    ipopt_options: dict = field(default_factory=dict)

    def __post_init__(self):
        _check("filter_gain", self.filter_gain, 0.0, 1.0, low_open=True)
        _check("modifier_filter", self.modifier_filter, 0.0, 1.0, low_open=True)
        if self.modifier_drift is not None:
            _check("modifier_drift", self.modifier_drift, 0.0, None)
        if self.constraint_drift is not None:
            _check("constraint_drift", self.constraint_drift, 0.0, None)
            if self.modifier_drift is None:
                raise ValueError(f"GMASettings.constraint_drift={self.constraint_drift!r} needs modifier_drift "
                                 "(the noise-matched filter); modifier_drift is None")
        _check("cost_sigma", self.cost_sigma, 0.0, None)
        if self.reject_sigma is not None:
            _check("reject_sigma", self.reject_sigma, 0.0, None)
        _check("trust_radius", self.trust_radius, 0.0, None, low_open=True, inf_ok=True)
        _check_bool("trust_adapt", self.trust_adapt)
        _check("trust_shrink", self.trust_shrink, 0.0, 1.0, low_open=True, high_open=True)
        _check("trust_grow", self.trust_grow, 1.0, None)
        _check("trust_radius_min", self.trust_radius_min, 0.0, None, low_open=True)
        _check("max_step", self.max_step, 0.0, None, low_open=True, inf_ok=True)
        _check("convexification", self.convexification, 0.0, None)
        _check("backoff", self.backoff, 0.0, None)
        _check("backoff_std_factor", self.backoff_std_factor, 0.0, None)
        if self.constraint_penalty is not None:
            _check("constraint_penalty", self.constraint_penalty, 0.0, None, low_open=True)
        _check("tol_c", self.tol_c, 0.0, None, low_open=True)
        _check("model_fd_step", self.model_fd_step, 0.0, 0.1, low_open=True)
        if self.model_point not in ("consistent", "realization"):
            raise ValueError(f"GMASettings.model_point={self.model_point!r}: expected 'consistent' or "
                             f"'realization'")
        _check_bool("model_secant", self.model_secant)
        _check_bool("model_secant_constraints", self.model_secant_constraints)
        _check_bool("model_secant_cost", self.model_secant_cost)
        if self.model_secant and not (self.model_secant_cost or self.model_secant_constraints):
            raise ValueError("GMASettings.model_secant=True with model_secant_cost=False and "
                             "model_secant_constraints=False: expected at least one of them True")
        _check("model_secant_within", self.model_secant_within, 0.0, None, low_open=True, inf_ok=True)
        _check("alternate_within", self.alternate_within, 0.0, None, low_open=True, inf_ok=True)
        _check("settle_time", self.settle_time, 0.0, None)
        _check("averaging", self.averaging, 0.0, None, low_open=True)
        try:
            sched = np.asarray(self.averaging_schedule, dtype=float)
        except (TypeError, ValueError):
            sched = None
        if sched is None or sched.ndim != 1 or not np.all(np.isfinite(sched)) or np.any(sched <= 0):
            raise ValueError(f"GMASettings.averaging_schedule={self.averaging_schedule!r}: expected a sequence of "
                             f"finite multipliers > 0 (empty = constant averaging)")
        self.averaging_schedule = tuple(float(x) for x in sched)
        _check_int("structure_check_every", self.structure_check_every, 0, " (0 = off)")
        _check("structure_stall", self.structure_stall, 0.0, None)
        _check("structure_step", self.structure_step, 0.0, 1.0, low_open=True)
        _check("structure_sigma", self.structure_sigma, 0.0, None)
        _check("structure_rel_tol", self.structure_rel_tol, 0.0, None)
        _check_bool("structure_kkt", self.structure_kkt)
        if self.structure_kkt and not self.structure_stall > 0:
            raise ValueError(f"GMASettings.structure_kkt=True with structure_stall={self.structure_stall!r}: "
                             f"expected structure_stall > 0 (the test runs at a stalled iterate)")
        if self.safe_curvature is not None:
            _check("safe_curvature", self.safe_curvature, 0.0, None)
        _check("safe_sigma", self.safe_sigma, 0.0, None)
        _check("safe_tolerance", self.safe_tolerance, 0.0, None)
        _check("safe_adapt_min_step", self.safe_adapt_min_step, 0.0, None)
        _check_bool("safe_filtered", self.safe_filtered)
        _check_bool("safe_truncation", self.safe_truncation)
        _check_bool("safe_both_ends", self.safe_both_ends)
        if not (isinstance(self.safe_model_slope, bool) or self.safe_model_slope in ("extrapolated", "terms")):
            raise ValueError(f"GMASettings.safe_model_slope={self.safe_model_slope!r}: expected True, False, "
                             "'extrapolated' or 'terms'")
        _check_bool("safe_shrink", self.safe_shrink)
        _check("noise_ratio", self.noise_ratio, 0.0, None, low_open=True)
        _check_int("max_repeats_noise", self.max_repeats_noise, 0, " (0 = off)")
        if self.bound_sigma is not None:
            _check("bound_sigma", self.bound_sigma, 0.0, None)
        _check_int("bound_sigma_after", self.bound_sigma_after, 0)
        _check_bool("bound_sigma_start", self.bound_sigma_start)
        _check_int("max_ipopt_iter", self.max_ipopt_iter, 1)
        _check_int("cost_sigma_after", self.cost_sigma_after, 0)
        if self.cost_sigma_until is not None:
            _check_int("cost_sigma_until", self.cost_sigma_until, self.cost_sigma_after + 1)
        if not isinstance(self.ipopt_options, dict):
            raise ValueError(f"GMASettings.ipopt_options={self.ipopt_options!r}: expected a dict")
        if np.any(np.asarray(self.trust_radius, dtype=float) < self.trust_radius_min):
            raise ValueError(f"GMASettings.trust_radius_min={self.trust_radius_min!r}: expected "
                             f"<= trust_radius={self.trust_radius!r}")

    def averaging_at(self, k: int) -> float:
        """The averaging hint of iteration ``k``'s requests: ``averaging`` times the schedule's multiplier."""
        sched = self.averaging_schedule
        return self.averaging * (sched[min(k, len(sched) - 1)] if sched else 1.0)

    @property
    def structure_check(self) -> bool:
        """True when the measured structure check is on (``structure_check_every`` or ``structure_stall``)."""
        return self.structure_check_every > 0 or self.structure_stall > 0

    def to_dict(self) -> dict:
        """Plain-JSON form (sequences as lists, ``inf`` as the string ``"inf"``)."""
        def plain(v):
            if isinstance(v, (list, tuple, np.ndarray)):
                return [plain(x) for x in np.asarray(v, dtype=float).ravel()]
            if isinstance(v, float) and math.isinf(v):
                return "inf" if v > 0 else "-inf"
            return v
        return {k: plain(v) if k != "ipopt_options" else dict(v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: dict) -> "GMASettings":
        """Inverse of :meth:`to_dict`; unknown keys raise ``TypeError``."""
        def back(v):
            if isinstance(v, list):
                return [back(x) for x in v]
            if v in ("inf", "-inf"):
                return float(v)
            return v
        return cls(**{k: back(v) if k != "ipopt_options" else v for k, v in data.items()})
