"""Model gradients at the edge of the setpoint box.

Model: phi = (u1 - 0.5)^2 + (u2 - 1.5)^2, g = u1 + u2 - 10 <= 0 (never active), y = u, and the bounds of u are
the setpoint box [0, 2]^2. At c = (2, 1) the input u1 = c1 sits at its bound; the bound holds because y(u) = c
does, so the setpoint moves it: d phi_hat / d c = (2 (c1 - 0.5), 2 (c2 - 1.5)) = (3, -1).

Plant: phi_p = (c1 - 2.2)^2 + (c2 - 1)^2, g_p = c1 + c2 - 10; its optimum in the box is (2, 1), on the edge.
With exact plant gradients, filter gain 1 and no trust region, MA steps from the model optimum (0.5, 1.5) to
(2, 1) and stays there: the cost modifier is lam = grad phi_p - grad phi_hat = (-5, 1) everywhere, and the
modified optimum u1 = 0.5 + 2.5 clips to 2. A model gradient halved at the edge, (1.5, -1), gives lam_1 = -3.5
there and a step back to u1 = 1.45: the iterates oscillate between 1.45 and 2.
"""
import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import GMA, GMASettings, GradientEstimate, GradientEstimator, ModelProblem, run_offline


def edge_problem():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - .5) ** 2 + (u[1] - 1.5) ** 2, constraints=u[0] + u[1] - 10, outputs=u,
                        lbu=[0, 0], ubu=[2, 2], u0=[.5, 1.5], c_lb=[0, 0], c_ub=[2, 2], name="edge")


def plant(c):
    return (c[0] - 2.2) ** 2 + (c[1] - 1) ** 2, np.array([c[0] + c[1] - 10])


class ExactPlantGradient(GradientEstimator):
    """The plant's gradients in closed form: no perturbation experiments."""

    def plan(self, c_k, lb, ub, past=()):
        return []

    def estimate(self, c_k, nominal, new, past=(), model=None):
        return GradientEstimate(np.array([2 * (c_k[0] - 2.2), 2 * (c_k[1] - 1)]), np.array([[1.0, 1.0]]), 1.0,
                                None, "exact")


@pytest.mark.parametrize("c, grad", [([2.0, 1.0], [3.0, -1.0]), ([0.0, 1.0], [-1.0, -1.0]),
                                     ([2.0, 2.0], [3.0, 1.0]), ([1.0, 1.0], [1.0, -1.0])])
def test_consistent_model_gradient_is_exact_on_the_box_edge(c, grad):
    model = GMA(edge_problem()).linearize(c)
    assert model.success
    np.testing.assert_allclose(model.grad_phi, grad, atol=1e-9)
    np.testing.assert_allclose(model.jac_g, [[1.0, 1.0]], atol=1e-9)


def test_the_reproduction_and_the_right_inverse_on_the_edge():
    """The original report's lines verbatim (default name, default settings): [3, -1], not [1.5, -1]. At u = (2, 1) the
    bound row of u1 equals the first row of dy: it is left out, and R is the identity (dy R = I exactly)."""
    u = ca.SX.sym("u", 2)
    P = ModelProblem(u=u, cost=(u[0] - .5) ** 2 + (u[1] - 1.5) ** 2, constraints=u[0] + u[1] - 10, outputs=u,
                     lbu=[0, 0], ubu=[2, 2], u0=[.5, 1.5], c_lb=[0, 0], c_ub=[2, 2])
    np.testing.assert_allclose(GMA(P).linearize([2., 1.]).grad_phi, [3.0, -1.0], atol=1e-9)
    np.testing.assert_allclose(P.tangent_right_inverse([2.0, 1.0]), np.eye(2), atol=1e-12)
    np.testing.assert_allclose(P.tangent_right_inverse([2.0, 2.0]), np.eye(2), atol=1e-12)   # a corner


def test_right_inverse_still_holds_inputs_that_y_does_not_fix():
    """u3 is not a setpoint and rests at its bound: the setpoints never move it (R[2] = 0), while u1 at its
    bound, which y(u) = c fixes, moves with c1."""
    u = ca.SX.sym("u", 3)
    pr = ModelProblem(u=u, cost=(u[0] - .5) ** 2 + (u[1] - 1.5) ** 2 + (u[2] - 5) ** 2 + u[0] * u[2],
                      constraints=None, outputs=u[:2], lbu=[0, 0, 0], ubu=[2, 2, 1], u0=[.5, 1.5, 1],
                      c_lb=[0, 0], c_ub=[2, 2])
    R = pr.tangent_right_inverse([2.0, 1.0, 1.0])
    np.testing.assert_allclose(pr.jacobians([2.0, 1.0, 1.0])["dy"] @ R, np.eye(2), atol=1e-12)
    np.testing.assert_array_equal(R[2], [0.0, 0.0])


def test_full_steps_reach_an_optimum_on_the_edge_in_two_iterations():
    gma = GMA(edge_problem(), GMASettings(filter_gain=1.0, trust_region=None),
              ExactPlantGradient())
    np.testing.assert_allclose(gma.c, [0.5, 1.5], atol=1e-6)          # started at the model optimum
    run_offline(gma, plant, 4)
    iterates = [r.c_next for r in gma.records]
    np.testing.assert_allclose(iterates, [[2.0, 1.0]] * 4, atol=1e-6)
    assert [r.converged for r in gma.records] == [False, True, True, True]
