"""Constraint modifiers from the model's own difference quotients (:class:`~kite_rto.gma.ModelSecant`,
gma/model_secant.py): with large finite-difference steps the measured constraint Jacobian is the plant's *secant*;
taking the model's secant over the same points cancels that error up to the curvature mismatch. The cost keeps the
plant's quotients (``ModelSecant`` replaced ``model_secant=True``, which also corrected the cost by default)."""
import casadi as ca
import numpy as np
import pytest
from scipy.optimize import minimize

from kite_rto.gma import (GMA, DirectionalGradient, ExperimentResult, FiniteDifferenceGradient, GMASettings,
                          LeastSquaresGradient, ModelProblem, ModelSecant, PlantPoint, TrustRegion, run_offline)
from kite_rto.gma.model_secant import ModelPoint, model_secant_estimate


def model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - 0.5) ** 2 + (u[1] - 1.5) ** 2, constraints=0.9 * u[0] + u[1] - 2.2,
                        outputs=u, lbu=-5, ubu=5, u0=[0, 0], c_lb=[-2, -2], c_ub=[3, 3], name="secant")


D = np.array([1.0, -0.5])


def plant(c, extra_curvature=0.0):
    """The model's cost plus a linear mismatch (and optionally more curvature along the first setpoint)."""
    c = np.asarray(c, float)
    phi = (c[0] - 0.5) ** 2 + (c[1] - 1.5) ** 2 + 0.8 * D @ c + extra_curvature * (c[0] - 0.2) ** 2
    return phi, np.array([0.9 * c[0] + c[1] - 2.2 + 0.3 * D @ c + 0.1])


def plant_optimum(extra_curvature=0.0):
    return minimize(lambda c: plant(c, extra_curvature)[0], [0.0, 0.0], method="SLSQP", tol=1e-12,
                    constraints=[{"type": "ineq", "fun": lambda c: -plant(c, extra_curvature)[1]}]).x


def settings(secant):
    """Full steps, a trust radius of one box width, the model secant on or off."""
    return GMASettings(filter_gain=1.0, trust_region=TrustRegion(radius=1.0),
                       model_secant=ModelSecant() if secant else None)


@pytest.mark.parametrize("secant", [True, False])
def test_the_cost_keeps_the_plants_secant(secant):
    """DMA along d with a step of 0.5: the plant's secant puts the fixed point at c_opt - h/2 d (the truncation
    error h d^T H d / 2 of the cost with H = 2 I; the constraint is inactive there). The model secant corrects the
    constraints only, whose quotients are exact here (both linear): it leaves the fixed point where it is (the old
    default, which also corrected the cost, reached c_opt)."""
    h = 0.5
    gma = GMA(model(), settings(secant), DirectionalGradient(D, step=h, reuse=False))
    run_offline(gma, plant, 10)
    np.testing.assert_allclose(gma.c, plant_optimum() - h / 2 * D, atol=1e-6)
    assert np.linalg.norm(gma.c - plant_optimum()) > 0.1
    assert any("model secant" in n for n in gma.records[-1].notes) == secant


def ellipse_model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=-(u[0] + u[1]), constraints=2 * u[0] ** 2 + u[1] ** 2 - 4, outputs=u, lbu=-5,
                        ubu=5, u0=[0, 0], c_lb=[-2, -2], c_ub=[2.5, 2.5], name="ellipse")


def ellipse_plant(c):
    return -(c[0] + c[1]), np.array([2.5 * c[0] ** 2 + c[1] ** 2 - 4])


def on_plant_constraint(offset):
    """The point with c1 = 2.5 c0 + offset on the plant's constraint 2.5 c0^2 + c1^2 = 4 (c0 > 0)."""
    a, b, cc = 2.5 + 6.25, 5 * offset, offset ** 2 - 4
    c0 = (-b + np.sqrt(b * b - 4 * a * cc)) / (2 * a)
    return np.array([c0, 2.5 * c0 + offset])


@pytest.mark.parametrize("secant, offset", [(False, 0.3), (True, 0.1)])
def test_forward_differences_keep_only_the_curvature_mismatch(secant, offset):
    """Linear cost -(c0 + c1) (exact quotients), constraint Hessians diag(4, 2) in the model and diag(5, 2) in the
    plant. Forward differences of h = 0.4 measure grad g_p + h/2 diag(5, 2); with the model secant, grad g_p +
    h/2 diag(5 - 4, 2 - 2), the mismatch's error alone. The fixed point is on the plant's constraint where the
    measured Jacobian is parallel to (1, 1): 5 c0 + b0 = 2 c1 + b1, i.e. c1 = 2.5 c0 + (b0 - b1) / 2, an offset
    of 0.3 from the plant's secant and 0.1 with the model's (0 at the plant optimum)."""
    gma = GMA(ellipse_model(), settings(secant), FiniteDifferenceGradient(0.4))
    run_offline(gma, ellipse_plant, 20)
    assert gma.converged
    np.testing.assert_allclose(gma.c, on_plant_constraint(offset), atol=1e-6)


def test_model_points_are_solved_only_when_read_and_keep_the_plant_noise():
    calls = []

    def evaluate(c):
        calls.append(np.asarray(c).copy())
        return float(np.sum(c ** 2)), np.array([c[0]])

    p = ModelPoint(PlantPoint(np.array([1.0, 2.0]), 7.0, np.array([0.0]), 0.3, np.array([0.1])), evaluate)
    assert calls == [] and p.cost_std == 0.3 and p.constraints_std[0] == 0.1
    assert p.cost == 5.0 and p.constraints[0] == 1.0 and len(calls) == 1     # one solve for both values
    # least squares over past points reads only the points it selects: the far one is never solved
    c_k = np.zeros(2)
    near = [PlantPoint(np.array(x), 0.0, np.zeros(1), 0.01) for x in ([0.1, 0.0], [0.0, 0.1], [0.1, 0.1])]
    far = PlantPoint(np.array([2.5, 2.5]), 0.0, np.zeros(1), 0.01)
    est = LeastSquaresGradient(FiniteDifferenceGradient(0.1), radius=0.5)
    nominal = PlantPoint(c_k, 0.0, np.zeros(1), 0.01)
    plant_est = est.estimate(c_k, nominal, [], [far] + near)
    calls.clear()
    out, note = model_secant_estimate(est, plant_est, c_k, nominal, [], [far] + near,
                                      type("M", (), {"grad_phi": np.zeros(2), "jac_g": np.zeros((1, 2))})(),
                                      evaluate)
    assert len(calls) == 4 and not any(np.allclose(c, far.c) for c in calls)
    np.testing.assert_allclose(out.cost_std, plant_est.cost_std)
    assert note.startswith("model secant")


def test_a_model_that_cannot_realize_a_point_leaves_the_plant_estimate():
    fd = FiniteDifferenceGradient(0.1)
    c_k = np.zeros(2)
    nominal = PlantPoint(c_k, 1.0, np.zeros(1), 0.01)
    new = [PlantPoint(p, 1.0 + p[0], np.zeros(1), 0.01) for p in fd.plan(c_k, -np.ones(2), np.ones(2))]
    plant_est = fd.estimate(c_k, nominal, new)
    m = type("M", (), {"grad_phi": np.zeros(2), "jac_g": np.zeros((1, 2))})()
    out, note = model_secant_estimate(fd, plant_est, c_k, nominal, new, [], m,
                                      lambda c: (np.nan, np.full(1, np.nan)))
    assert out is plant_est and "not finite" in note


def test_bad_setting_is_named():
    with pytest.raises(ValueError, match=r"GMASettings.model_secant='yes': expected ModelSecant\(...\) or None"):
        GMASettings(model_secant="yes")


def curved_quotients():
    """Forward differences of 0.5 at 0 of a curved cost ``c^T c`` and constraint ``c_0^2`` (the model's gradients at
    0 are zero for both): ``(plant estimate, model_secant_estimate(...))``."""
    fd = FiniteDifferenceGradient(0.5)
    c_k = np.zeros(2)

    def values(c):
        return float(c @ c), np.array([c[0] ** 2])

    def pt(c):
        phi, g = values(c)
        return PlantPoint(np.asarray(c, float), phi, g, 0.01)
    new = [pt(p) for p in fd.plan(c_k, -np.ones(2), np.ones(2))]
    plant_est = fd.estimate(c_k, pt(c_k), new)
    m = type("M", (), {"grad_phi": np.zeros(2), "jac_g": np.zeros((1, 2))})()
    return plant_est, model_secant_estimate(fd, plant_est, c_k, pt(c_k), new, [], m, values)


def test_constraints_only_keeps_the_plant_cost_quotients():
    """The constraints' Jacobian gets the model's truncation correction, the cost gradient stays the plant's
    difference quotient (for a model whose cost curves unlike the plant's)."""
    plant_est, (out, note) = curved_quotients()
    np.testing.assert_allclose(plant_est.cost, [0.5, 0.5])                 # the secant, h f''/2
    np.testing.assert_allclose(plant_est.constraints, [[0.5, 0.0]])
    np.testing.assert_allclose(out.cost, plant_est.cost)
    np.testing.assert_allclose(out.constraints, [[0.0, 0.0]], atol=1e-12)
    assert "constraints only" in note


def curved_model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=-(u[0] + u[1]), constraints=u[0] ** 2 + u[1] ** 2 - 4, outputs=u, lbu=-5, ubu=5,
                        u0=[0, 0], c_lb=[-2, -2], c_ub=[1.7, 1.7], name="curved_constraint")


def curved_plant(c):
    g = c[0] ** 2 + c[1] ** 2 - 4 + 0.3 * c[0] + 0.2 * c[1] - 0.3
    return ExperimentResult("", -(c[0] + c[1]), [g], cost_std=1e-3, constraints_std=[1e-3])


@pytest.mark.parametrize("secant", [False, True])
def test_the_constraint_secant_keeps_each_step_on_the_plant_constraint(secant):
    """The constraint curves in the model as in the plant (a circle; the plant adds a linear term). From (1.2, 0)
    the perturbation of 0.5 in c[0] leaves the box and is taken backwards: the plant's backward quotient
    underestimates how fast the constraint grows forward, and the second iterate oversteps it by 0.135. With the
    model's secant on the constraint the quotient's error cancels, and every iterate lands on the plant constraint;
    both end at the same point."""
    gma = GMA(curved_model(), settings(secant), DirectionalGradient(np.eye(2), step=0.5, reuse=False), c0=[1.2, 0.0])
    hist = run_offline(gma, curved_plant, 8)
    g = [curved_plant(r.c_next).constraints[0] for r in hist.iterations]
    if secant:
        assert max(g) < 1e-6, g
        assert all("constraints only" in " ".join(r.notes) for r in hist.iterations)
    else:
        assert max(g) > 0.1, g
    np.testing.assert_allclose(gma.c, [1.3218, 1.3718], atol=1e-3)
