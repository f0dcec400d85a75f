"""Optimizer node over real DDS: the synchronized graph flies the pure runner's sequence; a killed optimizer resumes."""
import os
import signal
import time
from dataclasses import replace

import numpy as np
import pytest

from kite_rto.rto.experiment import ExperimentSpec
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.rto.runner import run_rto
from kite_rto.kite.plant import PlantConfig
from kite_rto.flight.shape import setpoints_from_shape
from geometry_msgs.msg import Vector3Stamped
from std_msgs.msg import String

from kite_rto.gma import HistoryStore
from kite_rto.nodes.interface import LATCHED, LATCHED_10, MEASUREMENTS, stamp_to_ns
from kite_rto.rto.run import RunDescription
from kite_rto.runtime.run_description import plant_json
from kite_rto.tools.compare_pure import compare_histories
from kite_rto.tools.rto_report import run_of

from rosutil import Probe, start_node, stop

PER = KiteRTOSettings().experiments_per_iteration()   # experiments of one GMA iteration

pytestmark = pytest.mark.ros
QUIET = {"turbulence": False, "anemometer_noise": 0.0, "noise_angle_deg": 0.0, "noise_rate": 0.0, "noise_tension": 0.0}
SHORT = {"n_laps": 1, "settle_laps": 0, "n_iter": 1, "exit_when_done": True}


@pytest.fixture
def probe():
    p = Probe()
    yield p
    p.close()


def start_graph(probe, db, ros_env, sync=False, plant=None, n_iter=1):
    """Optimizer first (it publishes the first setpoints), then controller, then plant (waits for both to subscribe)."""
    opt = start_node("optimizer", {"db": str(db), **SHORT, "n_iter": n_iter}, ros_env)
    assert probe.spin_until(lambda: probe.node.count_publishers("/rto/setpoints") > 0, 120.0)
    ctrl = start_node("controller", {"sync_optimizer": sync}, ros_env)
    assert probe.spin_until(lambda: probe.node.count_publishers("/kite/steering") > 0, 60.0)
    plant = start_node("plant", {**(QUIET if plant is None else plant), "wait_subscribers": 2}, ros_env)
    return opt, ctrl, plant


def stored(db):
    store = HistoryStore(db)
    try:
        return store.load(), store.counts()
    finally:
        store.close()


@pytest.mark.parametrize("plant_params, config, n_iter", [
    (QUIET, PlantConfig().without_disturbances(), 1),
    ({"seed": 3}, PlantConfig(), 2),
], ids=["deterministic", "turbulent-seed-3"])
def test_graph_flies_the_pure_runners_sequence(probe, ros_env, tmp_path, plant_params, config, n_iter):
    """With the controller synchronized to the optimizer (lockstep), the three processes fly exactly what
    run_rto flies: the same experiments, bit-identical measured costs and the same GMA iterates."""
    db = tmp_path / "rto.sqlite"
    estimates = []                     # /kite/wind_estimate: the wind the cost is normalized by, per sample
    probe.node.create_subscription(Vector3Stamped, "/kite/wind_estimate", lambda m: estimates.append(
        (stamp_to_ns(m.header.stamp), m.vector.x)), MEASUREMENTS)
    opt, ctrl, plant = start_graph(probe, db, ros_env, sync=True, plant=plant_params, n_iter=n_iter)
    try:
        assert probe.spin_until(lambda: opt.poll() is not None, 600.0), "optimizer did not finish"
        assert opt.returncode == 0
    finally:
        out = stop(opt)
        stop(plant)
        ctrl_out = stop(ctrl)
    history, counts = stored(db)
    assert counts == {"experiments": PER * n_iter, "iterations": n_iter}, out
    settings = KiteRTOSettings(experiment=ExperimentSpec(n_laps=1, settle_laps=0))
    pure = run_rto(config, seed=plant_params.get("seed", 0), n_iter=n_iter, settings=settings)
    ros_c = np.array([setpoints_from_shape(q.c) for q, _ in history.experiments])
    ros_cost = [r.cost for _, r in history.experiments]
    ros_next = np.array([setpoints_from_shape(rec.c_next) for rec in history.iterations])
    print("setpoints ROS - pure (rad):", ros_c - [e.c for e in pure.experiments], "costs ROS - pure (kN):",
          np.subtract(ros_cost, [e.outcome.cost for e in pure.experiments]),
          "iterates ROS - pure (rad):", ros_next - pure.iterates[1:])
    diffs = compare_histories(history, pure.history)
    print(f"{len(diffs)} fields differ from the pure runner:", *diffs[:40], sep="\n  ")
    np.testing.assert_array_equal(ros_c, [e.c for e in pure.experiments])
    np.testing.assert_array_equal(ros_cost, [e.outcome.cost for e in pure.experiments])
    np.testing.assert_array_equal(ros_next, pure.iterates[1:])
    assert not diffs, "the stored history differs from the pure runner's (see the printed fields)"
    assert f"done: {n_iter} iterations" in out
    assert "no optimizer in the graph" not in ctrl_out, ctrl_out      # never released a sample unsynchronized
    stamps = np.array([s for s, _ in estimates])
    winds = np.array([w for _, w in estimates])
    assert len(estimates) > 1000 and np.all(np.diff(stamps) > 0) and np.all(stamps % 20_000_000 == 0)
    assert np.all(np.isfinite(winds)) and 1.0 < np.median(winds) < 20.0, np.percentile(winds, [0, 50, 100])


def test_killed_optimizer_resumes_from_its_database(probe, ros_env, tmp_path):
    db = tmp_path / "rto.sqlite"
    opt, ctrl, plant = start_graph(probe, db, ros_env, sync=True)
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
        ctrl_out = stop(ctrl)
    history, counts = stored(db)
    ids = [q.request_id for q, _ in history.experiments]
    assert counts == {"experiments": PER, "iterations": 1}
    assert len(set(ids)) == PER and done_before <= set(ids)
    assert f"resumed from {db}: {len(done_before)} experiments" in out
    # the synchronized controller waited for the restarted optimizer (its /rto/sync) or, if the restart took longer
    # than the liveliness lease, flew on unsynchronized and synchronized again with the new one
    assert ("steering unsynchronized" in ctrl_out) <= ("/rto/sync is back" in ctrl_out), ctrl_out
    assert "Traceback" not in ctrl_out, ctrl_out


def test_the_run_description_names_the_plant_and_survives_bad_messages(probe, ros_env, tmp_path):
    """The optimizer stores and publishes its run's description: its settings (h_min 115 m) from the start, the
    plant's configuration (w_ref 9 m/s) once the plant publishes it, which is what ``kite_report --db`` judges
    against. Bad /kite/plant_config messages are rejected with a warning and the optimizer takes the next good one.
    Restarted without a plant, it keeps the stored description."""
    db = tmp_path / "rto.sqlite"
    runs = []
    probe.node.create_subscription(String, "/rto/run", lambda m: runs.append(RunDescription.from_json(m.data)),
                                   LATCHED)
    params = {"db": str(db), **SHORT, "h_min": 115.0}
    opt = start_node("optimizer", params, ros_env)
    plant = opt2 = None
    try:
        assert probe.spin_until(lambda: runs, 120.0), "the optimizer published no /rto/run"
        assert runs[0].plant is None and runs[0].h_min == 115.0
        assert run_of(stored(db)[0]) == runs[0]                     # stored with the run's start
        plant = start_node("plant", {**QUIET, "w_ref": 9.0}, ros_env)
        assert probe.spin_until(lambda: runs[-1].plant is not None, 60.0), "the plant's configuration never came"
        flown = runs[-1].plant
        assert flown.params.w_ref == 9.0 and not flown.turbulence.enabled and runs[-1].h_min == 115.0
        judged = run_of(stored(db)[0])                              # what kite_report --db judges against
        assert judged == runs[-1] and judged.plant.params.w_ref == 9.0 and judged.h_min == 115.0

        other = replace(flown, params=replace(flown.params, w_ref=9.5))
        pub = probe.node.create_publisher(String, "/kite/plant_config", LATCHED_10)
        for text in ('{"dt": "fast"}', "not json", plant_json(other)):     # in order, on one reliable writer
            pub.publish(String(data=text))
        assert probe.spin_until(lambda: runs[-1].plant == other, 60.0), "the optimizer stopped taking configurations"
        assert run_of(stored(db)[0]).plant == other
        out = stop(opt)
        assert """rejected plant configuration '{"dt": "fast"}': not a PlantConfig (PlantConfig.dt = 'fast': """ \
               "expected a number)" in out, out[-3000:]
        assert "changed during the run" in out and "Traceback" not in out, out[-3000:]

        stop(plant)
        probe.node.destroy_publisher(pub)
        runs.clear()
        opt2 = start_node("optimizer", params, ros_env)          # resumes the run; no plant in the graph
        assert probe.spin_until(lambda: runs, 120.0), "the restarted optimizer published no /rto/run"
        assert runs == [RunDescription(runs[0].settings, other)] and run_of(stored(db)[0]).plant == other
    finally:
        for proc in (opt, plant, opt2):
            if proc is not None:
                stop(proc)

