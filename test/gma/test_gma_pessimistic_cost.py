"""The pessimistic modified cost (``GMASettings.cost_sigma``, issue #14 items 3 and 4): the modified problem adds
``z |sigma * d|`` to its cost, ``sigma`` the filtered cost-gradient modifier's standard deviation, so noise alone
does not move a converged iterate while a real plant-model mismatch still does.

Closed-form problems, setpoints c in [0, 2]^2, model cost |c - (1, 1)|^2 and no constraints; the cost is measured
with noise (std 0.05), central differences of 0.2 (exact on these quadratics; gradient std about 0.18 per setpoint).
"""
import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import GMA, ExperimentResult, FiniteDifferenceGradient, GMASettings, ModelProblem, run_offline
from kite_rto.gma.modifiers import Modifiers

COST_STD = 0.05


def model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - 1) ** 2 + (u[1] - 1) ** 2, constraints=ca.SX(0, 1), outputs=u,
                        lbu=[0, 0], ubu=[2, 2], u0=[1, 1], c_lb=[0, 0], c_ub=[2, 2], name="pessimistic")


def noisy_plant(seed, optimum):
    rng = np.random.default_rng(seed)

    def plant(c):
        cost = float(np.sum((np.asarray(c) - optimum) ** 2)) + COST_STD * rng.standard_normal()
        return ExperimentResult("", cost, np.zeros(0), cost_std=COST_STD, constraints_std=np.zeros(0))
    return plant


def run(seed, optimum, n_iter=10, **changes):
    s = GMASettings(filter_gain=1.0, modifier_drift=1.0, trust_radius=0.5, **changes)
    gma = GMA(model(), s, FiniteDifferenceGradient(0.2, "central"), c0=[1.0, 1.0])
    run_offline(gma, noisy_plant(seed, np.asarray(optimum, float)), n_iter)
    return gma.records


def test_the_modified_problem_has_the_closed_form_step():
    """The modified cost |c - 1|^2 + lam d + |sigma * d| at c_k = 1 has the step
    d_i = -(lam_i - sign(lam_i) z sigma_i) / 2 when |lam_i| > z sigma_i (per setpoint here: only one sigma is
    nonzero at a time), and d_i = 0 when |lam_i| <= z sigma_i."""
    gma = GMA(model(), GMASettings(cost_sigma=1.0), FiniteDifferenceGradient(0.2), c0=[1.0, 1.0])
    nlp = gma.modified_nlp
    cases = [((-1.0, 0.0), (0.4, 0.0), (0.3, 0.0)), ((0.3, 0.0), (0.4, 0.0), (0.0, 0.0)),
             ((0.0, 0.8), (0.0, 0.2), (0.0, -0.3)), ((0.5, 0.0), (0.0, 0.0), (-0.25, 0.0))]
    for lam, sigma, step in cases:
        mods = Modifiers(np.array([1.0, 1.0]), np.zeros(0), np.array(lam), np.zeros((0, 2)), np.zeros(0))
        res = nlp.solve(mods, radius=np.full(2, np.inf), convexification=np.zeros(2), penalty=None,
                        x0=np.array([1.0, 1.0]), spread=np.array(sigma))
        assert res.success
        np.testing.assert_allclose(res.x[:2] - 1.0, step, atol=2e-3)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_noise_alone_does_not_move_a_converged_point(seed):
    """Plant = model: every step is noise. With z = 2 the iterates travel less than half as far as without."""
    def travel(records):
        return float(sum(np.linalg.norm(r.step) for r in records))
    plain = run(seed, (1.0, 1.0))
    robust = run(seed, (1.0, 1.0), cost_sigma=2.0)
    assert travel(plain) > 0.2
    assert travel(robust) < 0.5 * travel(plain)
    assert all(any(n.startswith("pessimistic cost: 2 x sigma") for n in r.notes) for r in robust)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_real_mismatch_still_gets_through(seed):
    """Plant optimum at (1.5, 0.6), modifiers about (-1, 0.8): far above 2 sigma. GMA gets there with z = 2."""
    robust = run(seed, (1.5, 0.6), n_iter=12, cost_sigma=2.0)
    assert np.linalg.norm(robust[-1].c_next - [1.5, 0.6]) < 0.1


def test_bad_cost_sigma_is_named():
    with pytest.raises(ValueError, match="cost_sigma=-1.0"):
        GMASettings(cost_sigma=-1.0)


def test_cost_sigma_after_keeps_the_first_step():
    """With cost_sigma_after = 1 iteration 0 is solved without the pessimistic cost (same step as without it)
    and every later one with it."""
    plain = run(0, (1.5, 0.6), n_iter=3)
    late = run(0, (1.5, 0.6), n_iter=3, cost_sigma=2.0, cost_sigma_after=1)
    np.testing.assert_allclose(late[0].c_next, plain[0].c_next, atol=1e-6)
    assert not any(n.startswith("pessimistic cost") for n in late[0].notes)
    assert all(any(n.startswith("pessimistic cost: 2 x sigma") for n in r.notes) for r in late[1:])
    with pytest.raises(ValueError, match="cost_sigma_after=-1: expected an integer >= 0"):
        GMASettings(cost_sigma_after=-1)


def test_cost_sigma_until_ends_the_pessimism():
    """With cost_sigma_after = 1 and cost_sigma_until = 2 only iteration 1 is solved with the pessimistic cost:
    iterations 0 and 2 on take the plain step from their modifiers. The run leaves the plain one's history at
    iteration 1, so the checks are the notes, iteration 0's step (the plain one's), and iteration 1's modifiers
    (the plain one's) with a shorter step."""
    recs = run(0, (1.5, 0.6), n_iter=4, cost_sigma=2.0, cost_sigma_after=1, cost_sigma_until=2)
    marked = [any(n.startswith("pessimistic cost: 2 x sigma") for n in r.notes) for r in recs]
    assert marked == [False, True, False, False]
    plain = run(0, (1.5, 0.6), n_iter=2)
    np.testing.assert_allclose(recs[0].c_next, plain[0].c_next, atol=1e-6)
    # iteration 1: the same modifiers as the plain run's, a step shortened by the pessimism in every setpoint
    np.testing.assert_allclose(recs[1].lam, plain[1].lam, atol=1e-9)
    assert np.all(np.abs(recs[1].step) <= np.abs(plain[1].step) + 1e-9)
    assert np.linalg.norm(recs[1].step) < np.linalg.norm(plain[1].step)
    for bad in (1, 0):
        with pytest.raises(ValueError, match=f"cost_sigma_until={bad}: expected an integer >= 2"):
            GMASettings(cost_sigma_after=1, cost_sigma_until=bad)
