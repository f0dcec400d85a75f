"""The optimizer's pause, manual setpoints and resume without ROS (OptimizerRun on the storage tests' fast flight),
the operator event log and GMA's operator point."""
import math
import sqlite3

import numpy as np

from kite_rto.flight.shape import setpoints_from_shape, shape_from_setpoints
from kite_rto.gma import HistoryStore
from kite_rto.rto.builder import make_gma
from kite_rto.runtime.operator_log import MANUAL, TRANSITION, transition_event, was_paused

from storage_flight import DT, SETTINGS, TICK, Flight, sample

MANUAL_C = np.radians([33.0, 50.0, 7.5])       # inside the box and trackable (theta_0, A_phi, A_theta)


def step(f: Flight, n: int) -> None:
    """``n`` samples of the flight (or until its run is done)."""
    for i in range(n):
        if f.run.done:
            return
        f.clock += 0.1
        f.run.on_sample(sample(f.t))
        if i % TICK == 0:
            f.run.tick()
        f.t += DT


def check_db(db):
    store = HistoryStore(db)
    try:
        h = store.load()
        rows = sqlite3.connect(db).execute("SELECT request_id FROM experiments").fetchall()
        ids = [r for (r,) in rows]
        return h, ids, store.events()
    finally:
        store.close()


def test_pause_holds_then_manual_setpoints_become_the_iterate(tmp_path):
    db = tmp_path / "rto.sqlite"
    f = Flight(db, n_iter=2)
    f.run.begin()
    step(f, 15)                                    # one experiment done (1 s each), the second half-way
    assert len(f.gma.history.experiments) == 1
    interrupted = f.run.session.request.request_id
    held, sent = f.flying.copy(), len(f.sent)
    f.run.pause()
    step(f, 600)                                   # 60 s of simulated flight paused
    assert len(f.sent) == sent and np.array_equal(f.flying, held), "setpoints changed while paused"
    assert len(f.gma.history.experiments) == 1, "an experiment was measured while paused"
    assert f.run.phase.startswith("paused")
    assert f.run.manual_setpoints(MANUAL_C, t=f.t) == ""
    assert len(f.sent) == sent + 1 and np.allclose(f.flying, MANUAL_C, atol=1e-12)
    assert np.allclose(setpoints_from_shape(f.gma.c), MANUAL_C, atol=1e-12)
    f.run.resume()
    step(f, 2000)
    assert f.finished and f.unsafe == 0 and f.mismeasured == 0
    h, ids, events = check_db(db)
    assert len(ids) == len(set(ids)), "an experiment stored twice"
    assert interrupted not in ids, "the interrupted experiment was kept"
    assert np.allclose(h.iterations[0].c_k, shape_from_setpoints(MANUAL_C), rtol=0, atol=1e-12)
    assert h.iterations[0].experiment_ids[0] == "k0m1-0-nominal"
    assert ids[0] == "k0-0-nominal" and "k0m1-0-nominal" in ids        # the finished old-point one is kept
    assert [e[0] for e in events] == [MANUAL]
    assert np.allclose(events[0][1]["c"], MANUAL_C)


def test_manual_setpoints_refused_outside_the_box_or_while_active(tmp_path):
    f = Flight(tmp_path / "rto.sqlite")
    f.run.begin()
    step(f, 5)
    assert "active" in f.run.manual_setpoints(MANUAL_C)
    f.run.pause()
    sent = len(f.sent)
    why = f.run.manual_setpoints(np.radians([20.0, 50.0, 7.5]))
    assert "theta_0" in why and "20 deg" in why, why
    why = f.run.manual_setpoints(np.radians([33.0, 50.0, 12.0]))      # A_theta outside the setpoint box
    assert why and "A_theta" in why, why
    why = f.run.manual_setpoints([math.nan, 0.8, 0.1])
    assert why and "nan" in why.lower(), why
    assert len(f.sent) == sent and f.run.manual_note.startswith("refused")
    assert f.store.events() == []


def test_a_restart_after_manual_setpoints_continues_from_them(tmp_path):
    db = tmp_path / "rto.sqlite"
    f = Flight(db, n_iter=2)
    f.run.begin()
    step(f, 15)
    f.run.pause()
    assert f.run.manual_setpoints(MANUAL_C) == ""
    # killed while paused (the store left as it is); a new process resumes the run
    g = Flight(db, n_iter=2)
    assert g.gma.next_request().request_id == "k0m1-0-nominal"
    assert np.allclose(setpoints_from_shape(g.gma.c), MANUAL_C)
    g.fly()
    assert g.finished and g.unsafe == 0
    _, ids, _ = check_db(db)
    assert len(ids) == len(set(ids))


def test_gma_operator_points_get_new_ids_and_stay_in_the_box():
    gma = make_gma(SETTINGS)
    x = shape_from_setpoints(MANUAL_C)
    first = gma.plan_at(x)
    assert [q.request_id.split("-")[0] for q in first] == ["k0m1"] * len(first)
    gma.replace_plan(first)
    assert [q.request_id.split("-")[0] for q in gma.plan_at(x)] == ["k0m2"] * len(first)
    bad = np.array(x)
    bad[2] = 5.0
    try:
        gma.plan_at(bad)
    except ValueError as err:
        assert "outside the setpoint box" in str(err)
    else:
        raise AssertionError("plan_at accepted a point outside the box")


def test_event_log_and_was_paused(tmp_path):
    db = tmp_path / "rto.sqlite"
    store = HistoryStore(db)
    assert store.events() == [] and not was_paused(store.events())
    for label, a, b in (("configure", "unconfigured", "inactive"), ("activate", "inactive", "active"),
                        ("deactivate", "active", "inactive")):
        store.save_progress(events=[transition_event(label, a, b, 1.5)])
    assert was_paused(store.events())
    store.save_progress(events=[transition_event("cleanup", "inactive", "unconfigured", None)])
    assert was_paused(store.events()), "a cleanup does not end a pause"
    store.save_progress(events=[transition_event("activate", "inactive", "active", 2.0)])
    assert not was_paused(store.events())
    assert [e[0] for e in store.events()] == [TRANSITION] * 5
    store.close()


def test_an_old_database_without_the_event_log_opens_and_gains_it(tmp_path):
    db = tmp_path / "old.sqlite"
    f = Flight(db, n_iter=1).fly()
    assert f.finished
    conn = sqlite3.connect(db)
    conn.execute("DROP TABLE events")
    conn.commit()
    conn.close()
    store = HistoryStore(db)
    assert store.load() is not None and store.events() == []
    store.save_progress(events=[transition_event("deactivate", "active", "inactive", None)])
    assert was_paused(store.events())
    store.close()
