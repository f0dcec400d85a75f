"""Safe steps (:class:`~kite_rto.gma.SafeStep`, :mod:`kite_rto.gma.safe_step`).

Closed-form problem, setpoints c in the box [0, 2]^2, start c0 = (0.5, 0.5) (feasible):

    model  phi = |c - (2, 2)|^2,  g = c1 + c2 - 2.5 - 2 (c1 - 0.5)^2 <= 0   (thinks c1 relaxes the constraint)
    plant  phi_p = |c - (2, 2)|^2,  g_p = c1 + c2 - 2.5 <= 0                 (it does not)

Plant optimum (1.25, 1.25) with the constraint active. The modified problem corrects the model's constraint only
to first order at c_k, so it keeps the model's curvature: its step ends beyond the plant's constraint. With the
default settings (filter 0.5, trust radius 0.25) the iterates violate g_p by up to ~0.1 and wander. The safe step
(plant curvature bound M = 0, exact here: g_p is linear) shortens those steps, leaving the trust region as it is:
no iterate violates, and GMA still reaches the plant optimum.
"""
import re

import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import (GMA, DirectionalGradient, FiniteDifferenceGradient, GMASettings, ModelProblem,
                          ModifierFilter, SafeStep, TrustRegion, run_offline)
from kite_rto.gma.safe_step import ConstraintSample, observed_curvature, safe_fraction, step_weights


def model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - 2) ** 2 + (u[1] - 2) ** 2,
                        constraints=u[0] + u[1] - 2.5 - 2.0 * (u[0] - 0.5) ** 2, outputs=u, lbu=[0, 0], ubu=[2, 2],
                        u0=[0.5, 0.5], c_lb=[0, 0], c_ub=[2, 2], name="safe_model")


def plant(c):
    return (c[0] - 2) ** 2 + (c[1] - 2) ** 2, np.array([c[0] + c[1] - 2.5])


def cut(records):
    """The records whose step a safe step shortened."""
    return [r for r in records if any(n.startswith("safe step: scaled by") for n in r.notes)]


def test_default_steps_violate_the_plant_constraint():
    gma = GMA(model(), GMASettings(), c0=[0.5, 0.5])
    run_offline(gma, plant, 30)
    assert max(r.constraints[0] for r in gma.records) > 0.05


def test_safe_steps_never_violate_and_reach_the_plant_optimum():
    gma = GMA(model(), GMASettings(safe_step=SafeStep(curvature=0.0)), c0=[0.5, 0.5])
    run_offline(gma, plant, 30)
    assert max(r.constraints[0] for r in gma.records) <= 1e-6
    np.testing.assert_allclose(gma.c, [1.25, 1.25], atol=1e-3)
    assert cut(gma.records)


def test_a_shortened_step_does_not_shrink_the_trust_region():
    """The safe steps shorten the steps and no iterate violates; a shortened step leaves the trust radius as it was
    (the trust region's own adaptation off, so nothing else changes it). The library's old default halved it."""
    gma = GMA(model(), GMASettings(safe_step=SafeStep(curvature=0.0), trust_region=TrustRegion(adapt=False)),
              c0=[0.5, 0.5])
    run_offline(gma, plant, 15)
    assert cut(gma.records) and max(r.constraints[0] for r in gma.records) <= 1e-6
    for r in gma.records:
        np.testing.assert_allclose(r.trust_radius_next, r.trust_radius)
        np.testing.assert_allclose(r.trust_radius, [0.25, 0.25])


def test_safe_fraction_in_closed_form():
    # g = -0.5, slope 1, no curvature: alpha = 0.5; with M = 2 and |d|^2 = 1: alpha^2 + alpha - 0.5 = 0
    assert safe_fraction([-0.5], [0.0], [1.0], [0.0], [0.0], 1.0, 2.0, [0.0]) == (0.5, 0)
    alpha, j = safe_fraction([-0.5], [0.0], [1.0], [0.0], [2.0], 1.0, 2.0, [0.0])
    assert j == 0 and alpha == pytest.approx((-1 + 3 ** 0.5) / 2)
    # sigmas: g + 2 * 0.1 and slope + 2 * 0.05; a tolerance of 0.1 gives room 0.4: alpha = 0.4 / 1.1
    assert safe_fraction([-0.5], [0.1], [1.0], [0.05], [0.0], 1.0, 2.0, [0.1])[0] == pytest.approx(0.4 / 1.1)
    # a step that decreases the constraint is free, also from an infeasible point; one that increases it is not
    assert safe_fraction([0.3], [0.0], [-1.0], [0.0], [0.0], 1.0, 2.0, [0.0]) == (1.0, None)
    assert safe_fraction([0.3], [0.0], [1.0], [0.0], [0.0], 1.0, 2.0, [0.0]) == (0.0, 0)


def samples(jac_end, std=None):
    """g = c^2 (box width 1) measured at c = 0, gradient 0 there, then at c = 0.5 with the gradient ``jac_end``."""
    return [ConstraintSample(np.array([0.0]), np.array([0.5]), np.array([0.0]), std, np.array([[0.0]])),
            ConstraintSample(np.array([0.5]), np.array([0.5]), np.array([0.25]), std, np.array([[jac_end]]))]


def test_observed_curvature_from_consecutive_samples():
    # the true gradient 1 at the end: e = 0.25 from either end, curvature 2 * 0.25 / 0.25 = 2
    np.testing.assert_allclose(observed_curvature(samples(1.0), [1.0], 2.0, 0.01, 1), [2.0])
    # noise of 0.05 per measurement: e - 2 hypot(0.05, 0.05)
    np.testing.assert_allclose(observed_curvature(samples(1.0, np.array([0.05])), [1.0], 2.0, 0.01, 1),
                               [2 * (0.25 - 2 * 0.05 * 2 ** 0.5) / 0.25])
    assert observed_curvature(samples(1.0), [1.0], 2.0, 0.6, 1).tolist() == [0.0]   # step too short
    # GMA did not step from the first point to the second (an undone step, an operator's point): no evidence
    moved = samples(1.0)
    moved[0] = moved[0]._replace(c_next=np.array([0.2]))
    assert observed_curvature(moved, [1.0], 2.0, 0.01, 1).tolist() == [0.0]


def test_observed_curvature_from_the_steps_end():
    """The gradient estimated at the step's end also predicts its start: g = c^2 measured at 0 and 0.5, the end's
    gradient estimated as 3 (true 1, e.g. a secant over a long perturbation): predicted g(0) = 0.25 - 1.5, measured
    0, e = 1.25, curvature 2 * 1.25 / 0.25 = 10; the start's gradient alone shows 2 (the previous test)."""
    np.testing.assert_allclose(observed_curvature(samples(3.0), [1.0], 2.0, 0.01, 1), [10.0])


@pytest.mark.parametrize("make, expected", [
    (lambda: SafeStep(curvature=-1.0), r"SafeStep.curvature=-1.0: expected every value in \[0.0, inf\]"),
    (lambda: SafeStep(sigma=-1.0), r"SafeStep.sigma=-1.0"),
    (lambda: SafeStep(tolerance=[0.1, -0.1]), r"SafeStep.tolerance=\[0.1, -0.1\]"),
    (lambda: SafeStep(learn_min_step=float("inf")), r"SafeStep.learn_min_step=inf"),
])
def test_safe_settings_are_validated(make, expected):
    with pytest.raises(ValueError, match=expected):
        make()
    assert GMASettings().safe_step is None            # off by default


def test_the_predicted_change_is_the_estimates_own_not_the_filtered_modifiers():
    """With a modifier filter the raw constraint gradient (this iteration's estimate) and the modified problem's
    (model plus the filtered mu) differ on a plant that curves; the safe step predicts the constraint's change
    with the estimate's. Each safe-step note's predicted change is that Jacobian times the unscaled step (the
    forward differences are never extrapolated here, so the model's slope takes no part)."""
    u = ca.SX.sym("u", 1)
    pr = ModelProblem(u=u, cost=-u[0], constraints=u[0] - 1.0, outputs=u, lbu=-5, ubu=5, u0=[0], c_lb=[-2], c_ub=[3],
                      name="predicted_change")
    gma = GMA(pr, GMASettings(filter_gain=1.0, trust_region=TrustRegion(radius=0.2),
                              modifier_filter=ModifierFilter(0.3),
                              safe_step=SafeStep(curvature=0.0, tolerance=0.0, sigma=0.0)),
              FiniteDifferenceGradient(0.2), c0=[0.0])
    run_offline(gma, lambda c: (-c[0], np.array([c[0] - 1.0 + 0.8 * (c[0] - 0.5) ** 2])), 8)
    checked = 0
    for r in gma.records:
        for note in r.notes:
            m = re.match(r"safe step: scaled by ([0-9.e+-]+) .*predicted change ([0-9.e+-]+),", note)
            if not m or float(m.group(1)) == 0:
                continue
            J = r.jac_constraints.ravel()[0]
            assert J != pytest.approx((r.jac_g_hat + r.mu).ravel()[0], rel=1e-2)   # the two really differ
            assert float(m.group(2)) == pytest.approx(J * r.step[0] / float(m.group(1)), rel=2e-3)
            checked += 1
    assert checked >= 2


def one_step(problem, plant1, gradient, c0, curvature):
    """One iteration with full steps, a trust radius of 0.4 box widths and exact safe steps (no sigma, no
    tolerance)."""
    s = GMASettings(filter_gain=1.0, trust_region=TrustRegion(radius=0.4, adapt=False),
                    safe_step=SafeStep(curvature=curvature, sigma=0.0, tolerance=0.0))
    gma = GMA(problem, s, gradient, c0=c0)
    run_offline(gma, plant1, 1)
    return gma.records[0]


def test_the_models_slope_keeps_a_step_safe_that_a_backward_secant_would_not():
    """Model: minimize (c - 1)^2 on [0, 1] subject to c - 0.9 <= 0; plant constraint 5 (c - 0.7)^2 - 0.1, whose
    slope at c0 = 0.8 is 1, the model's. The perturbation of 0.3 does not fit forwards and is flown backwards, to
    0.5: its secant -0.5 has the wrong sign, the modified constraint allows c >= 0.7 and the step goes to the
    upper bound. The curvature bound M = 10 is the plant's own. The step extrapolates the backward difference
    (weight -2/3), so its change is predicted with the worse of the two slopes, the model's 1, and the step ends on
    the plant's constraint, at 0.7 + sqrt(0.02) (with the estimated slope alone the safe step would take 0.81 of it,
    to 0.8 + 0.2 (0.1 + sqrt(0.05)) / 0.4, and the plant's constraint would end at +0.24)."""
    u = ca.SX.sym("u", 1)
    pr = ModelProblem(u=u, cost=(u[0] - 1.0) ** 2, constraints=u[0] - 0.9, outputs=u, lbu=[0], ubu=[1], u0=[0.8],
                      c_lb=[0], c_ub=[1], name="model_slope")

    def plant1(c):
        return (float(c[0]) - 1.0) ** 2, np.array([5.0 * (float(c[0]) - 0.7) ** 2 - 0.1])
    rec = one_step(pr, plant1, DirectionalGradient([[1.0]], step=0.3, reuse=False), [0.8], 10.0)
    assert rec.jac_constraints.ravel()[0] == pytest.approx(-0.5)      # the backward secant over [0.5, 0.8]
    assert rec.c_next[0] == pytest.approx(0.7 + np.sqrt(0.02), abs=1e-6) and plant1(rec.c_next)[1][0] <= 1e-9
    assert any("model's change +0.2" in n for n in rec.notes)


def test_the_models_slope_is_not_used_on_the_side_of_the_measured_difference():
    """Model constraint 3 c - 2.9, plant c - 1.2 (never binding in [0, 1]); from c0 = 0.3 the forward difference
    over [0.3, 0.6] measures the plant's slope 1 and the step goes to the trust region's edge, 0.7. The model's
    change over it, 1.2, exceeds the room 0.9 (the model's slope everywhere would cut the step to 0.75 of it, to
    0.6); the step lies on the side of the measured difference, which predicts it, and is taken whole."""
    u = ca.SX.sym("u", 1)
    pr = ModelProblem(u=u, cost=(u[0] - 1.0) ** 2, constraints=3.0 * u[0] - 2.9, outputs=u, lbu=[0], ubu=[1],
                      u0=[0.3], c_lb=[0], c_ub=[1], name="model_slope_forward")
    rec = one_step(pr, lambda c: ((float(c[0]) - 1.0) ** 2, np.array([float(c[0]) - 1.2])),
                   DirectionalGradient([[1.0]], step=0.3, reuse=False), [0.3], 0.0)
    assert rec.c_next[0] == pytest.approx(0.7, abs=1e-6)


def test_the_models_slope_is_used_only_for_the_extrapolated_part_of_the_step():
    """Two setpoints in [0, 1], c0 = (0.3, 0.8), perturbations of 0.3 along each: the first is flown forwards,
    the second does not fit and is flown backwards. Plant constraint c_0 + c_1 - 1.9 (measured exactly), model
    3 c_0 + c_1 - 3: the model is wrong only along the forward perturbation. The step (0.4, 0.2), to the trust
    region's and the box's edge, changes the plant's constraint by 0.6 (room 0.8); the model's change over the
    whole step is 1.4 and would cut it to 4/7. The worse slope is taken only for the backward difference's part of
    the step (weight -2/3), where model and plant agree (0.2): the whole step is flown."""
    u = ca.SX.sym("u", 2)
    pr = ModelProblem(u=u, cost=(u[0] - 1.0) ** 2 + (u[1] - 1.0) ** 2, constraints=3.0 * u[0] + u[1] - 3.0,
                      outputs=u, lbu=[0, 0], ubu=[1, 1], u0=[0.3, 0.8], c_lb=[0, 0], c_ub=[1, 1],
                      name="model_slope_terms")

    def plant2(c):
        return (c[0] - 1.0) ** 2 + (c[1] - 1.0) ** 2, np.array([c[0] + c[1] - 1.9])
    rec = one_step(pr, plant2, DirectionalGradient(np.eye(2), step=0.3, reuse=False), [0.3, 0.8], 0.0)
    np.testing.assert_allclose(rec.jac_constraints.ravel(), [1.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(rec.c_next, (0.7, 1.0), atol=1e-6)


def test_step_weights_are_negative_for_a_difference_behind_the_step():
    np.testing.assert_allclose(step_weights([[-0.3]], [0.2], [1.0]), [-2 / 3])
    np.testing.assert_allclose(step_weights([[0.5, 0.0], [0.0, -0.25]], [0.1, 0.1], [1.0, 0.5]), [0.2, -0.4])
    assert step_weights(np.zeros((0, 2)), [0.1, 0.1], [1.0, 1.0]).size == 0
