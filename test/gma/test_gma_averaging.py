"""Effort matched to the iteration (``GMASettings.averaging_schedule``): every request of iteration ``k`` carries
``averaging`` times the schedule's ``k``-th multiplier (the last one holding), also repeats and an operator's
point, and a resumed run asks alike."""
import casadi as ca
import numpy as np
import pytest

from kite_rto.gma import GMA, ExperimentResult, GMASettings, History, ModelProblem, run_offline

SETTINGS = dict(filter_gain=1.0, trust_radius=0.3, averaging=4.0, averaging_schedule=(1, 2, 3))


def model():
    u = ca.SX.sym("u", 2)
    return ModelProblem(u=u, cost=(u[0] - 0.5) ** 2 + (u[1] - 1.5) ** 2, constraints=None, outputs=u,
                        lbu=-5, ubu=5, u0=[0, 0], c_lb=[-2, -2], c_ub=[3, 3], name="averaging")


def plant(c):
    return ExperimentResult("", (c[0] - 1) ** 2 + 2 * (c[1] - 1) ** 2, [], cost_std=1e-3, constraints_std=[])


def test_requests_carry_the_scheduled_averaging():
    hist = run_offline(GMA(model(), GMASettings(**SETTINGS)), plant, 5)
    by_k = {}
    for q, _ in hist.experiments:
        by_k.setdefault(q.iteration, set()).add(q.averaging)
    assert by_k == {0: {4.0}, 1: {8.0}, 2: {12.0}, 3: {12.0}, 4: {12.0}}


def test_without_a_schedule_every_request_gets_the_averaging():
    hist = run_offline(GMA(model(), GMASettings(filter_gain=1.0, averaging=4.0)), plant, 3)
    assert {q.averaging for q, _ in hist.experiments} == {4.0}


def test_operator_points_repeats_and_resumes_keep_the_schedule():
    first = run_offline(GMA(model(), GMASettings(**SETTINGS)), plant, 2)
    part = History(c0=first.c0, meta=first.meta, iterations=first.iterations[:1],
                   experiments=[(q, r) for q, r in first.experiments if q.iteration < 1])
    resumed = GMA(model(), GMASettings(**SETTINGS), history=part)
    assert [q.averaging for q in resumed.pending_requests()] == [8.0] * 3
    assert {q.averaging for q in resumed.plan_at([0.2, 0.3])} == {8.0}
    noisy = GMA(model(), GMASettings(**SETTINGS, max_repeats_noise=1, noise_ratio=1e-6))
    for _ in range(3):                                 # every change is "noisy": iteration 0 is flown again
        q = noisy.next_request()
        noisy.submit(ExperimentResult(q.request_id, plant(q.c).cost, [], cost_std=1.0, constraints_std=[]))
    again = noisy.pending_requests()
    assert len(again) == 3 and all(q.repeat_of and q.iteration == 0 for q in again)
    assert {q.averaging for q in again} == {4.0}


@pytest.mark.parametrize("bad", [(0,), (1, -2), (1, float("nan")), "ab", ((1, 2),), None])
def test_bad_schedules_are_named(bad):
    with pytest.raises(ValueError, match=r"GMASettings.averaging_schedule=.*expected a sequence of finite "
                                         r"multipliers > 0"):
        GMASettings(averaging_schedule=bad)


def test_settings_round_trip():
    s = GMASettings(**SETTINGS)
    back = GMASettings.from_dict(s.to_dict())
    assert [back.averaging_at(k) for k in range(5)] == [4.0, 8.0, 12.0, 12.0, 12.0]
    np.testing.assert_allclose(back.averaging_schedule, (1, 2, 3))
