"""Safe steps (issue #14 item 3; kite_rto.gma.safety, GMASettings.safe_curvature).

Closed-form problem, setpoints c in the box [0, 2]^2, start c0 = (0.5, 0.5) (feasible):

    model  phi = |c - (2, 2)|^2,  g = c1 + c2 - 2.5 - 2 (c1 - 0.5)^2 <= 0   (thinks c1 relaxes the constraint)
    plant  phi_p = |c - (2, 2)|^2,  g_p = c1 + c2 - 2.5 <= 0                 (it does not)

Plant optimum (1.25, 1.25) with the constraint active. The modified problem corrects the model's constraint only
to first order at c_k, so it keeps the model's curvature: its step ends beyond the plant's constraint. With the
default settings (filter 0.5, trust radius 0.25) the iterates violate g_p by up to ~0.1 and wander. The safe step
(plant curvature bound M = 0, exact here: g_p is linear) shortens those steps and shrinks the trust region: no
iterate violates, and GMA still reaches the plant optimum.
"""
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import GMA, DirectionalGradient, FiniteDifferenceGradient, GMASettings, ModelProblem, run_offline
from kite_rto.gma.safety import observed_curvature, safe_fraction


def model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - 2) ** 2 + (u[1] - 2) ** 2,
                        constraints=u[0] + u[1] - 2.5 - 2.0 * (u[0] - 0.5) ** 2, outputs=u, lbu=[0, 0], ubu=[2, 2],
                        u0=[0.5, 0.5], c_lb=[0, 0], c_ub=[2, 2], name="safe_model")


def plant(c):
    return (c[0] - 2) ** 2 + (c[1] - 2) ** 2, np.array([c[0] + c[1] - 2.5])


def test_default_steps_violate_the_plant_constraint():
    gma = GMA(model(), GMASettings(), c0=[0.5, 0.5])
    run_offline(gma, plant, 30)
    assert max(r.constraints[0] for r in gma.records) > 0.05


def test_safe_steps_never_violate_and_reach_the_plant_optimum():
    gma = GMA(model(), GMASettings(safe_curvature=0.0), c0=[0.5, 0.5])
    run_offline(gma, plant, 30)
    assert max(r.constraints[0] for r in gma.records) <= 1e-6
    np.testing.assert_allclose(gma.c, [1.25, 1.25], atol=1e-3)
    cut = [n for r in gma.records for n in r.notes if n.startswith("safe step: scaled by")]
    assert cut and all(n.endswith("trust region shrunk") for n in cut)


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


def test_observed_curvature_from_consecutive_records():
    # g = c^2 measured at c = 0 and 0.5 (box width 1), gradient 0 at 0: e = 0.25, curvature 2 * 0.25 / 0.25 = 2
    recs = [SimpleNamespace(c_k=np.array([0.0]), c_next=np.array([0.5]), constraints=np.array([0.0]),
                            jac_constraints=np.array([[0.0]])),
            SimpleNamespace(c_k=np.array([0.5]), c_next=np.array([0.5]), constraints=np.array([0.25]),
                            jac_constraints=np.array([[1.0]]))]
    np.testing.assert_allclose(observed_curvature(recs, [None, None], [1.0], 2.0, 0.01, 1), [2.0])
    # noise of 0.05 per measurement: e - 2 hypot(0.05, 0.05)
    np.testing.assert_allclose(observed_curvature(recs, [np.array([0.05])] * 2, [1.0], 2.0, 0.01, 1),
                               [2 * (0.25 - 2 * 0.05 * 2 ** 0.5) / 0.25])
    assert observed_curvature(recs, [None, None], [1.0], 2.0, 0.6, 1).tolist() == [0.0]   # step too short


def test_observed_curvature_from_the_steps_end():
    """With ``both_ends`` the gradient estimated at the step's end also predicts its start: g = c^2 measured at 0
    and 0.5, the end's gradient estimated as 3 (true 1, e.g. a secant over a long perturbation): predicted
    g(0) = 0.25 - 1.5, measured 0, e = 1.25, curvature 2 * 1.25 / 0.25 = 10; from the start's gradient only 2."""
    recs = [SimpleNamespace(c_k=np.array([0.0]), c_next=np.array([0.5]), constraints=np.array([0.0]),
                            jac_constraints=np.array([[0.0]])),
            SimpleNamespace(c_k=np.array([0.5]), c_next=np.array([0.5]), constraints=np.array([0.25]),
                            jac_constraints=np.array([[3.0]]))]
    np.testing.assert_allclose(observed_curvature(recs, [None, None], [1.0], 2.0, 0.01, 1), [2.0])
    np.testing.assert_allclose(observed_curvature(recs, [None, None], [1.0], 2.0, 0.01, 1, both_ends=True), [10.0])
    recs[1].jac_constraints = np.array([[1.0]])          # the true gradient: the start's curvature 2 again
    np.testing.assert_allclose(observed_curvature(recs, [None, None], [1.0], 2.0, 0.01, 1, both_ends=True), [2.0])


@pytest.mark.parametrize("field, value, expected", [
    ("safe_curvature", -1.0, r"safe_curvature=-1.0: expected every value in \[0.0, inf\]"),
    ("safe_sigma", -1.0, r"safe_sigma=-1.0"),
    ("safe_tolerance", [0.1, -0.1], r"safe_tolerance=\[0.1, -0.1\]"),
    ("safe_adapt_min_step", float("inf"), r"safe_adapt_min_step=inf"),
    ("safe_both_ends", 1, r"safe_both_ends=1: expected True or False"),
    ("safe_model_slope", "yes", r"safe_model_slope='yes': expected True, False, 'extrapolated' or 'terms'"),
    ("safe_model_slope", 1, r"safe_model_slope=1: expected True, False, 'extrapolated' or 'terms'"),
])
def test_safe_settings_are_validated(field, value, expected):
    with pytest.raises(ValueError, match=expected):
        GMASettings(**{field: value})
    assert GMASettings().safe_curvature is None            # off by default


@pytest.mark.parametrize("filtered", [False, True])
def test_safe_filtered_predicts_with_the_modified_problems_jacobian(filtered):
    """With a modifier filter the raw constraint gradient (this iteration's estimate) and the modified problem's
    (model plus the filtered mu) differ on a plant that curves; ``safe_filtered`` predicts the constraint's change
    with the latter. Each safe-step note's predicted change is that Jacobian times the unscaled step."""
    import re
    u = ca.SX.sym("u", 1)
    pr = ModelProblem(u=u, cost=-u[0], constraints=u[0] - 1.0, outputs=u, lbu=-5, ubu=5, u0=[0], c_lb=[-2], c_ub=[3],
                      name="safe_filtered")
    gma = GMA(pr, GMASettings(filter_gain=1.0, trust_radius=0.2, modifier_filter=0.3, safe_curvature=0.0,
                              safe_tolerance=0.0, safe_sigma=0.0, safe_filtered=filtered),
              FiniteDifferenceGradient(0.2), c0=[0.0])
    run_offline(gma, lambda c: (-c[0], np.array([c[0] - 1.0 + 0.8 * (c[0] - 0.5) ** 2])), 8)
    checked = 0
    for r in gma.records:
        for note in r.notes:
            m = re.match(r"safe step: scaled by ([0-9.e+-]+) .*predicted change ([0-9.e+-]+),", note)
            if not m or float(m.group(1)) == 0:
                continue
            J = (r.jac_g_hat + r.mu).ravel()[0] if filtered else r.jac_constraints.ravel()[0]
            assert float(m.group(2)) == pytest.approx(J * r.step[0] / float(m.group(1)), rel=2e-3)
            checked += 1
    assert checked >= 2
    with pytest.raises(ValueError, match="safe_filtered='no': expected True or False"):
        GMASettings(safe_filtered="no")


def test_truncation_bound_of_forward_differences_is_half_the_step_times_the_perturbation():
    """Coordinate forward differences of h_i (box widths): a_i = d_i / h_i, bound 0.5 sum |d_i| h_i."""
    from kite_rto.gma.safety import truncation_bound
    w = np.array([2.0, 0.5])
    disp = np.array([[0.3, 0.0], [0.0, -0.1]])
    step = np.array([0.2, 0.05])
    h, d = np.array([0.3, -0.1]) / w, step / w
    assert truncation_bound(disp, step, w) == pytest.approx(0.5 * np.sum(np.abs(d) * np.abs(h)))
    assert truncation_bound(np.zeros((0, 2)), step, w) == 0.0


def _one_setpoint():
    """Maximize c in [0, 1]; the model's constraint c - 2 never binds, the plant's 5 (c - 0.3)^2 - 1.2 <= 0 binds at
    c = 0.79. From c0 = 0.6 the forward difference of 0.5 would leave the box, so it is taken backwards (to 0.1):
    its secant 0.5 is a sixth of the plant's slope 3 at c0, and the step towards c = 1 sees almost no rise."""
    u = ca.SX.sym("u", 1)
    problem = ModelProblem(u=u, cost=-u[0], constraints=u[0] - 2.0, outputs=u, lbu=[0], ubu=[1], u0=[0.6],
                           c_lb=[0], c_ub=[1], name="truncation")

    def plant1(c):
        return -float(c[0]), np.array([5.0 * (c[0] - 0.3) ** 2 - 1.2])
    return problem, plant1


@pytest.mark.parametrize("truncation", [False, True])
def test_a_backward_perturbation_needs_the_truncation_bound_to_keep_the_step_safe(truncation):
    """Curvature bound M = 10, the plant's own: with the truncation bound the first step ends on the plant's
    constraint (the bound is tight for a quadratic), without it 0.85 of the step is taken and the plant's
    constraint is exceeded by 0.85."""
    problem, plant1 = _one_setpoint()
    s = GMASettings(filter_gain=1.0, trust_radius=np.inf, trust_adapt=False, safe_curvature=10.0, safe_sigma=0.0,
                    safe_truncation=truncation)
    gma = GMA(problem, s, FiniteDifferenceGradient(0.5), c0=[0.6])
    run_offline(gma, plant1, 1)
    rec = gma.records[0]
    assert rec.c_k[0] == pytest.approx(0.6)
    g_next = plant1(rec.c_next)[1][0]
    if truncation:
        assert g_next <= 1e-9 and rec.c_next[0] == pytest.approx(0.3 + np.sqrt(0.24), abs=1e-6)
        assert any("truncation bound +1" in n for n in rec.notes)
    else:
        assert g_next > 0.5


@pytest.mark.parametrize("model_slope", [False, True, "extrapolated", "terms"])
def test_the_models_slope_keeps_a_step_safe_that_a_backward_secant_would_not(model_slope):
    """Model: minimize (c - 1)^2 on [0, 1] subject to c - 0.9 <= 0; plant constraint 5 (c - 0.7)^2 - 0.1, whose
    slope at c0 = 0.8 is 1, the model's. The perturbation of 0.3 does not fit forwards and is flown backwards, to
    0.5: its secant -0.5 has the wrong sign, the modified constraint allows c >= 0.7 and the step goes to the
    upper bound. The curvature bound M = 10 is the plant's own. With the estimated slope alone the safe step takes
    0.81 of it and the plant's constraint ends at +0.24; with ``safe_model_slope`` the change is predicted with the
    model's slope 1 and the step ends on the plant's constraint, at 0.7 + sqrt(0.02); ``"extrapolated"`` and
    ``"terms"`` do the same, the step being made of the backward difference with weight -2/3."""
    u = ca.SX.sym("u", 1)
    pr = ModelProblem(u=u, cost=(u[0] - 1.0) ** 2, constraints=u[0] - 0.9, outputs=u, lbu=[0], ubu=[1], u0=[0.8],
                      c_lb=[0], c_ub=[1], name="model_slope")

    def plant1(c):
        return (float(c[0]) - 1.0) ** 2, np.array([5.0 * (float(c[0]) - 0.7) ** 2 - 0.1])
    s = GMASettings(filter_gain=1.0, trust_radius=0.4, trust_adapt=False, safe_curvature=10.0, safe_sigma=0.0,
                    safe_tolerance=0.0, safe_model_slope=model_slope)
    gma = GMA(pr, s, DirectionalGradient([[1.0]], step=0.3, reuse=False), c0=[0.8])
    run_offline(gma, plant1, 1)
    rec = gma.records[0]
    assert rec.jac_constraints.ravel()[0] == pytest.approx(-0.5)      # the backward secant over [0.5, 0.8]
    g_next = plant1(rec.c_next)[1][0]
    if model_slope:
        assert rec.c_next[0] == pytest.approx(0.7 + np.sqrt(0.02), abs=1e-6) and g_next <= 1e-9
        assert any("model's change +0.2" in n for n in rec.notes)
    else:
        assert rec.c_next[0] == pytest.approx(0.8 + 0.2 * (0.1 + np.sqrt(0.05)) / 0.4, abs=1e-6)
        assert g_next > 0.2


@pytest.mark.parametrize("model_slope, c1", [(False, 0.7), ("extrapolated", 0.7), ("terms", 0.7), (True, 0.6)])
def test_extrapolated_uses_the_models_slope_only_across_c_k(model_slope, c1):
    """Model constraint 3 c - 2.9, plant c - 1.2 (never binding in [0, 1]); from c0 = 0.3 the forward difference
    over [0.3, 0.6] measures the plant's slope 1 and the step goes to the trust region's edge, 0.7. The model's
    change over it, 1.2, exceeds the room 0.9: ``True`` cuts the step to 0.75 of it; ``"extrapolated"`` does not,
    the step lying on the side of the measured difference."""
    u = ca.SX.sym("u", 1)
    pr = ModelProblem(u=u, cost=(u[0] - 1.0) ** 2, constraints=3.0 * u[0] - 2.9, outputs=u, lbu=[0], ubu=[1],
                      u0=[0.3], c_lb=[0], c_ub=[1], name="model_slope_forward")
    s = GMASettings(filter_gain=1.0, trust_radius=0.4, trust_adapt=False, safe_curvature=0.0, safe_sigma=0.0,
                    safe_tolerance=0.0, safe_model_slope=model_slope)
    gma = GMA(pr, s, DirectionalGradient([[1.0]], step=0.3, reuse=False), c0=[0.3])
    run_offline(gma, lambda c: ((float(c[0]) - 1.0) ** 2, np.array([float(c[0]) - 1.2])), 1)
    assert gma.records[0].c_next[0] == pytest.approx(c1, abs=1e-6)


@pytest.mark.parametrize("model_slope, c_next", [(False, (0.7, 1.0)), ("terms", (0.7, 1.0)),
                                                  ("extrapolated", (0.3 + 0.4 * 4 / 7, 0.8 + 0.2 * 4 / 7)),
                                                  (True, (0.3 + 0.4 * 4 / 7, 0.8 + 0.2 * 4 / 7))])
def test_terms_use_the_models_slope_only_for_the_extrapolated_part_of_the_step(model_slope, c_next):
    """Two setpoints in [0, 1], c0 = (0.3, 0.8), perturbations of 0.3 along each: the first is flown forwards,
    the second does not fit and is flown backwards. Plant constraint c_0 + c_1 - 1.9 (measured exactly), model
    3 c_0 + c_1 - 3: the model is wrong only along the forward perturbation. The step (0.4, 0.2), to the trust
    region's and the box's edge, changes the plant's constraint by 0.6 (room 0.8); the model's change over the
    whole step is 1.4. ``"extrapolated"`` (the step extrapolates the second difference, weight -2/3) and ``True``
    cut it to 4/7; ``"terms"`` takes the worse slope only for that difference's part, where model and plant
    agree (0.2), and flies the whole step."""
    u = ca.SX.sym("u", 2)
    pr = ModelProblem(u=u, cost=(u[0] - 1.0) ** 2 + (u[1] - 1.0) ** 2, constraints=3.0 * u[0] + u[1] - 3.0,
                      outputs=u, lbu=[0, 0], ubu=[1, 1], u0=[0.3, 0.8], c_lb=[0, 0], c_ub=[1, 1],
                      name="model_slope_terms")

    def plant2(c):
        return (c[0] - 1.0) ** 2 + (c[1] - 1.0) ** 2, np.array([c[0] + c[1] - 1.9])
    s = GMASettings(filter_gain=1.0, trust_radius=0.4, trust_adapt=False, safe_curvature=0.0, safe_sigma=0.0,
                    safe_tolerance=0.0, safe_model_slope=model_slope)
    gma = GMA(pr, s, DirectionalGradient(np.eye(2), step=0.3, reuse=False), c0=[0.3, 0.8])
    run_offline(gma, plant2, 1)
    rec = gma.records[0]
    np.testing.assert_allclose(rec.jac_constraints.ravel(), [1.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(rec.c_next, c_next, atol=1e-6)


def test_step_weights_are_negative_for_a_difference_behind_the_step():
    from kite_rto.gma.safety import step_weights
    np.testing.assert_allclose(step_weights([[-0.3]], [0.2], [1.0]), [-2 / 3])
    np.testing.assert_allclose(step_weights([[0.5, 0.0], [0.0, -0.25]], [0.1, 0.1], [1.0, 0.5]), [0.2, -0.4])
    assert step_weights(np.zeros((0, 2)), [0.1, 0.1], [1.0, 1.0]).size == 0
