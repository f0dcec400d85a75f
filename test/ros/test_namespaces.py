"""Relative names and namespaces: two kite graphs (/kite1, /kite2) in one ROS domain, each flying its own
setpoints on its own clock (issue #17 item 2; docs/network.md *Two kites in one domain*)."""
import argparse
import math

import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from nav_msgs.msg import Path
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from kite_rto.flight.closed_loop import make_closed_loop, run_closed_loop
from kite_rto.flight.path import Setpoints
from kite_rto.runtime.sources import parse_source
from kite_rto.nodes import topics as T
from kite_rto.nodes.interface import LATCHED, stamp_to_ns
from kite_rto.nodes.namespace import (GRAPH_CLOCK_RULE, NamespaceError, add_namespace_option, check_namespace,
                                      namespace_args, tool_ros_args, with_graph_clock)
from kite_rto.tools.graph import node_command
from kite_rto.tools.record import parse_args as record_args

from rosutil import Probe, start_node, stop

DEEP = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)   # the probe must not drop samples


# ------------------------------------------------------------------------------------------------ names, pure
def test_topic_names_are_relative():
    constants = {getattr(T, n) for n in T.__all__ if n.isupper() and isinstance(getattr(T, n), str)}
    assert set(T.ALL) == constants and len(T.ALL) == len(constants)
    for name in T.ALL:
        assert not name.startswith("/") and not name.startswith("~"), name
        assert T.graph_name(name) == "/" + name and T.relative(T.graph_name(name)) == name
    assert T.CLOCK == "clock" and T.STATE == "kite/state" and T.SETPOINTS == "rto/setpoints"


@pytest.mark.parametrize("good", ["/", "/kite2", "/field/kite_1"])
def test_namespace_accepted(good):
    assert check_namespace(good) == good


@pytest.mark.parametrize("bad", ["kite2", "/kite2/", "/2kite", "/kite-2", "", "//kite"])
def test_namespace_refused_with_the_value(bad):
    with pytest.raises(NamespaceError) as err:
        check_namespace(bad)
    assert f"namespace {bad!r}: expected / or an absolute ROS namespace" in str(err.value)


def test_namespace_arguments():
    assert namespace_args(None) == namespace_args("/") == []
    assert namespace_args("/kite2") == ["--ros-args", "-r", "__ns:=/kite2"]
    assert with_graph_clock(["x"]) == ["x", "--ros-args", "-r", GRAPH_CLOCK_RULE]
    # the user's own rules come first (rcl applies the first rule that matches)
    assert tool_ros_args("kite_echo", ["/kite/state", "--ros-args", "-r", "/clock:=/sim"], "/kite2") == [
        "kite_echo", "/kite/state", "--ros-args", "-r", "/clock:=/sim", "--ros-args", "-r", "__ns:=/kite2",
        "--ros-args", "-r", GRAPH_CLOCK_RULE]
    assert node_command("plant", {"seed": 1}, "/kite2")[-4:] == ["-r", "__ns:=/kite2", "-p", "seed:=1"]
    assert "__ns:=/" not in " ".join(node_command("plant", {}, "/"))
    ap = argparse.ArgumentParser()
    add_namespace_option(ap)
    assert ap.parse_args(["--namespace", "/kite2"]).namespace == "/kite2"
    with pytest.raises(SystemExit):
        ap.parse_args(["--namespace", "kite2"])
    assert record_args(["--out", "x.mcap", "--topics", "/kite/state", "rto/setpoints"]).topics == [T.STATE,
                                                                                                   T.SETPOINTS]


def test_setpoint_source_resolves_in_the_controllers_namespace():
    assert parse_source("*", "/kite2") is None
    assert parse_source("optimizer") == "/optimizer"
    assert parse_source("optimizer", "/kite2") == "/kite2/optimizer"
    assert parse_source("/optimizer", "/kite2") == "/optimizer"              # fully qualified stays as given


# ------------------------------------------------------------------------------ the clock remap, in rclpy
@pytest.mark.parametrize("args,expected", [([], "/clock"), (["-r", "__ns:=/kite2"], "/kite2/clock"),
                                           (["-r", "__ns:=/kite2", "-r", "/clock:=/sim/clock"], "/sim/clock")],
                         ids=["root", "namespace", "user-remap-wins"])
def test_time_source_follows_the_graphs_clock(args, expected):
    """rclpy's time source subscribes the absolute /clock; with the rule the nodes add it resolves to the graph's
    clock, and a user's own /clock remap wins."""
    ctx = Context()
    rclpy.init(args=with_graph_clock(["node", "--ros-args", *args]), context=ctx)
    try:
        node = Node("clock_check", context=ctx, parameter_overrides=[Parameter("use_sim_time", value=True)])
        assert node.resolve_topic_name("/clock") == expected
        assert node.resolve_topic_name(T.CLOCK) == ("/clock" if not args else "/kite2/clock")   # the plant's
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


# ------------------------------------------------------------------------------ two graphs in one domain
GRAPHS = {"/kite1": {"seed": 3, "c": (32.0, 46.0, 7.0), "new": (34.0, 50.0, 8.0)},
          "/kite2": {"seed": 8, "c": (37.0, 54.0, 8.0), "new": (31.0, 44.0, 6.5)}}
DURATION = 6.0                       # simulated s of the first flight: 300 samples per graph
SECOND = 2.0                         # simulated s of the second flight, on the new setpoints
STEP = 20_000_000                    # sample time, ns


@pytest.fixture
def probe():
    p = Probe("ns_probe")
    yield p
    p.close()


def _setpoints(deg):
    return JointState(name=["theta_0", "A_phi", "A_theta"], position=list(Setpoints.from_degrees(*deg).as_array()))


def _mean_theta(path):
    return np.mean([math.atan2(math.hypot(p.pose.position.y, p.pose.position.z), p.pose.position.x)
                    for p in path.poses])


def _fmt(c):
    return f"theta_0 {c[0]:.1f} deg, A_phi {c[1]:.1f} deg"


@pytest.mark.ros
def test_two_namespaced_graphs_in_one_domain(probe, ros_env):
    """Plant + controller in /kite1 and in /kite2, lockstep, one domain. First flight: each controller flies the
    setpoints it was started with, bit for bit the pure closed loop of its setpoints and seed, on its own clock.
    Then the test publishes new setpoints on each <ns>/rto/setpoints and restarts both plants: each controller's
    reference path ends on its own graph's new setpoints. No node warns about a second plant or setpoint publisher."""
    n = probe.node
    steering = {ns: {} for ns in GRAPHS}
    clocks = {ns: [] for ns in GRAPHS}
    paths = {ns: [] for ns in GRAPHS}
    states = {ns: set() for ns in GRAPHS}
    pubs = {}
    for ns in GRAPHS:
        n.create_subscription(JointState, f"{ns}/kite/steering",
                              lambda m, s=steering[ns]: s.setdefault(stamp_to_ns(m.header.stamp), m.position[0]), DEEP)
        n.create_subscription(Clock, f"{ns}/clock", lambda m, c=clocks[ns]: c.append(stamp_to_ns(m.clock)), DEEP)
        n.create_subscription(JointState, f"{ns}/kite/state",
                              lambda m, s=states[ns]: s.add(stamp_to_ns(m.header.stamp)), DEEP)
        n.create_subscription(Path, f"{ns}/kite/reference_path", paths[ns].append, LATCHED)
        pubs[ns] = n.create_publisher(JointState, f"{ns}/rto/setpoints", LATCHED)     # used after the 1st flight
    ctrls, plants, plant_out, root_clock = {}, {}, {}, []

    def fly(duration):
        for ns, g in GRAPHS.items():
            # the plant starts once the controller and the probe listen to its /kite/state
            plants[ns] = start_node("plant", {"seed": g["seed"], "duration": duration, "wait_subscribers": 2},
                                    ros_env, namespace=ns)
        assert probe.spin_until(lambda: all(len(s) >= 20 for s in steering.values())
                                or any(p.poll() is not None for p in plants.values()), 300.0)
        root_clock.append(n.count_publishers("/clock"))
        for ns, p in plants.items():
            assert probe.spin_until(lambda: p.poll() is not None, 300.0), f"plant {ns} did not finish"
            plant_out[ns] = plant_out.get(ns, "") + stop(p)
            assert p.returncode == 0, plant_out[ns]

    try:
        for ns, g in GRAPHS.items():
            c = dict(zip(("theta_0_deg", "A_phi_deg", "A_theta_deg"), g["c"]))
            ctrls[ns] = start_node("controller", {**c, "use_sim_time": True}, ros_env, namespace=ns)
        for ns in GRAPHS:
            assert probe.spin_until(lambda: n.count_publishers(f"{ns}/kite/steering") > 0
                                    and pubs[ns].get_subscription_count() > 0, 60.0), stop(ctrls[ns])
        n_steps = round(DURATION / 0.02)
        fly(DURATION)
        probe.spin_until(lambda: all(len(s) >= n_steps for s in steering.values()), 30.0)
        first = {ns: dict(s) for ns, s in steering.items()}
        clock_subs = {ns: sorted((i.node_namespace, i.node_name) for i in n.get_subscriptions_info_by_topic(
            f"{ns}/clock")) for ns in GRAPHS}
        root_clock_subs = [(i.node_namespace, i.node_name) for i in n.get_subscriptions_info_by_topic("/clock")]
        for ns, g in GRAPHS.items():
            pubs[ns].publish(_setpoints(g["new"]))              # to the matched controller of that graph only
        fly(SECOND)                                             # a restarted plant: the controller takes it
        # each controller's reference path ends on its own new setpoints (published within 0.5 s wall of the change)
        probe.spin_until(lambda: all(paths[ns] and abs(_mean_theta(paths[ns][-1]) - math.radians(g["new"][0])) < 2e-3
                                     for ns, g in GRAPHS.items()), 30.0)
    finally:
        for ns, p in plants.items():
            plant_out[ns] = plant_out.get(ns, "") + stop(p)
        ctrl_out = {ns: stop(p) for ns, p in ctrls.items()}
    for ns, g in GRAPHS.items():
        pure_plant, controller = make_closed_loop(Setpoints.from_degrees(*g["c"]), seed=g["seed"])
        ref = run_closed_loop(pure_plant, controller, DURATION)
        got = np.array([first[ns].get(k * STEP, np.nan) for k in range(len(ref.delta))])
        assert not np.isnan(got).any(), f"{ns}: missing answers: {np.isnan(got).sum()}"
        np.testing.assert_array_equal(got, ref.delta)                           # its own setpoints, bit for bit
        assert paths[ns], f"{ns}: no reference path"
        assert _mean_theta(paths[ns][-1]) == pytest.approx(math.radians(g["new"][0]), abs=2e-3), ns
        other = next(o for o in GRAPHS if o != ns)
        for c in (GRAPHS[other]["c"], GRAPHS[other]["new"]):
            assert _fmt(c) not in ctrl_out[ns], ctrl_out[ns]
        # its own clock: the ticks heard (from when the probe matched the plant's clock writer) are its samples'
        assert len(states[ns]) >= n_steps and clocks[ns], (len(states[ns]), len(clocks[ns]))
        assert set(clocks[ns]) <= states[ns] and max(clocks[ns]) == max(states[ns])
        # the controller's time source (use_sim_time) follows its graph's clock, not /clock
        assert (ns, "controller") in clock_subs[ns], clock_subs
        # no node saw the other graph: no second plant, no foreign setpoint publisher, nothing refused
        for out in (plant_out[ns], ctrl_out[ns]):
            assert "another publisher of" not in out and "publishers of" not in out, out
            assert "refusing to start" not in out and "another plant" not in out, out
    assert root_clock == [0, 0] and not [s for s in root_clock_subs if s[0] in GRAPHS], root_clock_subs
