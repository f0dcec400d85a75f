"""Plant-gradient strategies on known functions."""
import numpy as np
import pytest

from kite_rto.gma import FiniteDifferenceGradient, LeastSquaresGradient, PlantPoint

LB, UB = np.array([-5.0, -5.0]), np.array([5.0, 5.0])


def f(c):
    c = np.asarray(c, float)
    return c[0] ** 2 + 3 * c[0] * c[1] - c[1], np.array([c[0] - 2 * c[1], c[1] ** 2])


def grad(c):
    return np.array([2 * c[0] + 3 * c[1], 3 * c[0] - 1]), np.array([[1.0, -2.0], [0.0, 2 * c[1]]])


def point(c, std=None):
    cost, g = f(c)
    return PlantPoint(np.asarray(c, float), cost, g, std, None)


def run(est, c, past=()):
    plan = est.plan(c, LB, UB, past)
    return plan, est.estimate(c, point(c, 0.01), [point(p, 0.01) for p in plan], past)


def test_central_differences_exact_for_quadratics():
    c = np.array([0.3, -0.7])
    plan, est = run(FiniteDifferenceGradient([1e-2, 2e-2], "central"), c)
    assert len(plan) == 4
    g, J = grad(c)
    np.testing.assert_allclose(est.cost, g, atol=1e-10)
    np.testing.assert_allclose(est.constraints, J, atol=1e-10)
    assert est.quality == 1.0
    np.testing.assert_allclose(est.cost_std, [0.01 * np.sqrt(2) / 0.02, 0.01 * np.sqrt(2) / 0.04])


def test_forward_differences_step_backwards_at_the_box_edge():
    c = np.array([5.0, 0.0])
    plan, est = run(FiniteDifferenceGradient(1e-6), c)
    assert len(plan) == 2 and plan[0][0] == pytest.approx(5.0 - 1e-6)
    np.testing.assert_allclose(est.cost, grad(c)[0], atol=1e-4)


def test_step_from_noise_rule():
    fd = FiniteDifferenceGradient.from_noise(1e-4, [1.0, 4.0])
    np.testing.assert_allclose(fd.step, [2e-2, 1e-2])  # h = 2 sqrt(sigma / |f''|)
    fd = FiniteDifferenceGradient.from_noise(1e-4, [1.0, 4.0], "central", third_derivative=0.3)
    np.testing.assert_allclose(fd.step, (3e-4 / 0.3) ** (1 / 3))


def test_least_squares_uses_well_conditioned_past_points():
    c = np.array([0.3, -0.7])
    est = LeastSquaresGradient(FiniteDifferenceGradient(0.01), radius=0.1)
    past = [point(c + d) for d in ([0.01, 0.0], [0.0, 0.01], [-0.01, 0.01])]
    plan, g = run(est, c, past)
    assert plan == []
    assert g.method.startswith("least-squares") and g.quality > 0.1
    np.testing.assert_allclose(g.cost, grad(c)[0], atol=0.05)
    np.testing.assert_allclose(g.constraints, grad(c)[1], atol=0.05)


def test_least_squares_falls_back_when_ill_conditioned_or_too_far():
    c = np.array([0.3, -0.7])
    est = LeastSquaresGradient(FiniteDifferenceGradient(0.01), radius=0.1)
    collinear = [point(c + d) for d in ([0.01, 0.01], [0.02, 0.02], [-0.01, -0.01])]
    plan, g = run(est, c, collinear)
    assert len(plan) == 2 and "fallback" in g.notes
    far = [point(c + d) for d in ([1.0, 0.0], [0.0, 1.0])]
    plan, g = run(est, c, far)
    assert len(plan) == 2 and g.method.startswith("finite-difference")
