"""The live 3-D view: kite_viz's /kite/markers on a running graph, kite_foxglove spoken to over the Foxglove WebSocket
protocol by a protocol-level client, and the shipped Foxglove and PlotJuggler layouts checked against the messages."""
import json
import re
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from geometry_msgs.msg import WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message
from visualization_msgs.msg import Marker, MarkerArray

from kite_rto.flight.scene import NAMESPACES, KiteView, build_scene
from kite_rto.nodes import topics as T
from kite_rto.nodes.controller_node import LAP_FIELDS
from kite_rto.tools.markers import marker_array
from kite_rto.tools.record import TOPICS

from rosutil import DIE_WITH_PARENT, Probe, start_node, stop
from ws_client import FoxgloveWsClient

PY = sys.executable
ROOT = Path(__file__).resolve().parents[2]


def test_marker_array_carries_the_scene():
    shapes = build_scene(KiteView(3.5, (300.0, 50.0, 250.0), psi=0.2), reference=[[0, 0, 1], [1, 1, 1], [2, 0, 1]],
                         trail=[[290.0, 40.0, 240.0], [300.0, 50.0, 250.0]], wind=8.0, h_min=100.0)
    back = deserialize_message(serialize_message(marker_array(shapes, 3_500_000_000)), MarkerArray)
    by = {m.ns: m for m in back.markers}
    assert set(by) == set(NAMESPACES)
    assert {m.header.frame_id for m in back.markers} == {"anchor"}
    assert {(m.header.stamp.sec, m.header.stamp.nanosec) for m in back.markers} == {(3, 500_000_000)}
    assert (by["kite"].type, by["tether"].type, by["wind"].type, by["h_min"].type, by["label"].type) == (
        Marker.TRIANGLE_LIST, Marker.LINE_STRIP, Marker.ARROW, Marker.CUBE, Marker.TEXT_VIEW_FACING)
    assert len(by["kite"].points) == 6 and by["h_min"].pose.position.z == 100.0
    assert (by["tether"].points[1].x, by["tether"].points[1].z) == (300.0, 250.0)
    assert all(m.action == Marker.ADD and m.lifetime.sec == 0 and m.pose.orientation.w == 1.0 for m in back.markers)


@pytest.mark.ros
def test_kite_viz_publishes_the_scene_on_simulated_time(ros_env):
    probe = Probe("viz_probe")
    got = []
    probe.node.create_subscription(MarkerArray, T.MARKERS, got.append, 100)
    viz = subprocess.Popen(
        [PY, "-m", "kite_rto.tools.viz", "--ros-args", "-p", "max_rate:=0.0"], env=ros_env,
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True, preexec_fn=DIE_WITH_PARENT)
    ctrl = plant = None
    out = ""
    try:
        assert probe.spin_until(lambda: probe.node.count_subscribers(T.STATE) >= 1, 60.0), "kite_viz not up"
        ctrl = start_node("controller", {}, ros_env)
        assert probe.spin_until(lambda: probe.node.count_publishers(T.STEERING) > 0, 60.0)
        plant = start_node("plant", {"duration": 6.0, "wait_subscribers": 2}, ros_env)
        assert probe.spin_until(lambda: plant.poll() is not None, 120.0), "plant did not finish"
        assert plant.returncode == 0
        probe.spin_until(lambda: got and got[-1].markers[0].header.stamp.sec >= 5, 10.0)
    finally:
        for p in (plant, ctrl):
            if p is not None:
                stop(p)
        out = stop(viz)
        probe.close()
    assert viz.returncode == 0 and "Traceback" not in out, out
    assert len(got) >= 10, f"{len(got)} arrays"
    stamps = [m.markers[0].header.stamp.sec * 10**9 + m.markers[0].header.stamp.nanosec for m in got]
    # at most one scene per 0.1 s of simulated time, stamped with a sample's time: the first sample at or after each
    # 0.1 s mark (the viewer's subscriptions are best effort, so on a busy machine that sample may be a later one)
    assert all(s % 20_000_000 == 0 for s in stamps), stamps[:20]
    bins = [s // 100_000_000 for s in stamps]
    assert bins == sorted(set(bins)), stamps
    print(f"{len(stamps)} scenes, {sum(s % 100_000_000 == 0 for s in stamps)} of them on the 0.1 s marks")
    last = {m.ns: m for m in got[-1].markers}
    assert set(last) == set(NAMESPACES), sorted(last)
    assert len(last["reference"].points) == 181 and len(last["trail"].points) >= 10
    kite = last["tether"].points[1]
    assert 350.0 < (kite.x ** 2 + kite.y ** 2 + kite.z ** 2) ** 0.5 < 450.0     # on the 400 m tether


def test_kite_viz_refuses_a_bad_parameter_and_answers_help(ros_env):
    bad = subprocess.run([PY, "-m", "kite_rto.tools.viz", "--ros-args", "-p", "period:=-1.0"], env=ros_env,
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "period = -1.0" in bad.stderr, bad.stderr
    typo = subprocess.run([PY, "-m", "kite_rto.tools.viz", "--ros-args", "-p", "hmin:=50.0"], env=ros_env,
                          capture_output=True, text=True, timeout=60)
    assert typo.returncode == 2 and "h_min" in typo.stderr, typo.stderr
    helped = subprocess.run([PY, "-m", "kite_rto.tools.viz", "--help"], env=ros_env, capture_output=True, text=True,
                            timeout=60)
    assert helped.returncode == 0 and "max_rate" in helped.stdout


@pytest.mark.ros
def test_kite_foxglove_serves_scene_and_tension_to_a_protocol_client(ros_env):
    server = subprocess.Popen([PY, "-m", "kite_rto.tools.foxglove_live", "--port", "0"], env=ros_env,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True, preexec_fn=DIE_WITH_PARENT)
    client = ctrl = plant = None
    said, err = [], ""
    try:
        m = None
        while m is None:                                    # the port is printed once the server listens
            line = server.stdout.readline()
            assert line, "kite_foxglove exited: " + "".join(said)
            said.append(line)
            m = re.search(r"ws://127\.0\.0\.1:(\d+)", line)
        client = FoxgloveWsClient("127.0.0.1", int(m.group(1)), timeout=60.0)
        assert client.subprotocol in ("foxglove.sdk.v1", "foxglove.websocket.v1")
        channels = client.wait_for_channels([T.graph_name(t) for t in (T.MARKERS, T.TENSION, T.SETPOINTS, T.STATE)],
                                            timeout=60.0)
        channels = {T.relative(name): ch for name, ch in channels.items()}      # channels: /kite/markers, ...
        assert client.server_info["name"] == "kite_rto" and "time" in client.server_info["capabilities"]
        for topic in (T.MARKERS, T.TENSION):
            ch = channels[topic]
            assert (ch["encoding"], ch["schemaEncoding"], ch["schemaName"]) == (
                "cdr", "ros2msg", TOPICS[topic][0].__module__.split(".")[0] + "/msg/" + TOPICS[topic][0].__name__)
        assert set(TOPICS) <= set(channels)
        client.subscribe({1: channels[T.MARKERS]["id"], 2: channels[T.TENSION]["id"]})

        ctrl = start_node("controller", {}, ros_env)
        plant = start_node("plant", {"duration": 600.0, "wait_subscribers": 2}, ros_env)
        received = {1: [], 2: []}
        end = time.monotonic() + 180.0
        parts = set()        # the wind arrow appears once the bridge has a wind reading (later on a busy machine)
        while time.monotonic() < end and (len(received[1]) < 3 or len(received[2]) < 3 or "wind" not in parts):
            kind, data = client.receive()
            if kind == "binary" and (md := client.message_data(data)) is not None:
                received[md[0]].append(md[1:])
                if md[0] == 1:
                    parts |= {mk.ns for mk in deserialize_message(md[2], MarkerArray).markers}
    finally:
        for p in (plant, ctrl):
            if p is not None:
                stop(p)
        if client is not None:
            client.close()
        err = "".join(said) + stop(server)
    assert server.returncode == 0 and "Traceback" not in err, err
    assert len(received[1]) >= 3 and len(received[2]) >= 3, {k: len(v) for k, v in received.items()}
    for log_time, payload in received[1]:
        scene = deserialize_message(payload, MarkerArray)
        assert {mk.ns for mk in scene.markers} >= {"kite", "tether", "h_min"}
        stamp = scene.markers[0].header.stamp
        assert log_time == stamp.sec * 10**9 + stamp.nanosec          # log time = simulated time
    for log_time, payload in received[2]:
        w = deserialize_message(payload, WrenchStamped)
        assert w.wrench.force.x > 0 and log_time == w.header.stamp.sec * 10**9 + w.header.stamp.nanosec
    assert "forwarded" in err
    assert "wind" in parts, parts


# ------------------------------------------------------------------------------------------------ layouts
def _field_ok(cls, path: str) -> bool:
    """``wrench.force.x`` or ``position[2]`` resolves in the message class ``cls``."""
    msg = cls()
    for part in path.split("."):
        m = re.fullmatch(r"(\w+)(?:\[(\d+)\])?", part)
        if not m or m.group(1) not in msg.get_fields_and_field_types():
            return False
        if m.group(2) is not None:
            return "sequence<" in msg.get_fields_and_field_types()[m.group(1)]
        msg = getattr(msg, m.group(1))
        if not hasattr(msg, "get_fields_and_field_types"):
            return part == path.split(".")[-1]
    return True


def test_foxglove_layout_names_real_topics_and_fields():
    layout = json.loads((ROOT / "config" / "kite_rto.foxglove.json").read_text())
    panels = layout["configById"]
    ids = re.findall(r'"([A-Za-z0-9]+![A-Za-z0-9]+)"', json.dumps(layout["layout"]))
    assert sorted(ids) == sorted(panels)
    paths = [p["value"] for c in panels.values() for p in c.get("paths", [])]
    assert {"/kite/tension.wrench.force.x", "/kite/position.point.z", "/rto/setpoints.position[0]",
            "/kite/laps.position[4]"} <= set(paths)
    for value in paths:
        topic, field = value.split(".", 1)
        topic = T.relative(topic)                           # the layout names topics as in a graph: /kite/...
        assert topic in TOPICS and _field_ok(TOPICS[topic][0], field), value
    assert LAP_FIELDS[2] == "mean_tension" and LAP_FIELDS[3] == "min_altitude" and \
        LAP_FIELDS[4] == "rms_cross_track_deg"
    assert panels["3D!kite"]["topics"][T.graph_name(T.MARKERS)]["visible"]
    assert panels["3D!kite"]["followTf"] == "anchor"


def test_plotjuggler_layout_names_real_topics_and_fields():
    root = ET.parse(ROOT / "config" / "kite_rto.plotjuggler.xml").getroot()
    names = {"/kite/laps": set(LAP_FIELDS), "/rto/setpoints": {"theta_0", "A_phi", "A_theta"},
             "/kite/state": {"theta", "phi", "psi"}}
    curves = [c.get(k) for c in root.iter("curve") for k in ("curve_x", "curve_y", "name") if c.get(k)]
    curves = [c for c in curves if "[[" not in c]
    assert "/kite/tension/wrench/force/x" in curves and "/rto/setpoints/A_phi/position" in curves
    for curve in curves:
        topic = next((T.graph_name(t) for t in TOPICS if curve.startswith(T.graph_name(t) + "/")), None)
        assert topic is not None, curve
        rest = curve[len(topic) + 1:]
        if topic in names:                                  # JointState: /topic/<name>/position
            name, field = rest.split("/")
            assert name in names[topic] and field == "position", curve
        else:
            assert _field_ok(TOPICS[T.relative(topic)][0], rest.replace("/", ".")), curve
