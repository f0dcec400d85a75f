"""Modifiers from the model's own difference quotients (``GMASettings.model_secant``, gma/model_secant.py): with
large finite-difference steps GMA's fixed point is where the plant's *secant* vanishes, half a step from the plant
optimum; taking the model's secant over the same points cancels that error up to the curvature mismatch."""
import casadi as ca
import numpy as np
import pytest
from scipy.optimize import minimize

from kite_rto.gma import (GMA, DirectionalGradient, ExperimentResult, FiniteDifferenceGradient, GMASettings,
                          LeastSquaresGradient, ModelProblem, PlantPoint, run_offline)
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


@pytest.mark.parametrize("secant", [True, False])
def test_large_directional_steps_reach_the_plant_optimum_only_with_the_model_secant(secant):
    """DMA along d with a step of 0.5: the plant's secant alone puts the fixed point at c_opt - h/2 d (the
    truncation error h d^T H d / 2 with H = 2 I); the model's secant over the same points has the same error."""
    h = 0.5
    gma = GMA(model(), GMASettings(filter_gain=1.0, trust_radius=1.0, model_secant=secant),
              DirectionalGradient(D, step=h, reuse=False))
    run_offline(gma, plant, 10)
    expected = plant_optimum() if secant else plant_optimum() - h / 2 * D
    np.testing.assert_allclose(gma.c, expected, atol=1e-6)
    assert any("model secant" in n for n in gma.records[-1].notes) == secant


def test_forward_differences_keep_only_the_curvature_mismatch():
    """Coordinate forward differences of 0.4 on a plant curving more than the model in c[0] (2 + 2 x 1.5 against
    2): with the model secant the error is the mismatch's, (3 h / 2) in the first gradient component, instead of
    the whole curvature's (5 h / 2); both leave c[1] where its plant gradient vanishes (same curvature)."""
    h, k = 0.4, 1.5
    c_opt = plant_optimum(k)
    ends = {}
    for secant in (False, True):
        gma = GMA(model(), GMASettings(filter_gain=1.0, trust_radius=1.0, model_secant=secant),
                  FiniteDifferenceGradient(h))
        run_offline(gma, lambda c: plant(c, k), 15)
        ends[secant] = gma.c
    # the constraint is active at the plant optimum, so the error moves the point along it: compare distances
    err = {s: np.linalg.norm(ends[s] - c_opt) for s in ends}
    assert err[True] < 0.7 * err[False]
    assert err[False] > 0.05


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
    with pytest.raises(ValueError, match="model_secant='yes': expected True or False"):
        GMASettings(model_secant="yes")


def curved_quotients():
    """Forward differences of 0.5 at 0 of a curved cost ``c^T c`` and constraint ``c_0^2`` (the model's gradients at
    0 are zero for both): ``(plant estimate, correct(**options) -> model_secant_estimate(...))``."""
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
    return plant_est, lambda **kw: model_secant_estimate(fd, plant_est, c_k, pt(c_k), new, [], m, values, **kw)


def test_cost_only_keeps_the_plant_constraint_quotients():
    """``model_secant_constraints=False``: the cost gradient gets the model's truncation correction, the constraints'
    Jacobian stays the plant's difference quotient."""
    plant_est, correct = curved_quotients()
    np.testing.assert_allclose(plant_est.cost, [0.5, 0.5])                 # the secant, h f''/2
    full, _ = correct()
    cost_only, _ = correct(constraints=False)
    np.testing.assert_allclose(full.cost, [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(full.constraints, [[0.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(cost_only.cost, [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(cost_only.constraints, plant_est.constraints)
    with pytest.raises(ValueError, match="model_secant_constraints=1: expected True or False"):
        GMASettings(model_secant_constraints=1)


def test_secant_within_corrects_only_after_a_short_step_and_still_reaches_the_plant_optimum():
    """``model_secant_within``: no correction at k = 0 (no previous step) nor after a step longer than the bound
    (box widths, largest entry); the same fixed point as the correction in every iteration once steps are short.
    The first record is the uncorrected run's to the digit."""
    h, within = 0.5, 0.05
    runs = {}
    for w in (within, np.inf, None):
        s = GMASettings(filter_gain=1.0, trust_radius=1.0, model_secant=w is not None,
                        model_secant_within=w if w is not None else np.inf)
        gma = GMA(model(), s, DirectionalGradient(D, step=h, reuse=False))
        run_offline(gma, plant, 12)
        runs[w] = gma
    recs = runs[within].records
    width = model().c_width
    corrected = [any("model secant" in n for n in r.notes) for r in recs]
    expected = [k > 0 and float(np.max(np.abs(recs[k - 1].step) / width)) <= within for k in range(len(recs))]
    assert corrected == expected
    assert not corrected[0] and any(corrected) and not all(corrected)
    np.testing.assert_array_equal(recs[0].c_next, runs[None].records[0].c_next)
    np.testing.assert_allclose(runs[within].c, plant_optimum(), atol=1e-6)
    np.testing.assert_allclose(runs[np.inf].c, plant_optimum(), atol=1e-6)


@pytest.mark.parametrize("bad", [0.0, -0.1, float("nan")])
def test_secant_within_must_be_positive(bad):
    with pytest.raises(ValueError, match="model_secant_within"):
        GMASettings(model_secant_within=bad)


def test_constraints_only_keeps_the_plant_cost_quotients():
    """``model_secant_cost=False``: the constraints' Jacobian gets the model's truncation correction, the cost
    gradient stays the plant's difference quotient (for a model whose cost curves unlike the plant's)."""
    plant_est, correct = curved_quotients()
    out, note = correct(cost=False)
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
    model's secant on the constraint only (``model_secant_cost=False``) the quotient's error cancels, and every
    iterate lands on the plant constraint; both end at the same point."""
    s = GMASettings(filter_gain=1.0, trust_radius=1.0, model_secant=secant, model_secant_cost=False)
    gma = GMA(curved_model(), s, DirectionalGradient(np.eye(2), step=0.5, reuse=False), c0=[1.2, 0.0])
    hist = run_offline(gma, curved_plant, 8)
    g = [curved_plant(r.c_next).constraints[0] for r in hist.iterations]
    if secant:
        assert max(g) < 1e-6, g
        assert all("constraints only" in " ".join(r.notes) for r in hist.iterations)
    else:
        assert max(g) > 0.1, g
    np.testing.assert_allclose(gma.c, [1.3218, 1.3718], atol=1e-3)


def test_a_model_secant_correcting_nothing_is_refused():
    with pytest.raises(ValueError, match="model_secant_cost=False and model_secant_constraints=False"):
        GMASettings(model_secant=True, model_secant_cost=False, model_secant_constraints=False)
    with pytest.raises(ValueError, match="model_secant_cost='no': expected True or False"):
        GMASettings(model_secant_cost="no")
