"""What the nodes put on the wire: QoS profiles, stamp conversion, value checks of incoming messages.

Topic names are in :mod:`kite_rto.nodes.topics`. Messages are ordinary rclpy messages (standard types only).
"""
from __future__ import annotations

import math

from builtin_interfaces.msg import Time
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = ["RELIABLE_10", "MEASUREMENTS", "LATCHED", "LATCHED_10", "LAP_HISTORY", "stamp_to_ns", "ns_to_stamp",
           "finite_floats"]

RELIABLE_10 = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
"""Measurements and steering: reliable, depth 10 (lockstep must not lose a sample)."""
MEASUREMENTS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
"""Publishers of per-sample topics (measurements, steering): reliable with a deep history (20 s of samples at
50 Hz), so that a subscriber stalled by CPU load (a recorder, a monitor) catches up instead of losing samples.
Subscribers stay at ``RELIABLE_10``: the depth is not part of QoS compatibility."""
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""Setpoints: a late joiner gets the current value."""
LATCHED_10 = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""A subscriber of a latched topic that must not lose one of several messages arriving at once (the optimizer's
``/kite/plant_config``: each one is checked); it matches ``LATCHED`` publishers (the depth is not part of QoS
compatibility)."""
LAP_HISTORY = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""Per-lap results (``/kite/laps``): a subscriber that matches late (a monitor started during a run, or one that
discovery on a busy machine matched after the first lap) gets the last 100 laps instead of missing them."""


def stamp_to_ns(stamp) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def ns_to_stamp(ns: int) -> Time:
    """Integer nanoseconds -> builtin_interfaces/Time."""
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def finite_floats(values, n: int | None = None) -> list | None:
    """The values as floats if all are finite (and there are ``n`` of them when given), else None."""
    out = [float(v) for v in values]
    if (n is not None and len(out) != n) or not all(map(math.isfinite, out)):
        return None
    return out
