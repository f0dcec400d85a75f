"""The optimizer as a lifecycle node over real DDS, driven by kite_ctl: paused mid-experiment it holds its
setpoints while the lockstep graph flies on, takes a manual setpoint (and refuses one outside the box), resumes and
finishes its iteration with nothing lost or repeated in the database; a restart while paused comes back paused."""
import os
import re
import signal
import subprocess
import sys
from collections import Counter

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from kite_rto.flight.shape import setpoints_from_shape, shape_from_setpoints
from kite_rto.gma import HistoryStore
from kite_rto.nodes.interface import LATCHED, MEASUREMENTS, RELIABLE_10, stamp_to_ns
from kite_rto.runtime.operator_log import MANUAL, TRANSITION
from kite_rto.rto.settings import KiteRTOSettings

from rosutil import Probe, start_node, stop

pytestmark = pytest.mark.ros
PER = KiteRTOSettings().experiments_per_iteration()
QUIET = {"turbulence": False, "anemometer_noise": 0.0, "noise_angle_deg": 0.0, "noise_rate": 0.0, "noise_tension": 0.0}
SHORT = {"n_laps": 1, "settle_laps": 0, "n_iter": 1, "exit_when_done": True}
HOLD = 60.0                                          # simulated s the paused optimizer must hold its setpoints
MANUAL_DEG = (33.0, 50.0, 7.5)


def ctl(env, *args, timeout=30.0):
    """Run ``kite_ctl`` (python -m kite_rto.tools.kite_ctl); (exit code, stdout + stderr)."""
    p = subprocess.run([sys.executable, "-m", "kite_rto.tools.kite_ctl", *args, "--timeout", "60"], env=env,
                       capture_output=True, text=True, timeout=timeout + 120)
    return p.returncode, p.stdout + p.stderr


def stored(db):
    store = HistoryStore(db)
    try:
        return store.load(), store.counts(), store.events()
    finally:
        store.close()


@pytest.fixture
def probe():
    p = Probe("lifecycle_probe")
    yield p
    p.close()


class Watch:
    """The probe's view: sim time, the setpoints in force per synced sample, /rto/setpoints, the status."""

    def __init__(self, probe):
        self.t, self.sync, self.setpoints, self.status = 0.0, [], [], {}
        n = probe.node
        n.create_subscription(Clock, "/clock", lambda m: setattr(self, "t", stamp_to_ns(m.clock) * 1e-9), 10)
        n.create_subscription(JointState, "/rto/sync", lambda m: self.sync.append(
            (stamp_to_ns(m.header.stamp) * 1e-9, tuple(m.position[:3]))), MEASUREMENTS)
        n.create_subscription(JointState, "/rto/setpoints", lambda m: self.setpoints.append(tuple(m.position)),
                              LATCHED)
        n.create_subscription(DiagnosticArray, "/rto/status", lambda m: self.status.update(
            {kv.key: kv.value for kv in m.status[0].values}, message=m.status[0].message), RELIABLE_10)


def test_pause_hold_manual_setpoint_resume(probe, ros_env, tmp_path):
    db = tmp_path / "rto.sqlite"
    w = Watch(probe)
    opt = start_node("optimizer", {"db": str(db), **SHORT, "autostart": False}, ros_env)
    ctrl = plant = None
    try:
        code, out = ctl(ros_env, "state")
        assert (code, out.strip()) == (0, "unconfigured"), out
        code, out = ctl(ros_env, "activate")                      # not possible from unconfigured
        assert code == 1 and "activate refused: the optimizer is unconfigured" in out, out
        assert ctl(ros_env, "configure") == (0, "configure: unconfigured -> inactive\n")
        assert ctl(ros_env, "resume") == (0, "activate: inactive -> active\n")
        assert probe.spin_until(lambda: w.setpoints, 300.0), "no setpoints after configure + activate"
        ctrl = start_node("controller", {"sync_optimizer": True}, ros_env)
        assert probe.spin_until(lambda: probe.node.count_publishers("/kite/steering") > 0, 60.0)
        plant = start_node("plant", {**QUIET, "wait_subscribers": 2}, ros_env)

        # Freeze the plant (SIGSTOP) as soon as the second experiment's (other) setpoints are out: the lockstep loop
        # stops at a sample of that experiment, so the pause lands mid-experiment however slowly kite_ctl starts.
        assert probe.spin_until(lambda: len(set(w.setpoints)) >= 2, 600.0), f"no second experiment: {w.status}"
        os.killpg(plant.pid, signal.SIGSTOP)
        try:
            code, out = ctl(ros_env, "pause")
            assert (code, out) == (0, "deactivate: active -> inactive\n"), out
            assert probe.spin_until(lambda: w.status.get("lifecycle") == "inactive", 60.0)
            done_before = [q.request_id for q, _ in stored(db)[0].experiments]
            t_frozen = w.t
        finally:
            os.killpg(plant.pid, signal.SIGCONT)
        # The setpoints held: what a subscriber joining now gets from the latched /rto/setpoints (the last message
        # published before the pause; the probe's own list may still be short of it under load).
        latest = []
        probe.node.create_subscription(JointState, "/rto/setpoints", lambda m: latest.append(tuple(m.position)),
                                       LATCHED)
        assert probe.spin_until(lambda: latest, 60.0), "no latched /rto/setpoints"
        held = latest[-1]
        assert probe.spin_until(lambda: w.setpoints and w.setpoints[-1] == held, 60.0), (held, w.setpoints)
        n_setpoints = len(w.setpoints)
        # When the pause began, in sim time: the probe's /clock, or, if the probe had not heard the plant's clock yet
        # (discovery under load), the first synced sample flying the held setpoints (at or before the pause).
        assert probe.spin_until(lambda: any(c == held for _, c in w.sync), 600.0), "the held setpoints never flown"
        t_pause = max(t_frozen, min(s for s, c in w.sync if c == held))
        assert probe.spin_until(lambda: w.t > t_pause + HOLD + 2.0, 600.0), "the lockstep loop stalled while paused"
        # /rto/sync comes on another topic than /clock: wait until the probe has heard it past the hold too
        assert probe.spin_until(lambda: w.sync and w.sync[-1][0] > t_pause + HOLD + 1.0, 600.0), "no /rto/sync"
        # every /rto/sync the probe heard over the 60 s carries the held setpoints (a busy probe may miss some; the
        # plant's clock passing t_pause + 60 s in lockstep shows that the controller got them all)
        during = [c for s, c in w.sync if t_pause < s <= t_pause + HOLD]
        assert during and max(s for s, _ in w.sync) > t_pause + HOLD - 1.0, "no /rto/sync while paused"
        assert all(np.array_equal(c, held) for c in during), \
            f"the setpoints changed while paused: held {held}, heard {Counter(during)} after t = {t_pause} s"
        assert len(w.setpoints) == n_setpoints, "new setpoints while paused"
        assert [q.request_id for q, _ in stored(db)[0].experiments] == done_before, "an experiment stored while paused"
        code, out = ctl(ros_env, "setpoint", "20", "50", "7.5")    # theta_0 below the box
        assert code == 1 and "theta_0" in out and "20" in out, out
        code, out = ctl(ros_env, "setpoint", *map(str, MANUAL_DEG))
        assert code == 0 and "accepted (33.00, 50.00, 7.50) deg" in out, out
        manual = setpoints_from_shape(shape_from_setpoints(np.radians(MANUAL_DEG)))
        assert probe.spin_until(lambda: np.allclose(w.setpoints[-1], manual, rtol=0, atol=1e-12), 60.0)
        assert probe.spin_until(lambda: w.sync and np.allclose(w.sync[-1][1], manual, rtol=0, atol=1e-12), 60.0), \
            "the controller was not handed the manual setpoints"
        assert ctl(ros_env, "resume") == (0, "activate: inactive -> active\n")
        assert probe.spin_until(lambda: opt.poll() is not None, 900.0), "the resumed run did not finish"
        assert opt.returncode == 0
    finally:
        out = stop(opt)
        for p in (plant, ctrl):
            if p is not None:
                stop(p)
    history, counts, events = stored(db)
    ids = [q.request_id for q, _ in history.experiments]
    interrupted = re.search(r"the experiment in progress \((\S+)\) is discarded", out).group(1)
    assert len(ids) == len(set(ids)), f"an experiment stored twice: {ids}"
    # the experiments finished before the pause stay; the interrupted one is gone; the manual point's iteration
    # follows (the second experiment or, on a machine too busy to freeze the plant in time, a later one of k0)
    assert 1 <= len(done_before) < PER and interrupted == f"k0-{len(done_before)}-perturbation", (done_before, out)
    assert ids[:len(done_before)] == done_before and interrupted not in ids, ids
    assert ids[len(done_before):] == [f"k0m1-{j}-{'nominal' if j == 0 else 'perturbation'}" for j in range(PER)]
    assert counts == {"experiments": len(done_before) + PER, "iterations": 1}
    assert np.allclose(history.iterations[0].c_k, shape_from_setpoints(np.radians(MANUAL_DEG)), rtol=0, atol=1e-12)
    kinds = [(k, d.get("transition")) for k, d, _ in events]
    assert kinds == [(TRANSITION, "configure"), (TRANSITION, "activate"), (TRANSITION, "deactivate"),
                     (MANUAL, None), (TRANSITION, "activate")], kinds
    assert "refusing manual setpoints" in out and "Traceback" not in out, out


def test_restart_while_paused_comes_back_paused(probe, ros_env, tmp_path):
    db = tmp_path / "rto.sqlite"
    w = Watch(probe)
    opt = start_node("optimizer", {"db": str(db), **SHORT}, ros_env)          # autostart (the default)
    try:
        assert probe.spin_until(lambda: w.setpoints, 300.0)
        assert ctl(ros_env, "state") == (0, "active\n")
        assert ctl(ros_env, "pause") == (0, "deactivate: active -> inactive\n")
    finally:
        out1 = stop(opt)
    assert "lifecycle: deactivate: active -> inactive" in out1, out1
    w.setpoints.clear()
    opt = start_node("optimizer", {"db": str(db), **SHORT}, ros_env)
    try:
        assert probe.spin_until(lambda: w.setpoints, 300.0), "the paused optimizer does not hold its setpoints"
        assert probe.spin_until(lambda: w.status.get("lifecycle") == "inactive"
                                and w.status.get("message", "").startswith("paused"), 60.0), w.status
        assert ctl(ros_env, "state") == (0, "inactive\n")
        assert ctl(ros_env, "shutdown") == (0, "shutdown: inactive -> finalized\n")
        assert probe.spin_until(lambda: opt.poll() is not None, 60.0), "shutdown did not end the process"
        assert opt.returncode == 0
    finally:
        out2 = stop(opt)
    assert out2.count("says this run was paused") == 1, out2
    kinds = [d.get("transition") for k, d, _ in stored(db)[2]]
    assert kinds == ["configure", "activate", "deactivate", "configure", "shutdown"], kinds
