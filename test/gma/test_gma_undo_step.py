"""The measured step test (:class:`~kite_rto.gma.Undo`): a step after which the plant's measured
cost rose by more than ``sigma`` standard errors is undone, the next operating point is the previous one and the trust
radius shrinks in the setpoints that moved.

Closed-form problem, setpoints c in [0, 2]^2: model cost |c - (1, 1)|^2; the plant's cost is four times as curved
in c_0 with its optimum at c_0 = 1.2, 4 (c_0 - 1.2)^2 + (c_1 - 1)^2, measured without noise but reported with a
standard error (0.01 unless a test says otherwise). From the model optimum (1, 1) the plant gradient is (-1.6, 0),
the modified problem steps to c_0 = 1.8 (inside the trust region of 0.5 box widths), where the plant's cost is 1.44
against 0.16: a rise of about 90 standard errors.
"""
import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import (GMA, ExperimentResult, FiniteDifferenceGradient, GMASettings, ModelProblem, TrustRegion,
                          Undo, run_offline)
from kite_rto.gma.modifiers import Decision


def model(constraint=None):
    u = ca.SX.sym("u", 2)
    g = ca.SX(0, 1) if constraint is None else constraint(u)
    return ModelProblem(u=u, cost=(u[0] - 1) ** 2 + (u[1] - 1) ** 2, constraints=g, outputs=u,
                        lbu=[0, 0], ubu=[2, 2], u0=[1, 1], c_lb=[0, 0], c_ub=[2, 2], name="undo")


def plant(cost_std=0.01, constraint=None):
    def fly(c):
        cost = 4.0 * (c[0] - 1.2) ** 2 + (c[1] - 1.0) ** 2
        g = np.zeros(0) if constraint is None else np.atleast_1d(constraint(c))
        return ExperimentResult("", float(cost), g, cost_std=cost_std, constraints_std=np.zeros(g.size))
    return fly


def run(n_iter=4, cost_std=0.01, constraint=None, model_constraint=None, undo=2.0):
    """``undo``: ``Undo.sigma``, ``None`` for no undo."""
    s = GMASettings(filter_gain=1.0, trust_region=TrustRegion(radius=0.5, adapt=False),
                    undo=None if undo is None else Undo(sigma=undo))
    gma = GMA(model(model_constraint), s, FiniteDifferenceGradient(1e-3, "central"), c0=[1.0, 1.0])
    run_offline(gma, plant(cost_std, constraint), n_iter)
    return gma


def test_a_step_the_plant_measures_as_a_loss_is_undone():
    recs = run(undo=2.0).records
    np.testing.assert_allclose(recs[0].c_next, [1.8, 1.0], atol=1e-3)        # the model's overshoot
    assert recs[1].outcome is Decision.UNDONE
    np.testing.assert_array_equal(recs[1].c_next, recs[0].c_k)             # back to the previous point
    np.testing.assert_allclose(recs[1].trust_radius_next, [0.25, 0.5])     # shrunk where the step moved
    assert any(n.startswith("step undone: the cost measured at c_k is 1.28") for n in recs[1].notes)
    # from (1, 1) again, the shorter trust region: 1.5 still rises (0.36 against 0.16), so it is undone as well;
    # then 1.25 (0.01) is kept
    np.testing.assert_allclose(recs[2].c_next, [1.5, 1.0], atol=1e-3)
    assert recs[3].outcome is Decision.UNDONE
    kept = [r.cost for r in recs if r.outcome is not Decision.UNDONE]
    assert kept == sorted(kept, reverse=True)


def test_switched_off_the_step_is_kept():
    recs = run(undo=None).records
    assert all(r.outcome is not Decision.UNDONE for r in recs)
    assert not np.allclose(recs[1].c_next, recs[0].c_k)
    assert not any(n.startswith("step undone") for n in recs[1].notes)


def test_a_rise_within_the_noise_is_kept():
    """With a standard error of 1 the rise of 1.28 is 0.9 standard errors of the difference: below sigma = 2."""
    recs = run(n_iter=2, cost_std=1.0, undo=2.0).records
    assert recs[1].outcome is not Decision.UNDONE


def test_no_undo_back_to_a_point_that_broke_the_constraints():
    """The plant's constraint c_1 <= 0.9 is violated at the model optimum (the model's is c_1 <= 5): the step
    that restores feasibility stays, even though the cost rose."""
    recs = run(n_iter=2, undo=2.0, constraint=lambda c: c[1] - 0.9, model_constraint=lambda u: u[1] - 5.0
               ).records
    assert recs[0].constraints[0] > 0
    assert recs[1].cost > recs[0].cost + 1.0
    assert recs[1].outcome is not Decision.UNDONE


def test_without_standard_errors_nothing_is_undone():
    recs = run(n_iter=2, cost_std=None, undo=0.0).records
    assert recs[1].outcome is not Decision.UNDONE


def test_a_resumed_run_undoes_alike():
    whole = run(n_iter=4, undo=2.0)
    part = run(n_iter=2, undo=2.0)
    resumed = GMA(model(), part.settings, FiniteDifferenceGradient(1e-3, "central"), history=part.history)
    run_offline(resumed, plant(), 2)
    for a, b in zip(whole.records, resumed.records):
        assert a.outcome is b.outcome
        np.testing.assert_allclose(a.c_next, b.c_next, atol=1e-9)
        np.testing.assert_allclose(a.trust_radius_next, b.trust_radius_next)


@pytest.mark.parametrize("bad", [-1.0, float("nan")])
def test_bad_undo_sigma_is_named(bad):
    with pytest.raises(ValueError, match=rf"Undo.sigma={bad!r}: expected every value in \[0.0, inf\]"):
        Undo(sigma=bad)
