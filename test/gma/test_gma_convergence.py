"""GMA converges to the plant's KKT point: (a) y(u) = u with a different active set, (b) n_u > n_c.

Problems (described in docs/gma.md):
(a) plant  phi_p = (c1-1)^2 + 2 (c2-1)^2,  g_p = c1 + c2 - 1.5 <= 0   -> c* = (2/3, 5/6), nu = 2/3 (active)
    model  phi = (u1-0.5)^2 + (u2-1.5)^2,  g = 0.9 u1 + u2 - 2.2 <= 0, y = u -> optimum (0.5, 1.5), inactive
(b) plant  phi_p = (c1-2)^2 + (c2-2)^2,  g_p = [c1 + 2 c2 - 3, c1 - 2.5] <= 0 -> c* = (1.4, 0.8), nu = (1.2, 0)
    model  n_u = 4, y = (u1 + 0.5 u3, u2 + 0.3 u4 + 0.1 u3^2), other cost and constraints.
"""
import casadi as ca
import numpy as np
import pytest
from scipy.optimize import minimize

from kite_rto.gma import (GMA, FiniteDifferenceGradient, GMASettings, GradientEstimate, GradientEstimator,
                          ModelProblem, ModelSettings, run_offline)


class ExactGradient(GradientEstimator):
    """Noise-free plant gradients from known functions: no perturbation experiments."""

    def __init__(self, grad_cost, jac_constraints):
        self.grad_cost, self.jac_constraints = grad_cost, jac_constraints

    def plan(self, c_k, lb, ub, past=()):
        return []

    def estimate(self, c_k, nominal, new, past=(), model=None):
        return GradientEstimate(self.grad_cost(c_k), self.jac_constraints(c_k), 1.0, None, "exact")


def problem_a():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - 0.5) ** 2 + (u[1] - 1.5) ** 2, constraints=0.9 * u[0] + u[1] - 2.2,
                        outputs=u, lbu=-5, ubu=5, u0=[0, 0], c_lb=[-2, -2], c_ub=[3, 3], name="quad_a")


def plant_a(c):
    return (c[0] - 1) ** 2 + 2 * (c[1] - 1) ** 2, np.array([c[0] + c[1] - 1.5])


def problem_b():
    u = ca.SX.sym("u", 4)
    y = ca.vertcat(u[0] + 0.5 * u[2], u[1] + 0.3 * u[3] + 0.1 * u[2] ** 2)
    cost = (u[0] - 1) ** 2 + (u[1] - 1) ** 2 + u[2] ** 2 + 0.5 * u[3] ** 2 + 0.2 * u[0] * u[1]
    g = ca.vertcat(u[0] + 2 * u[1] + 0.2 * u[3] - 2.5, u[0] + 0.5 * u[2] - 2.4)
    return ModelProblem(u=u, cost=cost, constraints=g, outputs=y, lbu=-4, ubu=4, u0=np.zeros(4),
                        c_lb=[-1, -1], c_ub=[3, 3], name="controlled_b")


def plant_b(c):
    return (c[0] - 2) ** 2 + (c[1] - 2) ** 2, np.array([c[0] + 2 * c[1] - 3, c[0] - 2.5])


def kkt_multipliers(grad_f, jac_g, active):
    """Least-squares multipliers of the active constraints and the stationarity residual."""
    A = jac_g[active].T
    nu, *_ = np.linalg.lstsq(A, -grad_f, rcond=None)
    return nu, np.linalg.norm(grad_f + A @ nu)


def test_a_converges_to_plant_kkt_point_with_fd_gradients():
    prob = problem_a()
    gma = GMA(prob, GMASettings(filter_gain=0.8), FiniteDifferenceGradient(1e-5, "central"))
    np.testing.assert_allclose(gma.c, [0.5, 1.5], atol=1e-6)  # starts at the model optimum
    hist = run_offline(gma, plant_a, 40, stop_on_convergence=True)
    c = gma.c
    assert gma.converged, [r.decision for r in hist.iterations]
    np.testing.assert_allclose(c, [2 / 3, 5 / 6], atol=2e-3)
    _, g = plant_a(c)
    assert abs(g[0]) < 1e-3  # same active set as the plant optimum
    nu, res = kkt_multipliers(np.array([2 * (c[0] - 1), 4 * (c[1] - 1)]), np.array([[1.0, 1.0]]), [0])
    assert res < 5e-3 and nu[0] == pytest.approx(2 / 3, abs=5e-3)


def test_standard_ma_iteration_matches_hand_computed_step():
    """With y(u) = u one GMA iteration is the standard MA step of SPEC §5 (no filter, no trust region)."""
    prob = problem_a()
    gp = lambda c: np.array([2 * (c[0] - 1), 4 * (c[1] - 1)])
    jp = lambda c: np.array([[1.0, 1.0]])
    gma = GMA(prob, GMASettings(filter_gain=1.0, trust_region=None), ExactGradient(gp, jp), c0=[0.2, 0.4])
    rec = run_offline(gma, plant_a, 1).iterations[0]
    ck = np.array([0.2, 0.4])
    eps = plant_a(ck)[1] - (0.9 * ck[0] + ck[1] - 2.2)
    lam = gp(ck) - np.array([2 * (ck[0] - 0.5), 2 * (ck[1] - 1.5)])
    mu = jp(ck) - np.array([[0.9, 1.0]])
    np.testing.assert_allclose(rec.eps, eps, atol=1e-9)
    np.testing.assert_allclose(rec.lam, lam, atol=1e-6)
    np.testing.assert_allclose(rec.mu, mu, atol=1e-6)
    ma = minimize(lambda u: (u[0] - 0.5) ** 2 + (u[1] - 1.5) ** 2 + lam @ (u - ck), ck, method="SLSQP",
                  constraints=[{"type": "ineq",
                                "fun": lambda u: -(0.9 * u[0] + u[1] - 2.2 + eps[0] + mu[0] @ (u - ck))}],
                  options={"ftol": 1e-12})
    np.testing.assert_allclose(rec.c_star, ma.x, atol=1e-6)
    np.testing.assert_allclose(rec.c_next, ma.x, atol=1e-6)


def test_realization_gradient_from_multipliers_matches_finite_differences():
    gma = GMA(problem_b(), c0=[1.0, 1.0])
    c, h = np.array([1.2, 0.7]), 1e-5
    base = gma.realize(c)
    assert base.success
    fd = [(gma.realize(c + h * e).phi - gma.realize(c - h * e).phi) / (2 * h) for e in np.eye(2)]
    np.testing.assert_allclose(base.grad_phi, fd, atol=1e-5)
    jac = np.array([(gma.realize(c + h * e).g - gma.realize(c - h * e).g) / (2 * h) for e in np.eye(2)]).T
    np.testing.assert_allclose(base.jac_g, jac, atol=1e-4)


def test_b_controlled_plant_more_model_inputs_than_setpoints():
    prob = problem_b()
    assert (prob.n_u, prob.n_c, prob.n_g) == (4, 2, 2)
    gma = GMA(prob, GMASettings(filter_gain=0.7), FiniteDifferenceGradient([1e-5, 1e-5], "central"))
    c0 = gma.c
    hist = run_offline(gma, plant_b, 40, stop_on_convergence=True)
    assert gma.converged
    assert np.linalg.norm(c0 - [1.4, 0.8]) > 0.1  # the model alone is wrong
    np.testing.assert_allclose(gma.c, [1.4, 0.8], atol=2e-3)
    _, g = plant_b(gma.c)
    assert abs(g[0]) < 1e-3 and g[1] < -0.5  # active set {g1}
    nu, res = kkt_multipliers(2 * (gma.c - 2), np.array([[1.0, 2.0], [1.0, 0.0]]), [0])
    assert res < 5e-3 and nu[0] == pytest.approx(1.2, abs=5e-3)
    assert all(r.model_status == "Solve_Succeeded" for r in hist.iterations)


def test_b_with_exact_gradients_and_defaults():
    """Default settings (filter 0.5, trust region 0.25) also converge, here with exact gradients."""
    gp = lambda c: 2 * (np.asarray(c) - 2)
    jp = lambda c: np.array([[1.0, 2.0], [1.0, 0.0]])
    gma = GMA(problem_b(), gradient=ExactGradient(gp, jp))
    run_offline(gma, plant_b, 60, stop_on_convergence=True)
    assert gma.converged
    np.testing.assert_allclose(gma.c, [1.4, 0.8], atol=2e-3)


def test_b_with_past_operating_points_needs_fewer_experiments():
    from kite_rto.gma import LeastSquaresGradient
    fd = FiniteDifferenceGradient([1e-4, 1e-4], "forward")
    gma = GMA(problem_b(), GMASettings(filter_gain=0.7), LeastSquaresGradient(fd, radius=0.5, rcond_min=0.05))
    hist = run_offline(gma, plant_b, 60, stop_on_convergence=True)
    assert gma.converged
    np.testing.assert_allclose(gma.c, [1.4, 0.8], atol=5e-3)
    methods = [r.gradient_method for r in hist.iterations]
    assert any(m.startswith("least-squares") for m in methods)
    assert len(hist.experiments) < 3 * len(hist.iterations)  # fewer than nominal + 2 FD per iteration


def test_b_literal_spec_realization_point_misses_the_constraint():
    """Documented limitation: with ``ModelSettings(point="realization")`` the modified problem uses model inputs that
    y(u) does not fix (u4 enters g1) differently from u_hat(c_k); its fixed point violates the plant
    constraint. The default 'consistent' point (tests above) reaches the plant KKT point."""
    gma = GMA(problem_b(), GMASettings(filter_gain=0.7, model=ModelSettings(point="realization")),
              FiniteDifferenceGradient([1e-5, 1e-5], "central"))
    run_offline(gma, plant_b, 40, stop_on_convergence=True)
    assert gma.converged
    assert plant_b(gma.c)[1][0] > 0.1
