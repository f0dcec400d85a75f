"""One plant per graph: the plant node's start-up check and its running watch for a second publisher.

Two plants in one graph (one ROS domain and namespace) publish two interleaved timelines on ``/kite/state`` and
``/clock``: the controller answers whichever sample arrives, each plant takes some of the answers, and what the
kites fly depends on timing.

- **At start-up** (:func:`refuse_if_another_plant`, before the plant creates its publishers) the node waits up to
  :data:`DISCOVERY_WAIT` for the graph; if another node publishes ``/kite/state`` or ``/clock`` and a message from
  it arrives within :data:`ALIVE_WAIT`, the plant refuses to start (exit code 2) naming that node. A publisher
  that sends nothing in that time (a node that holds a publisher on the topic but does not fly a kite, a frozen
  plant) is not a running plant: the plant names it and starts. Topic names resolve in the plant's namespace, so
  a plant of another graph (``-r __ns:=/kite2``) in the same domain is no obstacle. (A killed plant is no
  obstacle either: a participant that is gone sends no discovery announcements, so a newly started one never lists it.)
- **While running** (:class:`SecondPublisherWatch`, every :data:`WATCH_PERIOD` wall s) it warns, naming them, when
  the graph holds more publishers of ``/kite/state`` or ``/clock`` than its own (two plants started at the same
  moment, a probe or a replay publishing on its topics); the same set is warned about again every
  :data:`WARN_EVERY` s while it stays. Publishers found silent at start-up are not warned about again.
"""
from __future__ import annotations

import time

from rclpy.node import Node
from rclpy.wait_for_message import wait_for_message
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState

from ..kite.params import ParameterError
from .interface import RELIABLE_10, stamp_to_ns
from .topics import CLOCK, STATE

__all__ = ["DISCOVERY_WAIT", "ALIVE_WAIT", "WATCH_PERIOD", "WARN_EVERY", "AnotherPlant", "refuse_if_another_plant",
           "SecondPublisherWatch"]

DISCOVERY_WAIT = 1.0
"""Wall s the starting plant waits for DDS discovery before it looks for another plant (on localhost the graph
is complete after 0.1-0.3 s)."""
ALIVE_WAIT = 1.5
"""Wall s a publisher found at start-up has to send a message to count as a running plant (a lockstep plant
re-publishes an unanswered sample every ``resend_period``, 0.2 s by default; a real-time one steps every
``dt / rate_factor``)."""
WATCH_PERIOD = 0.5
"""Wall s between two looks at the graph while running."""
WARN_EVERY = 10.0
"""Wall s between two warnings about the same second publishers."""

_TOPICS = ((STATE, JointState), (CLOCK, ClockMsg))


class AnotherPlant(ParameterError):
    """Another node already publishes the plant's topics (the plant refuses to start: exit code 2)."""


def _full_name(info) -> str:
    return f"{info.node_namespace.rstrip('/')}/{info.node_name}"


def _names(node: Node, topic: str, wait: float = 1.0) -> str:
    """The publishers of ``topic`` by node name; DDS may list an endpoint before the ROS graph names its node
    (``_NODE_NAME_UNKNOWN_``): wait up to ``wait`` wall s for the names."""
    end = time.monotonic() + wait
    while True:
        names = sorted({_full_name(i) for i in node.get_publishers_info_by_topic(topic)})
        if not any("_UNKNOWN_" in n for n in names) or time.monotonic() >= end:
            return ", ".join(names)
        time.sleep(0.02)


def _stamp_s(msg) -> float:
    return stamp_to_ns(msg.clock if isinstance(msg, ClockMsg) else msg.header.stamp) * 1e-9


def refuse_if_another_plant(node: Node) -> set:
    """Before the plant publishes: raise :class:`AnotherPlant` if another node publishes ``/kite/state`` or
    ``/clock`` and sends on it (module docstring); return the endpoint GIDs of silent publishers found (bytes)."""
    topics = [(node.resolve_topic_name(topic), msg_type) for topic, msg_type in _TOPICS]
    end = time.monotonic() + DISCOVERY_WAIT
    while time.monotonic() < end and not any(node.count_publishers(t) for t, _ in topics):
        time.sleep(0.02)
    silent = set()
    for topic, msg_type in topics:
        infos = node.get_publishers_info_by_topic(topic)
        if not infos:
            continue
        got, msg = wait_for_message(msg_type, node, topic, qos_profile=RELIABLE_10, time_to_wait=ALIVE_WAIT)
        names = _names(node, topic)
        if got and msg is not None:
            raise AnotherPlant(f"another node already publishes {topic}: {names} (sent a message stamped "
                               f"{_stamp_s(msg):.2f} s); a second plant in the same ROS domain would interleave "
                               "its samples with that one's: stop it, or start this plant in another namespace "
                               "(--ros-args -r __ns:=/kite2) or ROS_DOMAIN_ID")
        node.get_logger().warning(f"{names} publishes {topic} but sent nothing in {ALIVE_WAIT:g} s: not a "
                                  "running plant (a frozen one?); starting")
        silent |= {bytes(i.endpoint_gid) for i in infos}
    return silent


class SecondPublisherWatch:
    """Warns when more nodes than this plant publish its ``/kite/state`` or ``/clock`` (module docstring).

    ``ignore``: endpoint GIDs (bytes) found silent at start-up. Call :meth:`check` every :data:`WATCH_PERIOD`.
    """

    def __init__(self, node: Node, ignore: set = frozenset()):
        self.node = node
        self.ignore = set(ignore)
        self.own = _full_name_of(node)
        self.topics = [node.resolve_topic_name(topic) for topic, _ in _TOPICS]
        self._warned: dict = {}                 # (topic, names) -> wall time of the last warning
        self._unnamed: set = set()              # topics whose new publisher had no node name at the last look

    def others(self, topic: str) -> list[str]:
        """Full names of the publishers of ``topic`` other than this node's own one (counted once)."""
        names = [_full_name(i) for i in self.node.get_publishers_info_by_topic(topic)
                 if bytes(i.endpoint_gid) not in self.ignore]
        if self.own in names:
            names.remove(self.own)
        return sorted(names)

    def check(self) -> list[str]:
        """Look at the graph; warn (throttled per set of names) and return the warning lines written."""
        lines, now = [], time.monotonic()
        for topic in self.topics:
            if self.node.count_publishers(topic) <= 1 and not self.ignore:
                continue
            names = self.others(topic)
            if any("_UNKNOWN_" in n for n in names) and topic not in self._unnamed:
                self._unnamed.add(topic)        # DDS lists the endpoint, the ROS graph not yet its node: next look
                continue
            self._unnamed.discard(topic)
            key = (topic, tuple(names))
            if names and now - self._warned.get(key, -WARN_EVERY) >= WARN_EVERY:
                self._warned[key] = now
                lines.append(f"another publisher of {topic} is in the graph: {', '.join(names)} (a second plant? "
                             "the controller and the optimizer cannot tell two plants' samples apart)")
                self.node.get_logger().warning(lines[-1])
        return lines


def _full_name_of(node: Node) -> str:
    return f"{node.get_namespace().rstrip('/')}/{node.get_name()}"
