"""Alternating one-sided differences (``alternate`` of FiniteDifferenceGradient and DirectionalGradient): in odd
iterations the perturbations go backwards, so a modifier filter that averages the gradients of an iterate that stays
put averages a forward and a backward quotient, whose truncation errors ``+-h f''/2`` cancel.

Closed form: model ``phi = (u1 - 0.5)^2 + (u2 - 1.5)^2``, plant ``phi_p = (c1 - 1)^2 + 2 (c2 - 1)^2`` without noise,
steps ``h = 0.5``. The forward quotient is ``f'(c) + h f''/2``; GMA with forward differences therefore stops where
the plant's secant vanishes, ``c = 1 - h/2 = (0.75, 0.75)``, a quarter from the plant optimum ``(1, 1)``."""
import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import (GMA, DirectionalGradient, ExperimentResult, FiniteDifferenceGradient, GMASettings,
                          LeastSquaresGradient, ModelProblem, run_offline)

H = 0.5
SECANT_POINT = np.array([1 - H / 2, 1 - H / 2])
OPTIMUM = np.array([1.0, 1.0])


def model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - 0.5) ** 2 + (u[1] - 1.5) ** 2, constraints=None,
                        outputs=u, lbu=-5, ubu=5, u0=[0, 0], c_lb=[-2, -2], c_ub=[3, 3], name="alternate")


def plant(c):
    return ExperimentResult("", (c[0] - 1) ** 2 + 2 * (c[1] - 1) ** 2, [], cost_std=1e-3, constraints_std=[])


SETTINGS = {"noise-matched": dict(modifier_drift=0.5), "fixed 0.5": dict(modifier_filter=0.5)}


def tail(estimator, filt, n=30):
    gma = GMA(model(), GMASettings(filter_gain=1.0, trust_radius=0.3, trust_radius_min=1e-3, **SETTINGS[filt]),
              estimator)
    hist = run_offline(gma, plant, n)
    return np.array([r.c_next for r in hist.iterations[-10:]]), hist


ESTIMATORS = {
    "forward": lambda alt: FiniteDifferenceGradient(H, alternate=alt),
    "directional": lambda alt: DirectionalGradient(np.eye(2), step=H, reuse=False, alternate=alt),
}


@pytest.mark.parametrize("filt", sorted(SETTINGS))
@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_alternating_steps_cancel_the_truncation_error(name, filt):
    """Off: the iterates stand at the secant's zero (0.75, 0.75). On: their mean is within 0.02 of (1, 1)."""
    off, _ = tail(ESTIMATORS[name](False), filt)
    np.testing.assert_allclose(off, np.broadcast_to(SECANT_POINT, off.shape), atol=1e-3)
    on, hist = tail(ESTIMATORS[name](True), filt)
    assert np.max(np.abs(on.mean(axis=0) - OPTIMUM)) < 0.02, on.mean(axis=0)
    assert np.max(np.ptp(on, axis=0)) < 0.05          # a small 2-cycle around it, not a wander
    # the perturbations really change side: iteration 1 steps back, iteration 2 forward again
    by_k = {}
    for q, _ in hist.experiments:
        by_k.setdefault(q.iteration, []).append(np.asarray(q.c))
    for k in (1, 2, 11):
        nominal, *pert = by_k[k]
        sign = -1.0 if k % 2 else 1.0
        np.testing.assert_allclose(np.array(pert) - nominal, sign * H * np.eye(2), atol=1e-12)


def test_a_step_that_would_leave_the_box_goes_the_other_way():
    lb, ub = np.array([-2.0, -2.0]), np.array([3.0, 3.0])
    c = np.array([-1.8, 2.8])                 # backwards leaves the box in c1, forwards in c2
    for est in (FiniteDifferenceGradient(H, alternate=True), DirectionalGradient(np.eye(2), H, alternate=True)):
        np.testing.assert_allclose(est.plan_iteration(c, lb, ub, [], 1), [[-1.3, 2.8], [-1.8, 2.3]])
        np.testing.assert_allclose(est.plan_iteration(c, lb, ub, [], 0), [[-1.3, 2.8], [-1.8, 2.3]])
    # without alternate every iteration plans as plan()
    fd = FiniteDifferenceGradient(H)
    np.testing.assert_allclose(fd.plan_iteration(np.zeros(2), lb, ub, [], 1), fd.plan(np.zeros(2), lb, ub))


def test_directional_steps_keep_their_side_despite_rounding():
    """Both signs of a full step inside the box keep the whole direction; which one is taken must not depend on
    rounding in the direction coordinates (it did: argmax over two values equal to ~1e-16)."""
    est = DirectionalGradient(np.array([[0.3, 0.1], [0.2, -0.4]]), step=0.5, reuse=False)
    rng = np.random.default_rng(0)
    lb, ub = np.full(2, -10.0), np.full(2, 10.0)
    for _ in range(200):
        c = rng.uniform(-1, 1, 2)
        pts = est.plan(c, lb, ub)
        np.testing.assert_allclose(np.array(pts) - c, 0.5 * est.U.T, atol=1e-12)


def test_least_squares_passes_the_iteration_to_its_fallback():
    ls = LeastSquaresGradient(FiniteDifferenceGradient(H, alternate=True))
    lb, ub = np.full(2, -10.0), np.full(2, 10.0)
    np.testing.assert_allclose(ls.plan_iteration(np.zeros(2), lb, ub, [], 3), -H * np.eye(2))


def test_bad_alternate_is_named():
    with pytest.raises(ValueError, match="alternate='yes'"):
        FiniteDifferenceGradient(H, alternate="yes")
    with pytest.raises(ValueError, match="alternate=1"):
        DirectionalGradient(np.eye(2), alternate=1)
