"""The kite's GMA settings: :class:`KiteRTOSettings` (experiments, box, gradient strategy, GMA's own settings).

The defaults (:func:`default_gma_settings`) were chosen on the campaign's tuning scenarios and reported on all
twelve (``kite_campaign``; docs/benchmarks.md has the current numbers, docs/history.md what each choice gave).
DMA measures along all three privileged directions (under the literature prior no setpoint bound is robustly
active): 4 experiments per iteration.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..gma import (BoundHold, DirectionalGradient, FiniteDifferenceGradient, GMASettings, LeastSquaresGradient,
                   ModelSecant, ModifierFilter, NoiseFilter, SafeStep, TrustRegion, Undo)
from ..flight.shape import ShapeBox
from .directions import ModelUncertainty
from .experiment import ExperimentSpec
from .ocp import KiteOCPSettings

__all__ = ["KiteRTOSettings", "GRADIENTS", "default_gma_settings"]

GRADIENTS = ("directional", "forward", "central", "least_squares")
"""The plant-gradient strategies of :attr:`KiteRTOSettings.gradient`."""


def default_gma_settings() -> GMASettings:
    """GMA's settings on the kite, each chosen by measurement (docs/history.md):

    - full steps (filter gain 1) inside a trust region of 0.7 box widths, adapted down to 0.05;
    - the gradient modifiers filtered with a gain matched to the noise (drift bound 15 cost units per squared box
      width; the fixed gain 0.5 where an estimate has no standard deviation), the altitude's by its own noise
      (drift bound 20 m per squared box width): a 4-lap experiment scatters as much as the cost differences near
      the optimum;
    - 3 m altitude back-off;
    - safe steps: the altitude predicted with 2 standard deviations and a curvature bound of 20 m per squared box
      width, learned from steps of at least 0.1 box widths, kept within 1 m of h_min;
    - the altitude's gradient modifier from the model's secant (the model's constraint is the reference path's
      geometry, whose quotients carry the same truncation error as the plant's);
    - experiments twice as long from iteration 1 on (``effort_schedule`` (1, 2): near the optimum a 4-lap gradient
      is as large as its noise);
    - a step undone when the measured cost rose by more than 1 standard error;
    - a setpoint at a bound an earlier step reached held there from iteration 2 on unless the held problem's
      multiplier exceeds 2 standard deviations of the cost modifier;
    - ``tol_c`` 1e-3 box widths.
    """
    return GMASettings(filter_gain=1.0, tol_c=1e-3, backoff=3.0, effort_schedule=(1.0, 2.0),
                       modifier_filter=ModifierFilter(gain=0.5),
                       noise_filter=NoiseFilter(drift=15.0, constraint_drift=20.0),
                       trust_region=TrustRegion(radius=0.7, min_radius=0.05),
                       safe_step=SafeStep(curvature=20.0, sigma=2.0, tolerance=1.0, learn_min_step=0.1),
                       undo=Undo(sigma=1.0), bound_hold=BoundHold(sigma=2.0, after=2), model_secant=ModelSecant())


@dataclass(frozen=True)
class KiteRTOSettings:
    """Tuning of GMA on the kite.

    Attributes:
        experiment: :class:`ExperimentSpec` of every experiment (nominal and perturbations).
        box: the optimizer's :class:`ShapeBox` (shape coordinates); every point of it tracks.
        gradient: ``"directional"`` (DMA: forward differences along ``n_directions`` privileged directions,
            the model's gradient elsewhere), ``"forward"`` / ``"central"`` finite differences in every shape
            coordinate, or ``"least_squares"`` over past points with forward differences as fallback.
        fd_step: finite-difference step per shape coordinate, relative to the box width, in (0, 1]; for
            ``"directional"`` the first value is the step along each privileged direction (box widths).
        n_directions: privileged directions of ``"directional"`` (1 to 3; at most the coordinates not held at a
            robustly active bound, none under the default prior).
        uncertainty: the model-parameter deviations that define the privileged directions.
        gma: GMA's :class:`~kite_rto.gma.GMASettings` (relative to the box width; back-off in m; the effort
            schedule multiplies ``experiment.n_laps``; default :func:`default_gma_settings`).
        ocp: the lap OCP's :class:`~kite_rto.rto.ocp.KiteOCPSettings` (discretization, bounds, what the altitude
            constraint bounds); its h_min is the experiment's.
        max_repeats: times a crashed/invalid experiment is repeated before it is submitted as measured
            (NaN-free) or, with no lap at all, the run stops (>= 0).
        c0: initial setpoints (theta_0, A_phi, A_theta), rad; None = the model-only optimum.
    """

    experiment: ExperimentSpec = field(default_factory=ExperimentSpec)
    box: ShapeBox = field(default_factory=ShapeBox)
    gradient: str = "directional"
    fd_step: tuple = (0.5, 0.5, 0.5)
    n_directions: int = 3
    uncertainty: ModelUncertainty = field(default_factory=ModelUncertainty)
    gma: GMASettings = field(default_factory=default_gma_settings)
    ocp: KiteOCPSettings = field(default_factory=KiteOCPSettings)
    max_repeats: int = 3
    c0: tuple | None = None

    def __post_init__(self):
        n = type(self).__name__
        if self.gradient not in GRADIENTS:
            raise ValueError(f"{n}.gradient = {self.gradient!r}: expected one of {GRADIENTS}")
        steps = np.atleast_1d(np.asarray(self.fd_step, dtype=float))
        if steps.size not in (1, 3) or not np.all((steps > 0) & (steps <= 1)):
            raise ValueError(f"{n}.fd_step = {self.fd_step!r}: expected 1 or 3 values in (0, 1]")
        if not isinstance(self.gma, GMASettings):
            raise ValueError(f"{n}.gma = {self.gma!r}: expected a GMASettings")
        if isinstance(self.n_directions, bool) or self.n_directions not in (1, 2, 3):
            raise ValueError(f"{n}.n_directions = {self.n_directions!r}: expected 1, 2 or 3")
        if not isinstance(self.ocp, KiteOCPSettings):
            raise ValueError(f"{n}.ocp = {self.ocp!r}: expected a KiteOCPSettings")
        if isinstance(self.max_repeats, bool) or not isinstance(self.max_repeats, int) or self.max_repeats < 0:
            raise ValueError(f"{n}.max_repeats = {self.max_repeats!r}: expected an integer >= 0")

    def with_gma(self, **changes) -> "KiteRTOSettings":
        """A copy with ``changes`` applied to :attr:`gma` (e.g. ``with_gma(filter_gain=0.8)``)."""
        return replace(self, gma=replace(self.gma, **changes))

    def experiments_per_iteration(self) -> int:
        """Nominal + perturbation experiments of one iteration (least squares: when it falls back)."""
        n = {"directional": self.n_directions, "central": 6}.get(self.gradient, 3)
        return 1 + n

    def gradient_estimator(self, directions=None):
        """The plant-gradient strategy (absolute steps, rad); ``"directional"`` needs the privileged
        ``directions`` (3, r) in shape coordinates (:func:`~kite_rto.rto.builder.make_gma` computes them)."""
        width = self.box.upper() - self.box.lower()
        steps = np.broadcast_to(np.asarray(self.fd_step, dtype=float), (3,)) * width
        if self.gradient == "directional":
            if directions is None:
                raise ValueError("KiteRTOSettings.gradient_estimator: 'directional' needs the privileged directions")
            return DirectionalGradient(directions, step=float(np.ravel(self.fd_step)[0]), reuse=False)
        if self.gradient == "least_squares":
            return LeastSquaresGradient(FiniteDifferenceGradient(steps), radius=2.0 * steps, window=8)
        return FiniteDifferenceGradient(steps, self.gradient)
