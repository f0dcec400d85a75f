"""Effort matched to the iteration (``GMASettings.effort_schedule``, which replaced ``averaging`` and
``averaging_schedule``): every request of iteration ``k`` carries the schedule's ``k``-th multiplier as its
``effort`` (the last one holding), also an operator's point, and a resumed run asks alike."""
import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import GMA, ExperimentResult, GMASettings, History, ModelProblem, TrustRegion, run_offline

SETTINGS = dict(filter_gain=1.0, trust_region=TrustRegion(radius=0.3), effort_schedule=(1, 2, 3))


def model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - 0.5) ** 2 + (u[1] - 1.5) ** 2, constraints=None, outputs=u,
                        lbu=-5, ubu=5, u0=[0, 0], c_lb=[-2, -2], c_ub=[3, 3], name="averaging")


def plant(c):
    return ExperimentResult("", (c[0] - 1) ** 2 + 2 * (c[1] - 1) ** 2, [], cost_std=1e-3, constraints_std=[])


def test_requests_carry_the_scheduled_effort():
    hist = run_offline(GMA(model(), GMASettings(**SETTINGS)), plant, 5)
    by_k = {}
    for q, _ in hist.experiments:
        by_k.setdefault(q.iteration, set()).add(q.effort)
    assert by_k == {0: {1.0}, 1: {2.0}, 2: {3.0}, 3: {3.0}, 4: {3.0}}


def test_without_a_schedule_every_request_gets_effort_one():
    hist = run_offline(GMA(model(), GMASettings(filter_gain=1.0)), plant, 3)
    assert {q.effort for q, _ in hist.experiments} == {1.0}


def test_operator_points_and_resumes_keep_the_schedule():
    first = run_offline(GMA(model(), GMASettings(**SETTINGS)), plant, 2)
    part = History(c0=first.c0, meta=first.meta, iterations=first.iterations[:1],
                   experiments=[(q, r) for q, r in first.experiments if q.iteration < 1])
    resumed = GMA(model(), GMASettings(**SETTINGS), history=part)
    assert [q.effort for q in resumed.pending_requests()] == [2.0] * 3
    assert {q.effort for q in resumed.plan_at([0.2, 0.3])} == {2.0}


@pytest.mark.parametrize("bad", [(0,), (1, -2), (1, float("nan")), "ab", ((1, 2),), None])
def test_bad_schedules_are_named(bad):
    with pytest.raises(ValueError, match=r"GMASettings.effort_schedule=.*expected a sequence of finite "
                                         r"multipliers > 0"):
        GMASettings(effort_schedule=bad)


def test_settings_round_trip():
    s = GMASettings(**SETTINGS)
    back = GMASettings.from_dict(s.to_dict())
    assert [back.effort_at(k) for k in range(5)] == [1.0, 2.0, 3.0, 3.0, 3.0]
    np.testing.assert_allclose(back.effort_schedule, (1, 2, 3))
