"""Controller node over real DDS: same trajectory as the pure runner, setpoint handling, lap statistics."""
import math

import numpy as np
import pytest
from nav_msgs.msg import Path
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from kite_rto.flight.closed_loop import make_closed_loop, run_closed_loop
from kite_rto.flight.path import DEFAULT_SETPOINTS, Setpoints
from kite_rto.nodes.interface import LATCHED, RELIABLE_10, stamp_to_ns

from rosutil import Probe, start_node, stop

pytestmark = pytest.mark.ros
DURATION = 45.0
DEEP = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)   # the probe must not drop samples


@pytest.fixture
def probe():
    p = Probe()
    yield p
    p.close()


def setpoint_msg(values):
    return JointState(name=["theta_0", "A_phi", "A_theta"], position=[float(v) for v in values])


@pytest.mark.parametrize("sync", [False, True], ids=["plain", "sync-without-optimizer"])
def test_dds_lockstep_matches_pure_runner(probe, ros_env, sync):
    """Bit for bit like the pure closed loop, also with sync_optimizer and no optimizer in the graph."""
    steering = {}
    probe.node.create_subscription(JointState, "/kite/steering",
                                   lambda m: steering.setdefault(stamp_to_ns(m.header.stamp), m.position[0]),
                                   DEEP)
    laps = []
    probe.node.create_subscription(JointState, "/kite/laps", laps.append, RELIABLE_10)
    ctrl = start_node("controller", {"sync_optimizer": sync}, ros_env)
    # the probe must hear the controller before the plant starts the loop
    assert probe.spin_until(lambda: probe.node.count_publishers("/kite/steering") > 0, 60.0)
    probe.spin_until(lambda: False, 1.0)
    plant = start_node("plant", {"seed": 5, "duration": DURATION}, ros_env)
    try:
        assert probe.spin_until(lambda: plant.poll() is not None, 300.0), "plant did not finish"
        n_steps = round(DURATION / 0.02)
        probe.spin_until(lambda: len(steering) >= n_steps and laps, 30.0)
        assert plant.returncode == 0
    finally:
        stop(plant)
        out = stop(ctrl)
    c = Setpoints.from_degrees(*DEFAULT_SETPOINTS.degrees())       # what the node builds from its parameters
    pure_plant, controller = make_closed_loop(c, seed=5)
    ref = run_closed_loop(pure_plant, controller, DURATION)
    n = len(ref.delta)
    got = np.array([steering.get(k * 20_000_000, np.nan) for k in range(n)])
    assert not np.isnan(got).any(), f"missing answers: {np.isnan(got).sum()}"
    np.testing.assert_array_equal(got, ref.delta)                  # bit for bit
    assert laps and list(laps[0].name)[:3] == ["lap", "lap_time", "mean_tension"], out
    assert laps[0].position[2] > 1e5                                # mean tension, N
    # with sync_optimizer and no optimizer in the graph, the first sample waits 1 s, then it flies on its own
    assert out.count("no optimizer in the graph") == (1 if sync else 0), out


def test_setpoints_late_joiner_rejection_and_path(probe, ros_env):
    pub = probe.node.create_publisher(JointState, "/rto/setpoints", LATCHED)
    paths = []
    probe.node.create_subscription(Path, "/kite/reference_path", paths.append, LATCHED)
    good = Setpoints.from_degrees(33.0, 46.0, 7.0).as_array()
    pub.publish(setpoint_msg(good))                                 # before the controller exists
    ctrl = start_node("controller", {}, ros_env)
    plant = start_node("plant", {"command_timeout": 30.0}, ros_env)
    try:
        def mean_theta(path):
            return np.mean([math.atan2(math.hypot(p.pose.position.y, p.pose.position.z), p.pose.position.x)
                            for p in path.poses])
        assert probe.spin_until(lambda: paths and abs(mean_theta(paths[-1]) - good[0]) < 2e-3, 60.0), \
            "no path for the latched setpoints"
        n_paths = len(paths)
        for bad in ([math.nan, 0.8, 0.12], [0.6, 0.8, 0.9], [0.1, 0.2]):
            pub.publish(JointState(name=["theta_0", "A_phi", "A_theta"][:len(bad)], position=bad))
            probe.spin_until(lambda: False, 0.5)
        probe.spin_until(lambda: False, 1.0)
        assert len(paths) == n_paths                                 # no new path for bad setpoints
    finally:
        stop(plant)
        out = stop(ctrl)
    assert "new setpoints theta_0 33.0 deg, A_phi 46.0 deg" in out
    assert out.count("rejected setpoints") >= 1 and "rejected setpoints message" in out
    assert "nan" in out.lower()


@pytest.mark.parametrize("arg,needle", [("theta_0_deg:=95.0", "parameter theta_0_deg = 95.0"),
                                        ("box_A_phi_deg:=[50.0,40.0]", "parameter box_A_phi_deg = [50.0, 40.0]"),
                                        ("theta_0_deg:=20.0", "initial setpoints"),
                                        ("setpoint_source:=1optimizer", "parameter setpoint_source = '1optimizer'")])
def test_bad_parameters_stop_the_controller(arg, needle, ros_env):
    import subprocess
    import sys
    res = subprocess.run([sys.executable, "-m", "kite_rto.nodes.controller_node", "--ros-args", "-p", arg],
                         env=ros_env, capture_output=True, text=True, timeout=60)
    assert res.returncode == 2, res.stderr
    assert needle in res.stderr
