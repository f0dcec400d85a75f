"""Settings of the GMA iteration: a few top-level values and one typed sub-object per mechanism.

A mechanism is on when its sub-object is given and off when it is ``None``, the only spelling of "off". Distances
in setpoint space (trust radius, convergence tolerance, the model's finite-difference step) are **relative to the
width of the setpoint box** ``c_ub - c_lb`` of the :class:`~kite_rto.gma.ModelProblem`, so that one set of defaults
works for setpoints of any unit. Per-setpoint (or per-constraint) values may be given as sequences; their length is
checked when a :class:`~kite_rto.gma.GMA` is built.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np

from ._checks import Scalar, check_choice, check_int, check_range
from .bound_hold import BoundHold
from .model_secant import ModelSecant
from .modifier_filter import ModifierFilter, NoiseFilter, build_filters
from .plain import from_plain, to_plain
from .safe_step import SafeStep
from .settle import Settle
from .trust_region import TrustRegion
from .undo import Undo

__all__ = ["GMASettings", "ModelSettings", "MECHANISMS", "ModelPoint"]

ModelPoint = Literal["consistent", "realization"]


@dataclass(frozen=True)
class ModelSettings:
    """How the model side is solved.

    Attributes:
        point: where the model is linearized at ``c_k``. ``"consistent"``: the model's best realization of ``c_k``
            under the previous iteration's modified constraints, gradients ``grad_u(.) R`` with ``R`` a right
            inverse of ``dy/du`` in the tangent space of the active internal constraints; at a fixed point this is
            the modified problem's own solution, so converged points are plant KKT points even when ``g`` depends
            on model inputs that ``y`` does not fix. ``"realization"``: the textbook GMA point,
            ``u_hat = argmin phi s.t. y(u) = c_k``, ``grad_c phi_hat`` from the multipliers of ``y(u) = c_k`` and
            ``grad_c g_hat`` from central differences of re-solves.
        fd_step: step of those central differences, box widths, in ``(0, 0.1]``.
        max_iter: IPOPT iteration limit per solve, ``>= 1``.
        ipopt_options: extra IPOPT options (without the ``ipopt.`` prefix), e.g. ``{"tol": 1e-9}``.
    """

    point: ModelPoint = "consistent"
    fd_step: float = 1e-4
    max_iter: int = 1000
    ipopt_options: dict = field(default_factory=dict)

    def __post_init__(self):
        n = type(self).__name__
        check_choice(n, "point", self.point, get_args(ModelPoint))
        check_range(n, "fd_step", self.fd_step, 0.0, 0.1, low_open=True)
        check_int(n, "max_iter", self.max_iter, 1)
        if not isinstance(self.ipopt_options, dict):
            raise ValueError(f"{n}.ipopt_options={self.ipopt_options!r}: expected a dict")

    def __hash__(self):
        return hash((self.point, self.fd_step, self.max_iter, tuple(sorted(self.ipopt_options.items()))))


MECHANISMS = {"modifier_filter": ModifierFilter, "noise_filter": NoiseFilter, "trust_region": TrustRegion,
              "safe_step": SafeStep, "undo": Undo, "bound_hold": BoundHold, "model_secant": ModelSecant,
              "settle": Settle}
"""The mechanisms' field names in :class:`GMASettings` and their settings classes, in the order GMA calls them."""


@dataclass(frozen=True)
class GMASettings:
    """Validated settings of :class:`~kite_rto.gma.GMA`. Invalid values raise ``ValueError`` naming them.

    Attributes:
        filter_gain: input filter ``K`` in ``c_{k+1} = c_k + K (c*_{k+1} - c_k)``; scalar or one gain per setpoint,
            each in ``(0, 1]``. 1 = full steps.
        tol_c: convergence tolerance on ``|c_{k+1} - c_k|``, box widths, ``> 0``.
        backoff: constant tightening ``b`` of the modified constraints, ``g + eps + mu (y - c_k) + b <= 0``,
            constraint units, ``>= 0``; scalar or one per constraint.
        effort_schedule: the experiments' effort by iteration, as multipliers of a unit the plant side defines
            (e.g. cycles averaged), the last one holding for every later iteration; each ``> 0``. Empty = 1 for every
            iteration. Near the plant optimum the gradient shrinks to the noise, so later iterations may need
            longer experiments: ``(1, 2)`` measures twice as long from iteration 1 on.
        model: :class:`ModelSettings` (linearization point, finite-difference step, IPOPT options).
        modifier_filter: :class:`~kite_rto.gma.ModifierFilter`, a fixed filter on the gradient modifiers.
        noise_filter: :class:`~kite_rto.gma.NoiseFilter`, a gain matched to the gradient noise (with
            ``modifier_filter`` as the fallback where an estimate has no standard deviation).
        trust_region: :class:`~kite_rto.gma.TrustRegion` (default one of 0.25 box widths); ``None``: unbounded.
        safe_step: :class:`~kite_rto.gma.SafeStep`, steps that keep the plant's constraints within tolerance.
        undo: :class:`~kite_rto.gma.Undo`, a step the plant measured as a loss is undone.
        bound_hold: :class:`~kite_rto.gma.BoundHold`, a setpoint leaves a bound it reached only on evidence.
        model_secant: :class:`~kite_rto.gma.ModelSecant`, the constraints' gradient modifiers from the model's
            own secants over the flown points.
        settle: :class:`~kite_rto.gma.Settle`, no perturbation at a settled point until a change is detected.
    """

    filter_gain: Scalar = 0.5
    tol_c: float = 1e-4
    backoff: Scalar = 0.0
    effort_schedule: tuple = ()
    model: ModelSettings = field(default_factory=ModelSettings)
    modifier_filter: ModifierFilter | None = None
    noise_filter: NoiseFilter | None = None
    trust_region: TrustRegion | None = field(default_factory=TrustRegion)
    safe_step: SafeStep | None = None
    undo: Undo | None = None
    bound_hold: BoundHold | None = None
    model_secant: ModelSecant | None = None
    settle: Settle | None = None

    def __post_init__(self):
        n = type(self).__name__
        check_range(n, "filter_gain", self.filter_gain, 0.0, 1.0, low_open=True)
        check_range(n, "tol_c", self.tol_c, 0.0, None, low_open=True)
        check_range(n, "backoff", self.backoff, 0.0, None)
        try:
            sched = np.asarray(self.effort_schedule, dtype=float)
        except (TypeError, ValueError):
            sched = None
        if sched is None or sched.ndim != 1 or not np.all(np.isfinite(sched)) or np.any(sched <= 0):
            raise ValueError(f"{n}.effort_schedule={self.effort_schedule!r}: expected a sequence of finite "
                             f"multipliers > 0 (empty = 1 for every iteration)")
        object.__setattr__(self, "effort_schedule", tuple(float(x) for x in sched))
        if not isinstance(self.model, ModelSettings):
            raise ValueError(f"{n}.model={self.model!r}: expected a ModelSettings")
        for name, cls in MECHANISMS.items():
            value = getattr(self, name)
            if value is not None and not isinstance(value, cls):
                raise ValueError(f"{n}.{name}={value!r}: expected {cls.__name__}(...) or None (off)")

    def effort_at(self, k: int) -> float:
        """The effort of iteration ``k``'s experiments (``effort_schedule``'s multiplier; 1 without one)."""
        sched = self.effort_schedule
        return sched[min(k, len(sched) - 1)] if sched else 1.0

    def build(self, problem) -> list:
        """The active mechanisms for ``problem``, in the order of :data:`MECHANISMS` (the two modifier filters are
        one mechanism)."""
        out = [build_filters(self.modifier_filter, self.noise_filter, problem)]
        out += [sub.build(problem) for name in MECHANISMS if name not in ("modifier_filter", "noise_filter")
                if (sub := getattr(self, name)) is not None]
        return [m for m in out if m is not None]

    def to_dict(self) -> dict:
        """Plain-JSON form: sub-objects as dicts (``None`` when off), sequences as lists, ``inf`` as ``"inf"``."""
        return to_plain(self)

    @classmethod
    def from_dict(cls, data: dict) -> "GMASettings":
        """Inverse of :meth:`to_dict`; unknown keys raise ``ValueError`` naming them."""
        return from_plain(cls, data)
