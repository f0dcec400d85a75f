"""Tuning of GMA on the kite: :class:`KiteRTOSettings` (experiments, gradients, GMA's own settings).

Chosen on the campaign's tuning scenarios (``kite_campaign --scenarios tuning``: the default plant, stronger shear
with IEC class A turbulence, a lower glide ratio with more glide loss, h_min 115 m; docs/benchmarks.md has the
numbers) and reported on all twelve. With the literature prior of :class:`~kite_rto.rto.directions.ModelUncertainty`
no setpoint bound is robustly active (theta_0's gradient changes by more than half its size under the prior), so
DMA measures along all three privileged directions: 4 experiments per iteration. In the 3-D field a 4-lap
experiment's observer-normalized mean scatters by 6.6-8.3 kN, comparable to the cost differences near the optimum,
so GMA averages its gradient modifiers over iterations with a gain matched to the noise
(:mod:`~kite_rto.gma.noise_filter`, ``modifier_drift`` 15: close to 1 after a long step, the running mean at a point
it stays at; the first iteration takes its measurement unfiltered; 15 rather than 5 forgets the modifiers measured
far away sooner, chosen on the tuning set's seeds 0-5: no run ends below 99 % against 1 of 24); the altitude,
measured to 0.1-0.3 m, gets a gain of its own (``constraint_drift`` 20), so the modified problem and the safe step
predict it alike. Every step is sized so that the altitude constraint, predicted from its measured value and gradient
with 2 standard deviations and a curvature bound of 20 m per squared box width learned upwards from steps of at
least 0.1 box widths, stays within 1 m (safe steps, :mod:`~kite_rto.gma.safety`; a cut step leaves the trust region
as it is). The altitude constraint's gradient modifier comes from the model's own quotients over the flown points
(``model_secant`` on the constraints only): the model's constraint is the reference figure-eight's geometry, so its
quotients carry the same truncation error as the plant's and the difference cancels it, while the cost keeps the
plant's quotients (on the tuning set's seeds 0-5 no iterate below h_min - 2 m in 24 runs against 3 of 24).
Near the optimum a 4-lap gradient is as large as its noise, so from iteration 1 on, once the first long step is
taken, every experiment averages twice as many laps (``averaging_schedule`` (1, 2)); the safe step's curvature
bound also learns from the gradient at each step's end predicting its start (``safe_both_ends``: with the longer
experiments a secant over a perturbation through a strongly curved region otherwise took one tuning run below
h_min - 2 m), and a step after which the measured cost rose by more than one standard error is undone
(``reject_sigma`` 1). On the tuning set's seeds 0-5 the three together leave 8 iterates of 192 below 99 % from
iteration 3 on against 18 and hold 99 % from iteration 3 on 19 runs of 24 against 17 (docs/benchmarks.md). Most
runs that then lose 99 % again leave the aspect's upper bound, where the plant optimum lies or nearly lies and the
measured slope is noise, for the trust region's edge: from iteration 2 on a setpoint at a bound stays there unless the
held modified problem's multiplier of it (constraints included) exceeds 2 standard deviations of the cost modifier
(``bound_sigma`` 2; tuning seeds 0-5: 20 runs of 24 held, 7 late dips; seeds 6-8 of all twelve, never run
before: 33 of 36 held against 31, every run ending at >= 99 % against 35). The bounds the model optimum sits on
(the start's: theta_0's and the aspect's lower bounds) are not held (``bound_sigma_start`` False): they are the
model's claim, which the measurements must be able to overrule at every iteration; holding them kept the aspect at
its lower bound where the plant optimum lies 0.87 box widths inside (tuning seeds 0-5: the same summary, 2 of 24
runs fly differently). Full steps (filter gain 1) inside a
trust region of 0.7 box widths keep the first iteration's large correction.
The altitude back-off is 3 m: 6 m cost about 1 % where the constraint binds hard (h_min 115 m). The model's
altitude constraint bounds the reference figure-eight of the lap's setpoints (``altitude = "reference"``), and in
the 3-D field the experiment normalizes the tension by the profile observer (``wind_source =
"observer_profile"``, the default of :func:`~kite_rto.rto.experiment.default_wind_source`): the two together,
chosen on the tuning set, hold 99 % from iteration 3 on in 10 of its 12 runs against 6 (docs/benchmarks.md).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..gma import DirectionalGradient, FiniteDifferenceGradient, GMASettings, LeastSquaresGradient
from ..flight.shape import ShapeBox
from .directions import ModelUncertainty
from .experiment import ExperimentSpec
from .ocp import ALTITUDES, KiteOCPSettings

__all__ = ["KiteRTOSettings", "GRADIENTS", "default_gma_settings"]

GRADIENTS = ("directional", "forward", "central", "least_squares")
"""The plant-gradient strategies of :attr:`KiteRTOSettings.gradient`."""


def default_gma_settings() -> GMASettings:
    """GMA's settings on the kite (see the module docstring): full steps (filter gain 1) inside a trust region of
    0.7 box widths (adapted down to 0.05), the modifier filter matched to the noise (drift bound 15 cost units per
    squared box width; the fixed filter 0.5 where an estimate has no standard deviation), the altitude's gradient
    modifier filtered by its own noise (drift bound 20 m per squared box width), 3 m altitude back-off, safe steps
    (curvature bound 20 m per squared box width learned from both ends of steps of at least 0.1 box widths, 2
    standard deviations, 1 m tolerance; a cut step does not shrink the trust region; the model's slope where it is
    worse for the part of the step that extrapolates, ``safe_model_slope`` ``"terms"``), the constraints' gradient
    modifiers from the model's secant (``model_secant``, ``model_secant_cost`` False), experiments twice as long
    from iteration 1 on (``averaging_schedule`` (1, 2)), a step undone when the measured cost rose by more than 1
    standard error (``reject_sigma`` 1), setpoints at a bound of the box held there from iteration 2 on unless the
    held problem's multiplier exceeds 2 standard deviations of the cost modifier (``bound_sigma`` 2), except the
    bounds the run started on (``bound_sigma_start`` False), ``tol_c`` 1e-3."""
    return GMASettings(filter_gain=1.0, modifier_filter=0.5, modifier_drift=15.0, constraint_drift=20.0,
                       trust_radius=0.7, trust_radius_min=0.05, backoff=3.0, safe_curvature=20.0, safe_sigma=2.0,
                       safe_tolerance=1.0, safe_shrink=False, safe_adapt_min_step=0.1, safe_both_ends=True,
                       safe_model_slope="terms", model_secant=True, model_secant_cost=False,
                       averaging_schedule=(1.0, 2.0), reject_sigma=1.0, bound_sigma=2.0, bound_sigma_start=False,
                       tol_c=1e-3)


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
        fd_alternate: perturb backwards in odd iterations (``alternate`` of the directional and forward
            strategies), so that the modifier filter averages forward and backward quotients (with
            ``gma.alternate_within``: counted from the last long step).
        fd_reflect: with ``fd_alternate`` and ``"directional"``: a backward iteration reflects the forward
            perturbations through ``c_k`` in the setpoints where that stays in the box (``reflect`` of
            :class:`~kite_rto.gma.DirectionalGradient`), so that a direction mixing theta_0 held at its bound with
            free setpoints still changes side in the free ones.
        fd_lead: with ``"directional"``: perturb each direction on the side the last step went, where that keeps
            at least half of the step in the box (``lead`` of :class:`~kite_rto.gma.DirectionalGradient`).
        fd_keep: with ``"directional"``: the forward perturbation is flown, clipped to the box, while it keeps at
            least this fraction of the step, in (0, 1] (``keep_side`` of
            :class:`~kite_rto.gma.DirectionalGradient`; 1: backwards whenever the forward step does not fit whole).
        n_directions: privileged directions of ``"directional"`` (1 to 3; at most the coordinates not held at a
            robustly active bound, none under the default prior).
        uncertainty: the model-parameter deviations that define the privileged directions.
        gma: GMA's :class:`~kite_rto.gma.GMASettings` (filter gain, modifier filter, trust radius and its
            minimum, relative to the box width, back-off in m, ...; default :func:`default_gma_settings`). Its
            ``settle_time`` and ``averaging`` hints are replaced by ``experiment``'s (:meth:`gma_settings`).
        altitude: what the model's altitude constraint bounds (:attr:`KiteOCPSettings.altitude
            <kite_rto.rto.ocp.KiteOCPSettings>`): ``"lap"``, the model lap's lowest point, or ``"reference"``, the
            lowest point of the reference figure-eight of the lap's setpoints.
        max_repeats: times a crashed/invalid experiment is repeated before it is submitted as measured
            (NaN-free) or, with no lap at all, the run stops (>= 0).
        c0: initial setpoints (theta_0, A_phi, A_theta), rad; None = the model-only optimum.
    """

    experiment: ExperimentSpec = field(default_factory=lambda: ExperimentSpec(n_laps=4))
    box: ShapeBox = field(default_factory=ShapeBox)
    gradient: str = "directional"
    fd_step: tuple = (0.5, 0.5, 0.5)
    fd_alternate: bool = False
    fd_reflect: bool = False
    fd_lead: bool = False
    fd_keep: float = 1.0
    n_directions: int = 3
    uncertainty: ModelUncertainty = field(default_factory=ModelUncertainty)
    gma: GMASettings = field(default_factory=default_gma_settings)
    altitude: str = "reference"
    max_repeats: int = 3
    c0: tuple | None = None

    def __post_init__(self):
        n = type(self).__name__
        if self.gradient not in GRADIENTS:
            raise ValueError(f"{n}.gradient = {self.gradient!r}: expected one of {GRADIENTS}")
        steps = np.atleast_1d(np.asarray(self.fd_step, dtype=float))
        if steps.size not in (1, 3) or not np.all((steps > 0) & (steps <= 1)):
            raise ValueError(f"{n}.fd_step = {self.fd_step!r}: expected 1 or 3 values in (0, 1]")
        if not isinstance(self.fd_alternate, bool):
            raise ValueError(f"{n}.fd_alternate = {self.fd_alternate!r}: expected True or False")
        if not isinstance(self.fd_reflect, bool):
            raise ValueError(f"{n}.fd_reflect = {self.fd_reflect!r}: expected True or False")
        if not isinstance(self.fd_lead, bool) or (self.fd_lead and self.fd_alternate):
            raise ValueError(f"{n}.fd_lead = {self.fd_lead!r}: expected True or False, and not True with "
                             f"fd_alternate")
        if isinstance(self.fd_keep, bool) or not isinstance(self.fd_keep, (int, float)) or \
                not 0.0 < self.fd_keep <= 1.0:
            raise ValueError(f"{n}.fd_keep = {self.fd_keep!r}: expected a number in (0, 1]")
        if not isinstance(self.gma, GMASettings):
            raise ValueError(f"{n}.gma = {self.gma!r}: expected a GMASettings")
        if isinstance(self.n_directions, bool) or self.n_directions not in (1, 2, 3):
            raise ValueError(f"{n}.n_directions = {self.n_directions!r}: expected 1, 2 or 3")
        if self.altitude not in ALTITUDES:
            raise ValueError(f"{n}.altitude = {self.altitude!r}: expected one of {ALTITUDES}")
        if isinstance(self.max_repeats, bool) or not isinstance(self.max_repeats, int) or self.max_repeats < 0:
            raise ValueError(f"{n}.max_repeats = {self.max_repeats!r}: expected an integer >= 0")

    def with_gma(self, **changes) -> "KiteRTOSettings":
        """A copy with ``changes`` applied to :attr:`gma` (e.g. ``with_gma(filter_gain=0.8)``)."""
        return replace(self, gma=replace(self.gma, **changes))

    def ocp_settings(self) -> KiteOCPSettings:
        """The lap OCP's :class:`~kite_rto.rto.ocp.KiteOCPSettings`: the experiment's h_min (m) and
        :attr:`altitude`, the rest at their defaults."""
        return KiteOCPSettings(h_min=self.experiment.h_min, altitude=self.altitude)

    def gma_settings(self) -> GMASettings:
        """The :class:`GMASettings` GMA runs with: :attr:`gma` with the experiment's settle time (s) and
        averaging (laps) as hints."""
        sp = self.experiment
        return replace(self.gma, settle_time=sp.settle_time, averaging=float(sp.n_laps))

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
            return DirectionalGradient(directions, step=float(np.ravel(self.fd_step)[0]), reuse=False,
                                       alternate=self.fd_alternate, reflect=self.fd_reflect, lead=self.fd_lead,
                                       keep_side=self.fd_keep)
        alternate = self.fd_alternate and self.gradient != "central"
        if self.gradient == "least_squares":
            return LeastSquaresGradient(FiniteDifferenceGradient(steps, alternate=alternate), radius=2.0 * steps,
                                        window=8)
        return FiniteDifferenceGradient(steps, self.gradient, alternate)
