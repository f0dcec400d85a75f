"""Which side a perturbation is flown on: the side the last step went (``DirectionalGradient(lead=True)``) and the
clipped forward step near the upper bound (``keep_side``), issue #14 item 3.

A one-sided quotient is a secant. Taken on the side the iterate moves, it spans the region the next step enters;
taken on the other side it is extrapolated across ``c_k`` with the plant's curvature. Closed forms: the points
planned for given last steps, and GMA handing its last step to the estimator on a one-setpoint problem whose plant
cost ``3 (c - 0.4)^2`` differs from the model's ``(c - 0.1)^2``.
"""
import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import GMA, DirectionalGradient, GMASettings, ModelProblem, run_offline

LB, UB = np.zeros(2), np.ones(2)


def test_each_direction_is_perturbed_on_the_side_of_the_last_step():
    est = DirectionalGradient(np.eye(2), step=0.3, lead=True)
    c = np.array([0.5, 0.5])
    plan = est.plan_iteration(c, LB, UB, [], 1, toward=np.array([0.2, -0.1]))
    np.testing.assert_allclose(plan, [[0.8, 0.5], [0.5, 0.2]])
    # without lead (or without a last step) both go forward, as before
    for other in (DirectionalGradient(np.eye(2), step=0.3).plan_iteration(c, LB, UB, [], 1, toward=[0.2, -0.1]),
                  est.plan_iteration(c, LB, UB, [], 1), est.plan_iteration(c, LB, UB, [], 1, toward=[0.0, 0.0])):
        np.testing.assert_allclose(other, [[0.8, 0.5], [0.5, 0.8]])


def test_the_side_of_the_step_is_kept_while_half_the_step_fits_in_the_box():
    est = DirectionalGradient(np.eye(2), step=0.3, lead=True)
    up = np.array([0.1, 0.1])
    # 0.2 of 0.3 left towards the upper bound: clipped there (the default would step back the full 0.3)
    np.testing.assert_allclose(est.plan_iteration(np.array([0.8, 0.5]), LB, UB, [], 1, toward=up)[0], [1.0, 0.5])
    assert DirectionalGradient(np.eye(2), step=0.3).plan(np.array([0.8, 0.5]), LB, UB)[0] == pytest.approx([0.5, 0.5])
    # 0.1 of 0.3 left: less than half of the step, so the default rule (backwards, whole)
    np.testing.assert_allclose(est.plan_iteration(np.array([0.9, 0.5]), LB, UB, [], 1, toward=up)[0], [0.6, 0.5])


@pytest.mark.parametrize("bad, match", [
    ({"lead": 1}, r"lead=1: expected True or False"),
    ({"lead": True, "alternate": True}, r"lead=True with alternate=True"),
])
def test_lead_rejects_bad_arguments(bad, match):
    with pytest.raises(ValueError, match=match):
        DirectionalGradient(np.eye(2), **bad)


def one_setpoint_model():
    u = ca.SX.sym("u", 1)
    return ModelProblem(u=u, cost=(u[0] - 0.1) ** 2, constraints=ca.SX(0, 1), outputs=u, lbu=[0], ubu=[1],
                        u0=[0.9], c_lb=[0], c_ub=[1], name="lead_1d")


def plant(c):
    return 3.0 * (float(c[0]) - 0.4) ** 2, np.zeros(0)


@pytest.mark.parametrize("lead, secant", [(True, 0.0), (False, 1.2)])
def test_gma_hands_its_last_step_to_the_estimator(lead, secant):
    """From c0 = 0.9 the forward step leaves the box, so iteration 0 measures backwards over [0.7, 0.9]: slope 2.4
    against the model's 1.6, and the step goes down to the trust region's edge, c1 = 0.5. There the plant's slope is
    0.6: with ``lead`` iteration 1 measures over [0.3, 0.5] (secant 0), the side the step went; without, over
    [0.5, 0.7] (secant 1.2)."""
    gma = GMA(one_setpoint_model(), GMASettings(filter_gain=1.0, trust_radius=0.4, trust_adapt=False),
              DirectionalGradient([[1.0]], step=0.2, reuse=False, lead=lead), c0=[0.9])
    run_offline(gma, plant, 2)
    r0, r1 = gma.records
    assert r0.grad_cost[0] == pytest.approx(2.4)
    assert r1.c_k[0] == pytest.approx(0.5)
    assert r1.grad_cost[0] == pytest.approx(secant, abs=1e-6)
    flown = sorted(float(q.c[0]) for q, _ in gma.history.experiments if q.iteration == 1)
    np.testing.assert_allclose(flown, [0.3, 0.5] if lead else [0.5, 0.7], atol=1e-6)


def test_keep_side_flies_the_clipped_forward_step_while_enough_of_it_fits():
    """``keep_side`` 0.5: at 0.8 with step 0.3 the forward step keeps 0.2 of 0.3 and is flown clipped to the upper
    bound; at 0.9 it keeps 0.1 of 0.3 and the full backward step is flown, as with the default 1."""
    est = DirectionalGradient(np.eye(2), step=0.3, keep_side=0.5)
    default = DirectionalGradient(np.eye(2), step=0.3)
    np.testing.assert_allclose(est.plan(np.array([0.8, 0.5]), LB, UB), [[1.0, 0.5], [0.8, 0.8]])
    np.testing.assert_allclose(default.plan(np.array([0.8, 0.5]), LB, UB), [[0.5, 0.5], [0.8, 0.8]])
    for e in (est, default):
        np.testing.assert_allclose(e.plan(np.array([0.9, 0.5]), LB, UB)[0], [0.6, 0.5])
    # the option survives a restored direction (GMA's structure check appends columns)
    assert est.with_directions(np.zeros((2, 0))).keep_side == 0.5


@pytest.mark.parametrize("keep, flown, secant", [(1.0, [0.5, 0.8], 1.5), (0.5, [0.8, 1.0], 3.0)])
def test_keep_side_measures_ahead_of_an_iterate_near_its_upper_bound(keep, flown, secant):
    """Model ``(c - 0.1)^2``, plant ``3 (c - 0.4)^2`` on [0, 1] from ``c0 = 0.8``, step 0.3: the forward step
    keeps 0.2 of 0.3. With the default it is flown backwards, over [0.5, 0.8] (secant 1.5, the plant's slope at
    0.65); with ``keep_side`` 0.5 forward to the bound, over [0.8, 1.0] (secant 3.0, the slope at 0.9)."""
    gma = GMA(one_setpoint_model(), GMASettings(filter_gain=1.0, trust_radius=0.4, trust_adapt=False),
              DirectionalGradient([[1.0]], step=0.3, reuse=False, keep_side=keep), c0=[0.8])
    run_offline(gma, plant, 1)
    assert gma.records[0].grad_cost[0] == pytest.approx(secant, abs=1e-6)
    got = sorted(float(q.c[0]) for q, _ in gma.history.experiments if q.iteration == 0)
    np.testing.assert_allclose(got, flown, atol=1e-6)


@pytest.mark.parametrize("bad", [0, 0.0, 1.5, -0.2, True, "half"])
def test_keep_side_rejects_values_outside_0_1(bad):
    with pytest.raises(ValueError, match=r"keep_side=.*expected a number in \(0, 1\]"):
        DirectionalGradient(np.eye(2), keep_side=bad)


def test_the_kite_setting_fd_keep_reaches_the_estimator_and_rejects_bad_values():
    from kite_rto.rto.settings import KiteRTOSettings
    est = KiteRTOSettings(fd_keep=0.5).gradient_estimator(np.eye(3))
    assert isinstance(est, DirectionalGradient) and est.keep_side == 0.5
    assert KiteRTOSettings().gradient_estimator(np.eye(3)).keep_side == 1.0
    with pytest.raises(ValueError, match=r"fd_keep = 0: expected a number in \(0, 1\]"):
        KiteRTOSettings(fd_keep=0)
