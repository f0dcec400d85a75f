"""The plan handshake's parts (kite_rto.runtime.plan, the shared end rule kite_rto.rto.experiment_end) and the
controller's side of it (SteeringLoop with OptimizerSync), without DDS."""
import math

import pytest

from kite_rto.flight.path import DEFAULT_SETPOINTS
from kite_rto.rto.experiment_end import COMPLETE, CRASHED, TIMED_OUT, ExperimentEnd
from kite_rto.runtime import optimizer_sync
from kite_rto.runtime.plan import PLAN_NAMES, PROGRESS_EVERY, Mode, Plan, PlanClock, PlanSender
from kite_rto.runtime.steering_loop import SYNC_NAMES

from test_steering_loop import DT_NS, NEW, Rig

C0 = tuple(DEFAULT_SETPOINTS.as_array().tolist())
PERIOD = 10.0                   # s: one lap of the synthetic phi below


def phi(t: float) -> float:
    """A figure-eight's phi (rad) with laps of PERIOD s, crossing zero upwards at t = 0.025, 10.025, ... s (the
    samples after the crossings: 0.05, 10.05, ... s)."""
    return 0.5 * math.sin(2.0 * math.pi * (t - 0.025) / PERIOD)


def end_time(end: ExperimentEnd, crash_at: float = math.inf, dt: float = 0.05):
    """Feed ``end`` the synthetic flight after its start until it ends: (time s, how)."""
    t = end.t_start
    while t < 1000.0:
        t = round(t + dt, 10)
        how = end.update(t, phi(t), 1 if t >= crash_at else 0)
        if how is not None:
            return t, how
    return None


def test_experiment_end_counts_laps_after_the_settling_and_ends_on_a_crash_or_the_time_limit():
    # started at 3 s: the lap from 10.025 s starts 7.025 s after it (< settle_time 8 s: not counted), the one
    # from 20.025 s is the settle lap, those from 30.025 and 40.025 s are averaged: complete at the sample after
    # the crossing at 50.025 s
    assert end_time(ExperimentEnd(3.0, 2, 8.0, 1, 300.0)) == (50.05, COMPLETE)
    assert end_time(ExperimentEnd(3.0, 2, 6.0, 1, 300.0)) == (40.05, COMPLETE)    # the lap from 10.025 s counts
    assert end_time(ExperimentEnd(3.0, 2, 8.0, 1, 300.0), crash_at=33.0) == (33.0, CRASHED)
    assert end_time(ExperimentEnd(3.0, 2, 8.0, 1, 25.0)) == (28.0, TIMED_OUT)
    end = ExperimentEnd(3.0, 2, 8.0, 1, 25.0)
    end_time(end)
    assert end.ended == TIMED_OUT and end.update(40.0, 0.0, 0) is None            # ended: says so once


def test_plan_messages_round_trip_and_bad_ones_name_what_is_wrong():
    plan = Plan(C0, 3, 7, Mode.EXPERIMENT, 4, 10.0, 1, 300.0)
    assert Plan.from_values(PLAN_NAMES, plan.values()) == plan
    assert SYNC_NAMES == PLAN_NAMES
    v = plan.values()
    bad = {"expected names": (["theta_0"], [0.5]), "expected finite": (PLAN_NAMES, [math.nan, *v[1:]]),
           "updates = 1.5": (PLAN_NAMES, [*C0, 1.5, *v[4:]]), "mode = 7.0": (PLAN_NAMES, [*v[:5], 7.0, *v[6:]]),
           "n_laps = 0": (PLAN_NAMES, [*v[:6], 0.0, *v[7:]])}
    for words, (names, values) in bad.items():
        with pytest.raises(ValueError, match=words):
            Plan.from_values(names, values)


def test_plan_clock_is_due_at_every_sample_under_each_never_under_free_and_from_the_end_of_an_experiment():
    clock = PlanClock()
    assert clock.due(0.0, 0.0, 0)                                     # no plan yet: every sample
    clock.begin(Plan(C0, 1, 1, Mode.FREE), 0.0)
    assert not any(clock.due(t, phi(t), 0) for t in range(1, 100))
    clock.begin(Plan(C0, 1, 2, Mode.EXPERIMENT, 1, 0.0, 0, 15.0), 0.0)
    due = [t for t in (k * 0.5 for k in range(1, 60)) if clock.due(t, phi(t), 0)]
    assert due[0] == 15.0 and due == [k * 0.5 for k in range(30, 60)]     # timed out, then every sample


def test_plan_sender_numbers_new_plans_and_reports_progress():
    sender = PlanSender()
    assert sender.after(0.0, True, None, 0, Mode.EACH) is None                # nothing published yet
    each = sender.after(0.02, True, C0, 1, Mode.EACH)
    assert each.number == 1 and sender.after(0.04, True, C0, 1, Mode.EACH) == each     # the same plan
    exp = sender.after(0.06, True, C0, 2, Mode.EXPERIMENT, (1, 0.0, 0, 15.0))
    again = sender.after(0.08, True, C0, 2, Mode.EXPERIMENT, (1, 0.0, 0, 15.0))
    assert (exp.number, again.number) == (2, 3)                               # a new start: a new plan
    sent = [sender.after(0.1 + k * 0.02, False, C0, 2, Mode.EACH) for k in range(3 * PROGRESS_EVERY)]
    assert [k for k, p in enumerate(sent) if p is not None] == [PROGRESS_EVERY - 1, 2 * PROGRESS_EVERY - 1,
                                                               3 * PROGRESS_EVERY - 1]
    assert all(p is None or p == again for p in sent)


def _experiment(number, updates=1, c=C0, max_duration=0.09):
    """An experiment plan that flies no lap and times out after ``max_duration`` s (5 samples of 0.02 s)."""
    return Plan(tuple(c), updates, number, Mode.EXPERIMENT, 1, 0.0, 0, max_duration).values()


def test_the_controller_waits_only_where_the_plan_says_a_decision_is_due():
    rig = Rig(sync=True)
    rig.sample(0)
    assert rig.answers == []                                          # no plan yet: waits
    rig.loop.sync_message(0, SYNC_NAMES, _experiment(1))
    for k in range(1, 5):
        rig.sample(k)
    assert [s for s, _ in rig.answers] == [k * DT_NS for k in range(5)]   # answered at once
    rig.sample(5)                                                     # t - t_start = 0.1 s >= 0.09 s: due
    assert len(rig.answers) == 5 and rig.loop.optimizer_sync.held[0] == 5 * DT_NS
    rig.loop.sync_message(3 * DT_NS, SYNC_NAMES, _experiment(1))      # progress about an earlier sample
    assert len(rig.answers) == 5
    rig.loop.sync_message(5 * DT_NS, SYNC_NAMES, _experiment(2, updates=2, c=NEW))     # the decision
    assert len(rig.answers) == 6 and rig.loop.controller.setpoints.as_array().tolist() == NEW
    for k in range(6, 10):
        rig.sample(k)
    assert len(rig.answers) == 10 and rig.loop.optimizer_sync.held is None
    rig.sample(10)                                                    # the new plan's end: 5 samples after 5
    assert len(rig.answers) == 10
    rig.loop.sync_message(10 * DT_NS, SYNC_NAMES, Plan(tuple(NEW), 2, 3, Mode.FREE).values())
    for k in range(11, 40):
        rig.sample(k)
    assert len(rig.answers) == 40 and rig.log.count("arrived after") == 0


def test_a_crash_ends_the_controllers_plan_as_it_ends_the_experiment():
    rig = Rig(sync=True)
    rig.sample(0)
    rig.loop.sync_message(0, SYNC_NAMES, _experiment(1, max_duration=100.0))
    rig.sample(1)
    rig.sample(2)
    rig.loop.crash_count(1)
    rig.sample(3)
    assert len(rig.answers) == 3 and rig.loop.optimizer_sync.held[0] == 3 * DT_NS


def test_a_plan_for_a_sample_already_answered_applies_from_the_next_with_a_warning():
    rig = Rig(sync=True)
    rig.sample(0)
    rig.loop.sync_message(0, SYNC_NAMES, _experiment(1, max_duration=100.0))
    for k in range(1, 4):
        rig.sample(k)
    rig.loop.sync_message(2 * DT_NS, SYNC_NAMES, _experiment(2, updates=2, c=NEW, max_duration=100.0))
    assert rig.log.count("arrived after") == 1
    assert rig.loop.controller.setpoints.as_array().tolist() == NEW
    rig.sample(4)
    assert len(rig.answers) == 5


def test_the_controller_stays_within_max_lead_samples_of_the_optimizer(monkeypatch):
    monkeypatch.setattr(optimizer_sync, "MAX_LEAD", 3)
    rig = Rig(sync=True)
    rig.sample(0)
    rig.loop.sync_message(0, SYNC_NAMES, Plan(C0, 1, 1, Mode.FREE).values())
    for k in range(1, 5):
        rig.sample(k)
    assert len(rig.answers) == 4                                     # 1, 2, 3 answered; 4 waits
    rig.loop.sync_message(DT_NS, SYNC_NAMES, Plan(C0, 1, 1, Mode.FREE).values())
    assert len(rig.answers) == 5                                     # 2, 3 unreported: 4 answered
    rig.sample(5)
    assert len(rig.answers) == 5
    rig.loop.sync_message(5 * DT_NS, SYNC_NAMES, Plan(C0, 1, 1, Mode.FREE).values())
    assert len(rig.answers) == 6 and rig.log.count("arrived after") == 0
