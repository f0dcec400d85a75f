"""Plant node over real DDS (isolated domain, localhost discovery)."""
import math
import subprocess
import sys
import time

import pytest
from geometry_msgs.msg import PointStamped, Vector3Stamped, WrenchStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from kite_rto.nodes.interface import MEASUREMENTS, RELIABLE_10, stamp_to_ns

from rosutil import Probe, start_node, stop

pytestmark = pytest.mark.ros

TOPICS = {"/clock": "rosgraph_msgs/msg/Clock", "/kite/state": "sensor_msgs/msg/JointState",
          "/kite/position": "geometry_msgs/msg/PointStamped", "/kite/tension": "geometry_msgs/msg/WrenchStamped",
          "/kite/wind": "geometry_msgs/msg/Vector3Stamped", "/kite/steering": "sensor_msgs/msg/JointState"}


@pytest.fixture
def probe():
    p = Probe()
    yield p
    p.close()


def test_documented_topics_and_types(probe, ros_env):
    proc = start_node("plant", {"turbulence": False}, ros_env)
    try:
        def found():
            have = dict(probe.node.get_topic_names_and_types())
            return all(t in have and TOPICS[t] in have[t] for t in TOPICS)
        assert probe.spin_until(found, 30.0), probe.node.get_topic_names_and_types()
    finally:
        stop(proc)


def test_lockstep_advances_one_step_per_answered_command(probe, ros_env):
    proc = start_node("plant", {"turbulence": False, "resend_period": 0.3, "command_timeout": 30.0}, ros_env)
    states, extra = [], {"tension": [], "position": [], "wind": [], "clock": []}
    n = probe.node
    steer = n.create_publisher(JointState, "/kite/steering", MEASUREMENTS)
    n.create_subscription(JointState, "/kite/state", states.append, RELIABLE_10)
    n.create_subscription(WrenchStamped, "/kite/tension", extra["tension"].append, RELIABLE_10)
    n.create_subscription(PointStamped, "/kite/position", extra["position"].append, RELIABLE_10)
    n.create_subscription(Vector3Stamped, "/kite/wind", extra["wind"].append, RELIABLE_10)
    n.create_subscription(Clock, "/clock", extra["clock"].append, 10)
    try:
        assert probe.spin_until(lambda: states, 30.0), stop(proc)
        answered = []
        for _ in range(25):
            last = states[-1]
            stamp = stamp_to_ns(last.header.stamp)
            cmd = JointState(name=["delta"], position=[0.1])
            cmd.header.stamp = last.header.stamp
            answered.append(stamp)
            # steering is best effort, as from the controller: a command lost on a busy machine is answered again
            # (for the same sample) until the plant steps, at most 60 s
            end = time.monotonic() + 60.0
            while True:
                steer.publish(cmd)
                if probe.spin_until(lambda: stamp_to_ns(states[-1].header.stamp) > stamp, 0.5):
                    break
                assert time.monotonic() < end, f"the plant did not step past {stamp} ns"
        # exactly one step (dt = 20 ms) per answered command
        assert [b - a for a, b in zip(answered, answered[1:])] == [20_000_000] * 24
        # without an answer the plant does not advance; it re-publishes the same sample
        before = stamp_to_ns(states[-1].header.stamp)
        count = len(states)
        probe.spin_until(lambda: False, 1.0)
        assert len(states) > count
        assert {stamp_to_ns(s.header.stamp) for s in states[count:]} == {before}
        s = states[-1]
        assert list(s.name) == ["theta", "phi", "psi"] and len(s.velocity) == 3
        assert all(math.isfinite(v) for v in s.position)
        assert extra["tension"][-1].wrench.force.x > 1e4
        assert extra["position"][-1].point.z > 0 and extra["position"][-1].header.frame_id == "anchor"
        assert extra["wind"][-1].vector.x > 0
        assert stamp_to_ns(extra["clock"][-1].clock) == before
    finally:
        stop(proc)


def test_realtime_mode_keeps_pace(probe, ros_env):
    proc = start_node("plant", {"mode": "realtime", "turbulence": False, "rate_factor": 2.0}, ros_env)
    clocks = []
    probe.node.create_subscription(Clock, "/clock", clocks.append, 10)
    try:
        assert probe.spin_until(lambda: clocks, 30.0)
        t0, w0 = stamp_to_ns(clocks[-1].clock) * 1e-9, time.monotonic()
        probe.spin_until(lambda: False, 3.0)
        sim = stamp_to_ns(clocks[-1].clock) * 1e-9 - t0
        wall = time.monotonic() - w0
        assert sim / wall == pytest.approx(2.0, rel=0.15)
    finally:
        out = stop(proc)
    assert "flying neutral" in out           # nobody steered: it says so


def test_lockstep_waits_for_a_pilot_in_the_graph_and_flies_neutral_once_none_is(probe, ros_env):
    """A silent steering writer in the graph (a controller waiting for a slow optimizer) holds the lockstep plant
    however long it takes; once no writer is in the graph (it left, or DDS dropped a killed one) the plant flies
    neutral after command_timeout and keeps its clock going."""
    proc = start_node("plant", {"turbulence": False, "command_timeout": 0.1, "duration": 1.0}, ros_env)
    states = []
    steer = probe.node.create_publisher(JointState, "/kite/steering", MEASUREMENTS)
    probe.node.create_subscription(JointState, "/kite/state", states.append, RELIABLE_10)
    try:
        assert probe.spin_until(lambda: states, 30.0)
        # the one answer must not go out before the plant's steering subscription has matched this writer
        # (volatile durability: a command published earlier is lost, and on a busy machine discovery lags)
        assert probe.spin_until(lambda: steer.get_subscription_count() > 0, 30.0)
        cmd = JointState(name=["delta"], position=[0.0])
        cmd.header.stamp = states[0].header.stamp
        steer.publish(cmd)                          # one answer, then silence from a writer in the graph
        assert probe.spin_until(lambda: any(stamp_to_ns(m.header.stamp) > 0 for m in states), 30.0)
        probe.spin_until(lambda: proc.poll() is not None, 3.0)      # 30x command_timeout: still waiting
        assert proc.poll() is None
        assert max(stamp_to_ns(m.header.stamp) for m in states) == 20_000_000      # one step, then held
        probe.node.destroy_publisher(steer)         # the pilot leaves the graph
        assert probe.spin_until(lambda: proc.poll() is not None, 60.0)
        assert proc.returncode == 0
    finally:
        out = stop(proc)
    assert "waiting" in out and "its controller is in the graph" in out
    assert "flying neutral" in out and "duration reached" in out


@pytest.mark.parametrize("arg,needle", [("E:=-1.0", "parameter E = -1.0"), ("mode:=fast", "parameter mode = 'fast'"),
                                        ("r:=abc", "parameter r = 'abc'"),
                                        ("c_E:=5.0", "KiteParams.c_E = 5.0")])
def test_bad_parameters_stop_the_node(arg, needle, ros_env):
    res = subprocess.run([sys.executable, "-m", "kite_rto.nodes.plant_node", "--ros-args", "-p", arg],
                         env=ros_env, capture_output=True, text=True, timeout=60)
    assert res.returncode == 2
    assert needle in res.stderr and "expected" in res.stderr
