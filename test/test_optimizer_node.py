"""Optimizer node over real DDS: an end-to-end GMA iteration equals the pure runner; a killed optimizer resumes."""
import os
import signal
import time

import numpy as np
import pytest

from kite_rto.core.experiment import ExperimentSpec
from kite_rto.core.kite_rto import KiteRTOSettings, run_kite_rto
from kite_rto.core.plant import PlantConfig
from kite_rto.core.path import setpoints_from_shape
from kite_rto.gma import HistoryStore

from rosutil import Probe, start_node, stop

pytestmark = pytest.mark.ros
QUIET = {"turbulence": False, "anemometer_noise": 0.0, "noise_angle_deg": 0.0, "noise_rate": 0.0, "noise_tension": 0.0}
SHORT = {"n_laps": 1, "settle_laps": 0, "n_iter": 1, "exit_when_done": True}


@pytest.fixture
def probe():
    p = Probe()
    yield p
    p.close()


def start_graph(probe, db, ros_env):
    """Optimizer first (it publishes the first setpoints), then controller, then plant (waits for both to subscribe)."""
    opt = start_node("optimizer", {"db": str(db), **SHORT}, ros_env)
    assert probe.spin_until(lambda: probe.node.count_publishers("/rto/setpoints") > 0, 120.0)
    ctrl = start_node("controller", {}, ros_env)
    assert probe.spin_until(lambda: probe.node.count_publishers("/kite/steering") > 0, 60.0)
    plant = start_node("plant", {**QUIET, "wait_subscribers": 2}, ros_env)
    return opt, ctrl, plant


def stored(db):
    store = HistoryStore(db)
    try:
        return store.load(), store.counts()
    finally:
        store.close()


def test_end_to_end_iteration_matches_pure_runner(probe, ros_env, tmp_path):
    db = tmp_path / "rto.sqlite"
    opt, ctrl, plant = start_graph(probe, db, ros_env)
    try:
        assert probe.spin_until(lambda: opt.poll() is not None, 600.0), "optimizer did not finish"
        assert opt.returncode == 0
    finally:
        out = stop(opt)
        stop(plant)
        stop(ctrl)
    history, counts = stored(db)
    assert counts == {"experiments": 4, "iterations": 1}, out
    settings = KiteRTOSettings(experiment=ExperimentSpec(n_laps=1, settle_laps=0))
    pure = run_kite_rto(PlantConfig().without_disturbances(), seed=0, n_iter=1, settings=settings)
    ros_c = np.array([setpoints_from_shape(q.c) for q, _ in history.experiments])
    pure_c = np.array([e.c for e in pure.experiments])
    np.testing.assert_allclose(ros_c, pure_c, atol=1e-9)
    # The controller applies a setpoint change when its message arrives, a few samples after the optimizer's
    # decision; the pure runner applies it at the next sample. One-lap costs therefore agree to about 1 % (seen:
    # 0.1-0.7 %), not bit for bit; the setpoint sequence agrees far closer.
    ros_cost = [r.cost for _, r in history.experiments]
    np.testing.assert_allclose(ros_cost, [e.outcome.cost for e in pure.experiments], rtol=2e-2)
    c_next = setpoints_from_shape(history.iterations[0].c_next)
    np.testing.assert_allclose(c_next, pure.iterates[1], atol=np.radians(0.25))
    print("c_next ROS - pure (deg):", np.degrees(c_next - pure.iterates[1]))
    assert "done: 1 iterations" in out


def test_killed_optimizer_resumes_from_its_database(probe, ros_env, tmp_path):
    db = tmp_path / "rto.sqlite"
    opt, ctrl, plant = start_graph(probe, db, ros_env)
    try:
        def some_done():
            return db.exists() and stored(db)[1]["experiments"] >= 2
        assert probe.spin_until(some_done, 600.0)
        os.killpg(opt.pid, signal.SIGKILL)                 # no clean shutdown
        opt.wait()
        done_before = {q.request_id for q, _ in stored(db)[0].experiments}
        opt2 = start_node("optimizer", {"db": str(db), **SHORT}, ros_env)
        assert probe.spin_until(lambda: opt2.poll() is not None, 600.0), "restarted optimizer did not finish"
        assert opt2.returncode == 0
    finally:
        out = stop(opt2) if "opt2" in locals() else ""
        stop(plant)
        stop(ctrl)
    history, counts = stored(db)
    ids = [q.request_id for q, _ in history.experiments]
    assert counts == {"experiments": 4, "iterations": 1}
    assert len(set(ids)) == 4 and done_before <= set(ids)
    assert f"resumed from {db}: {len(done_before)} experiments" in out
