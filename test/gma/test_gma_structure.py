"""Measurements overrule the model's structure (issue #14 item 2; kite_rto.gma.structure).

Closed-form problem, setpoints c = (c1, c2) in the box [0, 1] x [0, 2]:

    model  phi = 0.2 c1 + (c2 - theta)^2,  g = c2 - 0.9 - a c1 <= 0,  y = u,  theta = 0.8
    plant  phi_p = 0.2 c1 + (c2 - 1.3)^2,  g_p = c2 - 0.85 - c1 <= 0

The model optimum is (0, 0.8): c1 on its lower bound, pressed there by d phi / d c1 = 0.2, the constraint
inactive. The plant's constraint is active at its optimum and pulls c1 off the bound: on c2 = 0.85 + c1 the cost
is 0.2 c1 + (c1 - 0.45)^2, so the plant optimum is (0.35, 1.2) with multiplier nu = 0.2 (cost 0.08); the best
point with c1 held at its bound is (0, 0.85) (cost 0.2025).

DMA with the uncertain theta finds one privileged direction, c2, and declares the c1 bound robustly active (the
parameter moves only the c2 component of the Lagrangian gradient). Plant minus model is affine in c in both
cost and constraint, so the DMA estimate along c2 is exact up to the forward-difference bias of its step.
"""
import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import (GMA, DirectionalGradient, ExperimentResult, GMASettings, History, ModelProblem,
                          excluded_directions, lagrangian_gradient, model_optimum, privileged_directions,
                          robust_bounds, run_offline, structure_test, PlantPoint, GradientEstimate)

C_LB, C_UB = np.array([0.0, 0.0]), np.array([1.0, 2.0])
PLANT_OPT = np.array([0.35, 1.2])
HELD_OPT = np.array([0.0, 0.85])
H = 1e-3                        # DMA step (multiples of the direction, which is one box width long)


def model(theta=0.8, a=0.0):
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=0.2 * u[0] + (u[1] - theta) ** 2, constraints=u[1] - 0.9 - a * u[0], outputs=u,
                        lbu=C_LB, ubu=C_UB, u0=[0.5, 1.0], c_lb=C_LB, c_ub=C_UB, name="bound_model")


def plant(c, slope=1.0):
    return 0.2 * c[0] + (c[1] - 1.3) ** 2, np.array([c[1] - 0.85 - slope * c[0]])


def noisy(plant_fn, sigma, seed):
    rng = np.random.default_rng(seed)

    def measure(c):
        f, g = plant_fn(c)
        return ExperimentResult("", f + rng.normal(0, sigma), g + rng.normal(0, sigma, g.size), cost_std=sigma,
                                constraints_std=np.full(g.size, sigma))
    return measure


def dma_directions():
    """DMA's directions at the model optimum with the gradient-only activity test (the c1 bound fixed)."""
    pr = model()
    c0 = model_optimum(pr)
    np.testing.assert_allclose(c0, [0.0, 0.8], atol=1e-7)
    pd = privileged_directions(lambda th: lagrangian_gradient(model(th[0]), c0, [0.0]), [0.8], [0.3], 1,
                               scale=pr.c_width, at_bound=[-1, 0])
    assert pd.fixed.tolist() == [True, False]
    return pd.directions


def test_the_activity_test_with_constraints_frees_a_bound_the_constraint_can_pull_off():
    """Model with the right constraint structure (a = 1): theta + 0.3 makes the constraint active and moves the
    model optimum to c1 = 0.1; tightening the constraint by 0.3 moves it to c1 = 0.1 too. The gradient-only
    test at the model optimum (nu = 0) fixes c1 all the same."""
    def optimum(theta, offsets):
        return model_optimum(model(theta[0], a=1.0), offsets)

    gradient_only = privileged_directions(lambda th: lagrangian_gradient(model(th[0], 1.0), [0.0, 0.8], [0.0]),
                                          [0.8], [0.3], 1, scale=C_UB - C_LB, at_bound=[-1, 0])
    assert gradient_only.fixed.tolist() == [True, False]
    by_theta = robust_bounds(optimum, [0.8], [0.3], C_LB, C_UB)
    assert by_theta.nominal.tolist() == [-1, 0] and by_theta.at_bound.tolist() == [0, 0]
    assert by_theta.fragile.tolist() == [True, False] and by_theta.cases == ["nominal", "theta[0]"]
    np.testing.assert_allclose(by_theta.optima[1], [0.1, 1.0], atol=1e-6)
    by_offset = robust_bounds(optimum, [0.8], [-0.3], C_LB, C_UB, constraint_offsets=[0.3])
    assert by_offset.cases == ["nominal", "theta[0]", "constraint[0]"] and by_offset.at_bound.tolist() == [0, 0]
    np.testing.assert_allclose(by_offset.optima[2], [0.1, 0.7], atol=1e-6)
    # with the bound free, DMA gives c1 a share of the directions; a deviation that keeps the constraint
    # inactive (theta - 0.3) leaves the bound robustly active
    pd = privileged_directions(lambda th: lagrangian_gradient(model(th[0], 1.0), [0.0, 0.8], [0.0]), [0.8], [0.3],
                               1, scale=C_UB - C_LB, at_bound=by_theta.at_bound)
    assert not pd.fixed.any()
    assert robust_bounds(optimum, [0.8], [-0.3], C_LB, C_UB).at_bound.tolist() == [-1, 0]
    with pytest.raises(ValueError, match=r"deviations=\[0.0\]: expected 1 finite nonzero values"):
        robust_bounds(optimum, [0.8], [0.0], C_LB, C_UB)


def test_without_the_check_dma_holds_the_bound_and_misses_the_plant_optimum():
    gma = GMA(model(), GMASettings(), DirectionalGradient(dma_directions(), step=H, reuse=False))
    run_offline(gma, plant, 15)
    np.testing.assert_allclose(gma.c, HELD_OPT, atol=5e-3)
    assert all(r.c_next[0] == 0.0 for r in gma.records)
    assert not any(r.restored_directions for r in gma.records)
    assert all(e.purpose != "structure" for e, _ in gma.history.experiments)


def test_the_structure_check_restores_the_held_coordinate_and_reaches_the_plant_optimum():
    """The first check (k = 0) flies c1 + 0.1: the constraint changes by -0.1 where the model predicts 0, so
    c1 joins the directions and GMA reaches the plant optimum. Fails if the check is switched off."""
    gma = GMA(model(), GMASettings(structure_check_every=5),
              DirectionalGradient(dma_directions(), step=H, reuse=False))
    run_offline(gma, plant, 15)
    np.testing.assert_allclose(gma.c, PLANT_OPT, atol=5e-3)            # forward-difference bias ~1e-3
    first = gma.records[0]
    assert first.experiment_ids == ["k0-0-nominal", "k0-1-perturbation", "k0-2-structure"]
    assert len(first.restored_directions) == 1
    np.testing.assert_allclose(np.asarray(first.restored_directions[0]), [1.0, 0.0])   # one box width, as U
    assert any("mismatch in g[0]: direction restored" in n for n in first.notes)
    assert any("re-estimated (directional (2 of 2))" in n for n in first.notes)
    np.testing.assert_allclose(first.jac_constraints, [[-1.0, 1.0]], atol=1e-9)         # measured at once
    assert gma.gradient.n_directions == 2
    assert sum(len(r.restored_directions) for r in gma.records) == 1    # nothing left to check afterwards
    assert plant(gma.c)[0] == pytest.approx(0.08, abs=2e-3) and plant(gma.c)[1][0] <= 1e-6


def test_a_stalled_iterate_triggers_the_check_and_noise_alone_does_not_restore():
    """With noise (sigma = 1e-3, seeded) and only the stall trigger: DMA first stalls at the held optimum, the
    check then sees the constraint residual (-0.1, about 50 sigma) and restores c1. A plant whose constraint
    does not depend on c1 either (the model's structure is right there) never restores it."""
    settings = GMASettings(structure_stall=0.01)
    gma = GMA(model(), settings, DirectionalGradient(dma_directions(), step=0.05, reuse=False))
    run_offline(gma, noisy(plant, 1e-3, seed=3), 25)
    k_restored = [r.k for r in gma.records if r.restored_directions]
    assert len(k_restored) == 1 and k_restored[0] > 0
    assert gma.records[k_restored[0] - 1].c_next[0] == 0.0             # stalled on the bound before
    # the forward difference of 0.1 in c2 biases d phi_p / d c2 by +0.1 (f'' = 2): the fixed point is the optimum
    # of 0.3 c1 + (c1 - 0.45)^2 on the constraint, (0.3, 1.15), instead of (0.35, 1.2); noise ~1e-2 around it
    assert np.abs(gma.c - [0.3, 1.15]).max() < 0.02
    agree = GMA(model(), settings, DirectionalGradient(dma_directions(), step=0.05, reuse=False))
    run_offline(agree, noisy(lambda c: plant(c, slope=0.0), 1e-3, seed=3), 25)
    checks = [n for r in agree.records for n in r.notes if n.startswith("structure check along")]
    assert len(checks) >= 5 and all(n.endswith("model agrees") for n in checks)
    assert not any(r.restored_directions for r in agree.records)
    assert agree.gradient.n_directions == 1


def test_resume_keeps_the_restored_direction():
    settings = GMASettings(structure_check_every=5)
    gma = GMA(model(), settings, DirectionalGradient(dma_directions(), step=H, reuse=False))
    run_offline(gma, plant, 3)
    resumed = GMA(model(), settings, DirectionalGradient(dma_directions(), step=H, reuse=False),
                  history=History.from_json(gma.history.to_json()))
    np.testing.assert_allclose(resumed.gradient.U, gma.gradient.U)
    run_offline(gma, plant, 4)
    run_offline(resumed, plant, 4)
    np.testing.assert_allclose(resumed.c, gma.c, atol=1e-9)


def test_structure_test_thresholds_and_excluded_directions():
    est = GradientEstimate(np.array([1.0, 0.0]), np.array([[0.0, 0.5]]), 1.0, np.array([0.0, 0.02]))
    nominal = PlantPoint(np.zeros(2), 0.0, np.zeros(1), 0.01, np.array([0.01]))
    # predicted cost change 0.1; residual 0.05 vs threshold 3 * hypot(0.01 sqrt 2, 0) + 0.2 * 0.1 = 0.0624
    t = structure_test(np.zeros(2), nominal, PlantPoint(np.array([0.1, 0.0]), 0.15, np.zeros(1), 0.01,
                                                        np.array([0.01])), est, 3.0, 0.2)
    assert t.residual_cost == pytest.approx(0.05) and t.threshold_cost == pytest.approx(3 * 0.01 * 2 ** 0.5 + 0.02)
    assert not t.significant and t.describe().endswith("model agrees")
    t = structure_test(np.zeros(2), nominal, PlantPoint(np.array([0.1, 0.0]), 0.1, np.array([0.1]), 0.01,
                                                        np.array([0.01])), est, 3.0, 0.2)
    assert t.significant and "mismatch in g[0]" in t.describe()
    N = excluded_directions([[1.0], [1.0], [0.0]], [1.0, 1.0, 2.0])
    assert N.shape == (3, 2)
    np.testing.assert_allclose(np.array([[1.0, 1.0, 0.0]]) @ N, 0.0, atol=1e-12)
    np.testing.assert_allclose(np.max(np.abs(N) / np.array([[1.0], [1.0], [2.0]]), axis=0), 1.0)
    assert excluded_directions(np.eye(2), [1.0, 1.0]).shape == (2, 0)


@pytest.mark.parametrize("field, value, expected", [
    ("structure_check_every", -1, r"structure_check_every=-1: expected an integer >= 0"),
    ("structure_check_every", 1.5, r"structure_check_every=1.5: expected an integer >= 0"),
    ("structure_stall", -0.1, r"structure_stall=-0.1: expected every value in \[0.0, inf\]"),
    ("structure_step", 0.0, r"structure_step=0.0: expected every value in \(0.0, 1.0\]"),
    ("structure_sigma", float("nan"), r"structure_sigma=nan"),
    ("structure_rel_tol", -1.0, r"structure_rel_tol=-1.0"),
])
def test_structure_settings_are_validated(field, value, expected):
    with pytest.raises(ValueError, match=expected):
        GMASettings(**{field: value})
    assert not GMASettings().structure_check              # off by default
