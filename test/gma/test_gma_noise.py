"""(d) Safeguards: the trust region stops MA oscillation; with noisy measurements the iterates stay in a
neighbourhood of the plant optimum consistent with the noise.

Oscillation problem: plant phi_p = 3 |c - (1, 1)|^2, model phi = |u|^2, y = u, no constraints. The model's
curvature is a third of the plant's, so the undamped MA step overshoots: c_{k+1} - c* = -2 (c_k - c*).
Noise problem: problem (a) of test_gma_convergence with Gaussian noise on cost and constraint.
"""
import casadi as ca
import numpy as np

from kite_rto.gma import (GMA, ExperimentResult, FiniteDifferenceGradient, GMASettings, ModelProblem, ModifierFilter,
                          TrustRegion, run_offline)


def flat_model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=ca.sumsqr(u), constraints=None, outputs=u, lbu=-10, ubu=10, u0=[0, 0],
                        c_lb=[-3, -3], c_ub=[3, 3], name="flat")


def steep_plant(c):
    return 3 * float(np.sum((np.asarray(c) - 1) ** 2)), np.zeros(0)


def sign_changes(steps):
    s = np.sign(np.asarray(steps))
    return int(np.sum(s[1:] * s[:-1] < 0))


def run(settings, n=30):
    gma = GMA(flat_model(), settings, FiniteDifferenceGradient(1e-6, "central"))
    hist = run_offline(gma, steep_plant, n, stop_on_convergence=True)
    return gma, np.array([r.step for r in hist.iterations])


def test_without_safeguards_ma_oscillates():
    gma, steps = run(GMASettings(filter_gain=1.0, trust_region=None))
    assert not gma.converged
    assert sign_changes(steps[:, 0]) >= 20  # flips sign at every iteration
    assert np.max(np.abs(gma.c - 1.0)) > 1.0  # bounces between the box walls
    amplitude = np.max(np.abs(steps), axis=1)
    assert np.min(amplitude[-5:]) > 1.0  # and never settles


def test_trust_region_stops_the_oscillation():
    gma, steps = run(GMASettings(filter_gain=1.0, trust_region=TrustRegion(radius=0.25, min_radius=1e-4)))
    assert gma.converged
    np.testing.assert_allclose(gma.c, [1.0, 1.0], atol=1e-3)
    amplitude = np.max(np.abs(steps), axis=1)
    assert np.max(amplitude[-5:]) < 0.01 * np.max(amplitude[:5])  # the oscillation dies out


def test_the_input_filter_also_converges():
    """Filter gain 0.3: c_{k+1} - c* = (1 - 0.3 - 0.3 x 2) (c_k - c*) = 0.1 (c_k - c*), a contraction."""
    gma, _ = run(GMASettings(filter_gain=0.3, trust_region=None), n=60)
    assert gma.converged
    np.testing.assert_allclose(gma.c, [1.0, 1.0], atol=1e-3)


def quad_model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - 0.5) ** 2 + (u[1] - 1.5) ** 2, constraints=0.9 * u[0] + u[1] - 2.2,
                        outputs=u, lbu=-5, ubu=5, u0=[0, 0], c_lb=[-2, -2], c_ub=[3, 3])


def noisy_plant(sigma, seed):
    rng = np.random.default_rng(seed)

    def plant(c):
        cost = (c[0] - 1) ** 2 + 2 * (c[1] - 1) ** 2 + sigma * rng.standard_normal()
        g = c[0] + c[1] - 1.5 + sigma * rng.standard_normal()
        return ExperimentResult("", cost, [g], cost_std=sigma, constraints_std=[sigma])
    return plant


def tail_stats(settings, sigma, seed, n=40):
    fd = FiniteDifferenceGradient.from_noise(sigma, curvature=[2.0, 4.0], scheme="central")
    gma = GMA(quad_model(), settings, fd)
    hist = run_offline(gma, noisy_plant(sigma, seed), n)
    tail = np.array([r.c_next for r in hist.iterations[-15:]])
    return tail, hist


def test_noise_neighbourhood_and_damping():
    sigma, c_opt = 1e-3, np.array([2 / 3, 5 / 6])
    safe = GMASettings(filter_gain=0.7, trust_region=TrustRegion(radius=0.25, min_radius=1e-3))
    bare = GMASettings(filter_gain=1.0, trust_region=None)
    spreads_safe, spreads_bare = [], []
    h = FiniteDifferenceGradient.from_noise(sigma, curvature=[2.0, 4.0], scheme="central").step
    # central differences: gradient error std ~ sigma / (sqrt(2) h); mapped through the smallest plant
    # curvature (2) this is the setpoint error; allow 3 standard deviations.
    radius = 3 * sigma / (np.sqrt(2) * np.min(h)) / 2.0
    for seed in range(3):
        tail, hist = tail_stats(safe, sigma, seed)
        assert hist.iterations[-1].gradient_method == "finite-difference (central)"
        assert np.all(np.abs(tail - c_opt) < radius), (tail, radius)
        assert np.all(np.abs(tail.mean(axis=0) - c_opt) < radius / 3)
        spreads_safe.append(np.max(np.ptp(tail, axis=0)))
        tail_b, _ = tail_stats(bare, sigma, seed)
        spreads_bare.append(np.max(np.ptp(tail_b, axis=0)))
    assert np.mean(spreads_safe) < 0.5 * np.mean(spreads_bare), (spreads_safe, spreads_bare)


def test_modifier_filter_averages_the_gradient_noise():
    """With noisy gradients, lambda_k = (1 - b) lambda_{k-1} + b lambda_measured: the recursion holds exactly,
    the filtered modifiers scatter less than the measured ones, and the iterates end closer to the optimum."""
    sigma, c_opt = 3e-3, np.array([2 / 3, 5 / 6])
    errors = {}
    for b in (1.0, 0.3):
        settings = GMASettings(filter_gain=0.7, trust_region=TrustRegion(radius=0.25, min_radius=1e-3),
                               modifier_filter=None if b == 1.0 else ModifierFilter(b))
        scatter, err = [], []
        for seed in range(3):
            tail, hist = tail_stats(settings, sigma, seed)
            its = hist.iterations
            measured = np.array([r.grad_cost - r.grad_phi_hat for r in its])
            lam = np.array([r.lam for r in its])
            if b < 1.0:
                np.testing.assert_allclose(lam[1:], (1 - b) * lam[:-1] + b * measured[1:], rtol=1e-12, atol=1e-12)
                assert "modifiers filtered" in " ".join(its[-1].notes)
            else:
                np.testing.assert_allclose(lam, measured, rtol=1e-12, atol=1e-12)
            scatter.append(np.std(np.diff(lam[-15:], axis=0)))
            err.append(np.max(np.abs(tail.mean(axis=0) - c_opt)))
        errors[b] = (np.mean(scatter), np.mean(err))
    assert errors[0.3][0] < 0.6 * errors[1.0][0], errors
    assert errors[0.3][1] <= errors[1.0][1] * 1.5, errors
