"""The constraint modifiers' own noise-matched gain (``NoiseFilter.constraint_drift``).

Closed-form problem, setpoints c in [0, 2]^2: the model and the plant share the cost |c - (2, 2)|^2 and differ in
the constraint, model g = c1 + c2 - 2.5, plant g_p = c1 + c2 - 2.5 + 0.5 (c1 - 0.5)^2, so the constraint-gradient
modifier mu = (c1 - 0.5, 0) changes as c1 moves. The cost is measured with noise (std 0.05), the constraint almost
exactly (std 1e-4): like the kite's tension and altitude.
"""
import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import (GMA, ExperimentResult, FiniteDifferenceGradient, GMASettings, ModelProblem, NoiseFilter,
                          TrustRegion, run_offline)
from kite_rto.gma.noise_filter import noise_gain

COST_STD, G_STD = 0.05, 1e-4


def model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - 2) ** 2 + (u[1] - 2) ** 2, constraints=u[0] + u[1] - 2.5, outputs=u,
                        lbu=[0, 0], ubu=[2, 2], u0=[0.5, 0.5], c_lb=[0, 0], c_ub=[2, 2], name="mu_filter")


def noisy_plant(seed):
    rng = np.random.default_rng(seed)

    def plant(c):
        cost = (c[0] - 2) ** 2 + (c[1] - 2) ** 2 + COST_STD * rng.standard_normal()
        g = c[0] + c[1] - 2.5 + 0.5 * (c[0] - 0.5) ** 2 + G_STD * rng.standard_normal()
        return ExperimentResult("", cost, np.array([g]), cost_std=COST_STD, constraints_std=np.array([G_STD]))
    return plant


def run(seed, constraint_drift=None):
    s = GMASettings(noise_filter=NoiseFilter(drift=1.0, constraint_drift=constraint_drift),
                    trust_region=TrustRegion(radius=0.1, min_radius=0.05))
    gma = GMA(model(), s, FiniteDifferenceGradient(0.2), c0=[0.5, 0.5])
    run_offline(gma, noisy_plant(seed), 8)
    return gma.records


def lag(records):
    """Largest gap between the recorded constraint modifier and the one this iteration measured."""
    return max(float(np.max(np.abs(r.mu - (r.jac_constraints - r.jac_g_hat)))) for r in records[1:])


@pytest.mark.parametrize("seed", [0, 1])
def test_a_precise_constraint_follows_its_measurements(seed):
    """With the cost's gain the constraint modifier lags its own exact measurements by the cost's averaging; with
    ``constraint_drift`` its gain comes from its own (tiny) noise and it follows them."""
    shared = run(seed)
    own = run(seed, constraint_drift=1.0)
    assert lag(shared) > 0.02
    assert lag(own) < 1e-3
    for r in own[1:]:
        assert any("constraint modifiers filtered by their own noise" in n for n in r.notes)
    assert all("constraint modifiers" not in n for r in shared for n in r.notes)


def test_the_gain_is_the_filters_with_the_constraints_noise():
    """The recorded mu = (1 - K_g) mu_prev + K_g mu_measured, K_g from noise_gain over the same chain with the
    gradient's std scaled by G_STD / COST_STD and drift bound constraint_drift."""
    recs = run(0, constraint_drift=0.0)
    width = np.array([2.0, 2.0])
    for k in (1, 3, len(recs) - 1):
        chain = recs[: k + 1]
        K, _ = noise_gain([r.c_k for r in chain], [r.grad_cost_std * G_STD / COST_STD for r in chain], 0.0, width)
        measured = recs[k].jac_constraints - recs[k].jac_g_hat
        np.testing.assert_allclose(recs[k].mu, (1 - K) * recs[k - 1].mu + K * measured, rtol=1e-9, atol=1e-12)


def test_settings_name_bad_values():
    with pytest.raises(ValueError, match=r"NoiseFilter.constraint_drift=-1.0: expected every value in \[0.0, inf\]"):
        NoiseFilter(drift=1.0, constraint_drift=-1.0)
    with pytest.raises(ValueError, match=r"NoiseFilter.constraint_drift=\[1.0, nan\]"):
        NoiseFilter(constraint_drift=[1.0, float("nan")])
