"""nodes.wire: every message template and the raw JointState reader against rclpy.serialization."""
import math

import pytest
from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from kite_rto.nodes import echo_pilot, plant_node
from kite_rto.nodes.wire import READER_CHECKS, JointStateReader, MessageTemplate, cdr_serialize

TEMPLATES = [(plant_node._clock_msg, 0), (plant_node._state_msg, 6), (plant_node._position_msg, 3),
             (plant_node._tension_msg, 1), (plant_node._wind_msg, 1), (echo_pilot.steering_msg, 1)]
"""Every MessageTemplate the nodes build: (builder, number of values)."""
STAMPS = [0, 1, 20_000_000, 3_187_020_000_000, (2**31 - 1) * 10**9 + 999_999_999]


class Log:
    def __init__(self):
        self.warnings = []

    def warning(self, text, **_):
        self.warnings.append(text)


def _values(n, k):
    return [(-1.0) ** (i + k) * (i + 1) * 10.0 ** (k - 2) + math.pi * k for i in range(n)]


@pytest.mark.parametrize("build, n", TEMPLATES, ids=[b.__name__ for b, _ in TEMPLATES])
def test_template_round_trips_through_rclpy(build, n):
    log = Log()
    template = MessageTemplate(build, n, log)
    assert template.compiled and log.warnings == []
    for k, ns in enumerate(STAMPS):
        values = _values(n, k)
        msg = build(Time(sec=ns // 10**9, nanosec=ns % 10**9), values)
        data = template(ns, values)
        assert isinstance(data, bytes)
        assert deserialize_message(data, type(msg)) == msg                           # rclpy reads our bytes
        assert deserialize_message(serialize_message(msg), type(msg)) == deserialize_message(data, type(msg))
        assert data == cdr_serialize(msg)                                            # the reference serializer


def test_template_fallback_is_logged():
    def varying(stamp, values):              # layout depends on the value: a string of varying length
        msg = JointState(name=["x" * int(values[0] % 5 + 1)], position=list(values))
        msg.header.stamp = stamp
        return msg

    log = Log()
    template = MessageTemplate(varying, 1, log)
    assert not template.compiled and len(log.warnings) == 1 and "varying" in log.warnings[0]
    msg = template(1_500_000_000, [2.0])
    assert isinstance(msg, JointState) and msg == varying(Time(sec=1, nanosec=500_000_000), [2.0])


def test_joint_state_reader_matches_rclpy():
    log = Log()
    read = JointStateReader(log)
    assert read.fast and log.warnings == []
    for stamp, frame, names, pos in READER_CHECKS + ((5, "anchor", ["theta", "phi", "psi"], [1.0, 2.0, 3.0]),):
        msg = JointState(name=names, position=pos, velocity=[0.5] * len(pos), effort=[1.0] * len(pos))
        msg.header.stamp = Time(sec=stamp // 10**9, nanosec=stamp % 10**9)
        msg.header.frame_id = frame
        back = deserialize_message(serialize_message(msg), JointState)
        assert read(serialize_message(msg)) == (stamp, tuple(back.position))
    with pytest.raises(ValueError):
        read(b"\x00\x01\x00\x00garbage")
