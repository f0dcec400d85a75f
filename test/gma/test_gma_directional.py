"""Directional modifier adaptation (kite_rto.gma.directional) against known answers.

Plants here are the model plus a mismatch that is affine in c, so finite differences are exact and every
expectation is a closed-form number: the DMA gradient equals the plant's along the privileged directions and
the model's across them, and GMA with DMA reaches the plant optimum when the mismatch lies in span(U).
"""
import casadi as ca
import numpy as np
import pytest
from scipy.optimize import minimize

from kite_rto.gma import (GMA, DirectionalGradient, GMASettings, ModelProblem, PlantPoint, TrustRegion,
                          lagrangian_gradient, privileged_directions, run_offline)


class Model:
    """What DirectionalGradient.estimate reads from a ModelRealization."""

    def __init__(self, grad_phi, jac_g):
        self.grad_phi, self.jac_g = np.asarray(grad_phi, float), np.asarray(jac_g, float)


def affine_plant(grad, jac, f0=1.0, g0=(-0.5,)):
    def at(c):
        c = np.asarray(c, float)
        return PlantPoint(c, f0 + grad @ c, np.asarray(g0) + jac @ c)
    return at


def test_privileged_directions_are_the_leading_singular_vectors_in_scaled_coordinates():
    A = np.array([[2.0, 0.0, 1.0], [0.0, 0.5, 0.0], [1.0, 0.0, 3.0]])     # d grad / d theta
    dev = np.array([0.1, 0.2, -0.3])
    w = np.array([1.0, 2.0, 0.5])
    pd = privileged_directions(lambda th: np.array([1.0, -2.0, 0.5]) + A @ th, np.zeros(3), dev, 2, scale=w)
    S = A * dev                                                           # forward differences are exact
    U, sv, _ = np.linalg.svd(w[:, None] * S)
    np.testing.assert_allclose(pd.singular_values, sv, rtol=1e-12)
    np.testing.assert_allclose(pd.sensitivity, S, atol=1e-12)
    for j in range(2):   # same direction up to sign, unit length in scaled coordinates
        assert abs(abs(pd.scaled[:, j] @ U[:, j]) - 1.0) < 1e-12
        np.testing.assert_allclose(pd.directions[:, j], w * pd.scaled[:, j])
    np.testing.assert_allclose(pd.scaled.T @ pd.scaled, np.eye(2), atol=1e-12)
    assert pd.captured == pytest.approx(np.sum(sv[:2] ** 2) / np.sum(sv ** 2))
    assert not pd.fixed.any()


def test_a_robustly_active_bound_gets_no_direction_and_a_fragile_one_does():
    A = np.array([[1.0, 0.5], [3.0, -2.0], [0.5, 4.0]])
    # c1 at its lower bound with gradient 10 (> 1 / margin 0.5 = 2x its largest change 1): robust;
    # c2 at its upper bound with gradient -1 (pushing, but its change 3 could flip it): fragile.
    g0 = np.array([10.0, -1.0, 0.2])
    pd = privileged_directions(lambda th: g0 + A @ th, np.zeros(2), [1.0, 1.0], 2, at_bound=[-1, 1, 0])
    assert pd.fixed.tolist() == [True, False, False]
    np.testing.assert_allclose(pd.directions[0], 0.0)
    _, sv, _ = np.linalg.svd(A[1:])
    np.testing.assert_allclose(pd.singular_values, sv, rtol=1e-12)
    with pytest.raises(ValueError, match=r"n_directions=3: expected an integer in \[1, 2\] \(2 setpoints not at"):
        privileged_directions(lambda th: g0 + A @ th, np.zeros(2), [1.0, 1.0], 3, at_bound=[-1, 1, 0])
    # a gradient pulling the setpoint off its bound never fixes it
    pd = privileged_directions(lambda th: -g0 + A @ th, np.zeros(2), [1.0, 1.0], 1, at_bound=[-1, 0, 0])
    assert not pd.fixed.any()


@pytest.mark.parametrize("bad, match", [
    ({"deviations": [0.1, 0.0]}, r"deviations=\[0.1, 0.0\]: expected 2 finite nonzero values"),
    ({"n_directions": 0}, r"n_directions=0: expected an integer in \[1, 2\]"),
    ({"at_bound": [2, 0]}, r"at_bound=\[2, 0\]: expected 2 values in -1, 0, \+1"),
    ({"scale": [1.0, -1.0]}, r"scale=\[1.0, -1.0\]: expected finite values > 0"),
    ({"robust_margin": 0.0}, r"robust_margin=0.0: expected a value in \(0, 1\]"),
])
def test_privileged_directions_reject_bad_arguments(bad, match):
    args = {"deviations": [0.1, 0.1], "n_directions": 1, "scale": None, "at_bound": None, "robust_margin": 0.5}
    args.update(bad)
    with pytest.raises(ValueError, match=match):
        privileged_directions(lambda th: np.array([1.0, 2.0]) + th, np.zeros(2), args.pop("deviations"),
                              args.pop("n_directions"), **args)


def test_estimate_is_the_plant_along_the_directions_and_the_model_across():
    model = Model([1.0, -2.0, 0.5], [[0.3, 0.1, -0.2]])
    U = np.array([[1.0, 0.0], [1.0, 1.0], [0.0, 2.0]])                   # not orthogonal, not unit
    b_true = np.array([0.7, -1.5])                                       # plant - model along U (cost)
    lam = np.linalg.pinv(U).T @ b_true                                   # in span(U)
    mu = np.linalg.pinv(U).T @ np.array([0.2, 0.4])
    plant = affine_plant(model.grad_phi + lam, model.jac_g + mu[None, :])
    est = DirectionalGradient(U, step=0.1)
    c_k, lb, ub = np.array([0.2, 0.3, 0.1]), np.zeros(3), np.ones(3)
    new = [plant(c) for c in est.plan(c_k, lb, ub, [])]
    got = est.estimate(c_k, plant(c_k), new, [], model=model)
    np.testing.assert_allclose(got.cost, model.grad_phi + lam, atol=1e-10)
    np.testing.assert_allclose(got.constraints, model.jac_g + mu[None, :], atol=1e-10)
    np.testing.assert_allclose(U.T @ got.cost, U.T @ (model.grad_phi + lam), atol=1e-10)
    assert got.quality > 0.2 and got.method == "directional (2 of 3)"
    # a mismatch orthogonal to span(U) is not seen: the estimate keeps the model's gradient there
    n = np.cross(U[:, 0], U[:, 1])
    hidden = affine_plant(model.grad_phi + 3.0 * n, model.jac_g)
    got = est.estimate(c_k, hidden(c_k), [hidden(c) for c in est.plan(c_k, lb, ub, [])], [], model=model)
    np.testing.assert_allclose(got.cost, model.grad_phi, atol=1e-10)


def test_plan_turns_and_clips_at_a_corner_and_fits_the_clipped_steps():
    U = np.array([[0.0, 0.0], [0.95, -0.3], [0.3, 0.95]])
    est = DirectionalGradient(U, step=0.5)
    c_k, lb, ub = np.zeros(3), np.zeros(3), np.ones(3)                  # the lower corner, as on the kite
    plan = est.plan(c_k, lb, ub, [])
    assert len(plan) == 2 and all(np.all((p >= lb) & (p <= ub)) for p in plan)
    np.testing.assert_allclose(plan[0], 0.5 * U[:, 0])                  # fits as it is
    np.testing.assert_allclose(plan[1], [0.0, 0.0, 0.475])              # -d clipped: keeps more of d than +d
    model = Model([0.5, 1.0, -1.0], np.zeros((1, 3)))
    lam = np.linalg.pinv(U).T @ np.array([-2.0, 1.0])
    plant = affine_plant(model.grad_phi + lam, np.zeros((1, 3)))
    got = est.estimate(c_k, plant(c_k), [plant(p) for p in plan], [], model=model)
    np.testing.assert_allclose(U.T @ got.cost, U.T @ plant(np.zeros(3)).c + U.T @ (model.grad_phi + lam),
                               atol=1e-10)
    # and without any room along a direction the estimate says so instead of inventing a gradient
    flat = [PlantPoint(c_k.copy(), 1.0, np.zeros(1)), PlantPoint(c_k.copy(), 1.0, np.zeros(1))]
    bad = est.estimate(c_k, flat[0], flat, [], model=model)
    assert bad.quality == 0.0 and np.isnan(bad.cost).all() and "do not span" in bad.notes


def test_reuse_takes_past_points_instead_of_perturbations():
    model = Model([1.0, 0.0], np.zeros((0, 2)))
    U = np.array([[1.0], [1.0]])
    lam = np.array([0.5, 0.5]) * 0.8                                    # along U
    def plant(c):
        c = np.asarray(c, float)
        return PlantPoint(c, (model.grad_phi + lam) @ c, np.zeros(0))
    est = DirectionalGradient(U, step=0.2, reuse=True)
    c_k = np.array([0.5, 0.5])
    assert len(est.plan(c_k, np.zeros(2), np.ones(2), [])) == 1           # nothing to reuse yet
    past = [plant([0.3, 0.35]), plant([5.0, 5.0])]                        # the second is out of reach
    assert est.plan(c_k, np.zeros(2), np.ones(2), past) == []
    got = est.estimate(c_k, plant(c_k), [], past, model=model)
    np.testing.assert_allclose(got.cost, model.grad_phi + lam, atol=1e-10)
    assert "1 past points" in got.notes
    assert DirectionalGradient(U, step=0.2, reuse=False).plan(c_k, np.zeros(2), np.ones(2), past) != []


@pytest.mark.parametrize("bad, match", [
    ({"directions": np.ones((2, 3))}, r"expected a finite \(n_c, r\) array with 1 <= r <= n_c"),
    ({"directions": [[1.0, 2.0], [2.0, 4.0]]}, r"the 2 columns are linearly dependent"),
    ({"step": -0.1}, r"step=-0.1: expected finite values > 0"),
    ({"rcond_min": 0.0}, r"rcond_min=0.0: expected a value in \(0, 1\]"),
    ({"window": 0}, r"window=0: expected an integer >= 1 or None"),
])
def test_directional_gradient_rejects_bad_arguments(bad, match):
    args = {"directions": [[1.0], [0.0]], **bad}
    with pytest.raises(ValueError, match=match):
        DirectionalGradient(**args)


def quad_model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - 0.5) ** 2 + (u[1] - 1.5) ** 2, constraints=0.9 * u[0] + u[1] - 2.2,
                        outputs=u, lbu=-5, ubu=5, u0=[0, 0], c_lb=[-2, -2], c_ub=[3, 3], name="quad_dma")


def test_lagrangian_gradient_of_a_model_with_known_derivatives():
    pr = quad_model()
    c = np.array([0.2, 0.7])
    np.testing.assert_allclose(lagrangian_gradient(pr, c), 2 * (c - [0.5, 1.5]), atol=1e-7)
    np.testing.assert_allclose(lagrangian_gradient(pr, c, [2.0]), 2 * (c - [0.5, 1.5]) + 2.0 * np.array([0.9, 1.0]),
                               atol=1e-6)
    with pytest.raises(ValueError, match="c has 3 entries and nu 1, expected n_c=2 and n_g=1"):
        lagrangian_gradient(pr, [0.0, 0.0, 0.0], [0.0])


@pytest.mark.parametrize("reuse", [False, True])
def test_gma_with_dma_reaches_the_plant_optimum_when_the_mismatch_lies_in_span_u(reuse):
    d = np.array([1.0, -0.5])
    a, b = 0.8, 0.3             # plant = model + a d^T c (cost) + b d^T c + 0.1 (constraint)
    def plant(c):
        c = np.asarray(c, float)
        phi = (c[0] - 0.5) ** 2 + (c[1] - 1.5) ** 2 + a * d @ c
        return phi, np.array([0.9 * c[0] + c[1] - 2.2 + b * d @ c + 0.1])
    ref = minimize(lambda c: plant(c)[0], [0.0, 0.0], method="SLSQP",
                   constraints=[{"type": "ineq", "fun": lambda c: -plant(c)[1]}])
    # forward differences of step h along d carry the bias h d^T H d / 2 (H = 2 I): the fixed point moves by
    # -h/2 d, 5e-5 here (0.025 d with h = 0.05)
    h = 1e-4
    gma = GMA(quad_model(), GMASettings(filter_gain=1.0, trust_region=TrustRegion(radius=1.0)),
              DirectionalGradient(d, step=h, reuse=reuse))
    run_offline(gma, plant, 12)
    n_exp = len(gma.history.experiments)
    assert gma.records[-1].gradient_method == "directional (1 of 2)"
    if not reuse:
        assert n_exp == 2 * 12                                         # nominal + 1 direction per iteration
        np.testing.assert_allclose(gma.c, ref.x - h / 2 * d, atol=1e-6)
    else:   # past iterates stand in for perturbations: fewer experiments, a first-order fit across them
        assert n_exp < 2 * 12
        np.testing.assert_allclose(gma.c, ref.x, atol=1e-3)
