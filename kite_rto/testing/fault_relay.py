"""Fault relay: forward one topic to another, dropping and delaying messages (seeded), for fault-injection tests.

Put it in a path with ROS remapping, e.g. the controller's steering through a lossy link::

    python -m kite_rto.testing.fault_relay --in /kite/steering_raw --out /kite/steering \\
        --type sensor_msgs/JointState --drop 0.1 --delay 0.05 --seed 0 &
    ros2 run kite_rto controller --ros-args -r /kite/steering:=/kite/steering_raw

Messages are relayed as serialized bytes (any type, unchanged), reliable, depth 10 (the graph's QoS; ``--latched``
for transient-local topics such as /rto/setpoints). ``--drop p`` drops each message with probability p
(``random.Random(seed)``: the same seed drops the same message indices); ``--delay d`` holds each message d wall
seconds (plus a uniform ``--jitter``), order preserved. ``--dive-at T`` (sensor_msgs/JointState steering only)
replaces the steering answering samples from sim time T s on by a "dive" command that turns the kite to psi = pi
(straight down) until the plant reports a crash on /kite/crashes (or ``--dive-for`` sim seconds pass): a faulty
pilot that crashes the kite. On exit (Ctrl-C) it prints one line ``fault_relay summary: {json}`` with the counts.
"""
from __future__ import annotations

import argparse
import heapq
import importlib
import json
import math
import random
import sys
import time

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import JointState
from std_msgs.msg import UInt32

from ..nodes.interface import LATCHED, RELIABLE_10, stamp_to_ns
from ..nodes.spin import run_node
from ..nodes.topics import CRASHES, STATE

__all__ = ["main", "parse_args", "message_type"]


def message_type(name: str):
    """``pkg/Type`` or ``pkg/msg/Type`` -> the message class."""
    parts = name.strip("/").split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"--type {name!r}: expected pkg/Type or pkg/msg/Type, e.g. sensor_msgs/JointState")
    try:
        return getattr(importlib.import_module(f"{parts[0]}.{parts[1]}"), parts[2])
    except (ImportError, AttributeError) as err:
        raise ValueError(f"--type {name!r}: unknown message type ({err})") from None


def parse_args(argv):
    ap = argparse.ArgumentParser(prog="python -m kite_rto.testing.fault_relay", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--in", dest="inp", required=True, help="topic to subscribe")
    ap.add_argument("--out", required=True, help="topic to publish")
    ap.add_argument("--type", required=True, help="message type, e.g. sensor_msgs/JointState")
    ap.add_argument("--drop", type=float, default=0.0, help="probability of dropping a message, in [0, 1)")
    ap.add_argument("--delay", type=float, default=0.0, help="delay, wall s (>= 0)")
    ap.add_argument("--jitter", type=float, default=0.0, help="extra uniform delay in [0, jitter], wall s")
    ap.add_argument("--seed", type=int, default=0, help="seed of the drop and jitter draws")
    ap.add_argument("--latched", action="store_true", help="transient-local QoS, depth 1 (e.g. /rto/setpoints)")
    ap.add_argument("--dive-at", type=float, default=None, help="steering only: dive from this sim time, s")
    ap.add_argument("--dive-for", type=float, default=30.0, help="longest dive, sim s (ends at the first crash)")
    ap.add_argument("--name", default=None, help="node name (default: fault_relay_<out topic>)")
    args = ap.parse_args(argv)
    if not 0.0 <= args.drop < 1.0:
        ap.error(f"--drop {args.drop!r}: expected a probability in [0, 1)")
    for opt in ("delay", "jitter"):
        v = getattr(args, opt)
        if not (math.isfinite(v) and 0.0 <= v <= 60.0):
            ap.error(f"--{opt} {v!r}: expected wall seconds in [0, 60]")
    try:
        args.msg_type = message_type(args.type)
    except ValueError as err:
        ap.error(str(err))
    if args.dive_at is not None and args.msg_type.__name__ != "JointState":
        ap.error("--dive-at needs --type sensor_msgs/JointState (the steering topic)")
    return args


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def make_node(args):
    name = args.name or "fault_relay" + "".join(c if c.isalnum() else "_" for c in args.out)

    class FaultRelay(Node):
        def __init__(self):
            super().__init__(name)
            qos = LATCHED if args.latched else RELIABLE_10
            self.rng = random.Random(args.seed)
            self.counts = {"in": 0, "dropped": 0, "out": 0, "dived": 0, "pending_at_exit": 0}
            self.max_delay = 0.0
            self._queue: list = []
            self._seq = 0
            self._last_release = 0.0
            self.pub = self.create_publisher(args.msg_type, args.out, qos)
            self.create_subscription(args.msg_type, args.inp, self.on_message, qos, raw=True)
            if args.delay > 0 or args.jitter > 0:
                self.create_timer(0.002, self.release, clock=Clock(clock_type=ClockType.STEADY_TIME))
            self._dive = args.dive_at is not None
            if self._dive:
                self._psi = 0.0
                self._crashes = None
                self._dive_start = None      # sim ns of the first dived command
                self._dive_done = False
                self.create_subscription(JointState, STATE, self.on_state, RELIABLE_10)
                self.create_subscription(UInt32, CRASHES, self.on_crashes, LATCHED)
            self.get_logger().info(f"relaying {args.inp} -> {args.out} ({args.type}): drop {args.drop:g}, delay "
                                   f"{args.delay:g} s + jitter {args.jitter:g} s, seed {args.seed}"
                                   + (f", dive at {args.dive_at:g} s" if self._dive else ""))

        # ------------------------------------------------------------- dive fault
        def on_state(self, msg) -> None:
            if len(msg.position) == 3 and math.isfinite(msg.position[2]):
                self._psi = msg.position[2]

        def on_crashes(self, msg) -> None:
            if self._crashes is not None and msg.data > self._crashes and self._dive_start is not None:
                if not self._dive_done:
                    self.get_logger().info(f"crash #{msg.data} reported: dive ends")
                self._dive_done = True
            self._crashes = msg.data

        def dive(self, raw: bytes) -> bytes:
            msg = deserialize_message(raw, JointState)
            t = stamp_to_ns(msg.header.stamp)
            if t < args.dive_at * 1e9:
                return raw
            if self._dive_start is None:
                self._dive_start = t
                self.get_logger().info(f"diving from sim time {t * 1e-9:.2f} s")
            if t - self._dive_start > args.dive_for * 1e9:
                self._dive_done = True
                return raw
            msg.position = [max(-1.0, min(1.0, 2.0 * _wrap(math.pi - self._psi)))]
            self.counts["dived"] += 1
            return serialize_message(msg)

        # ------------------------------------------------------------------ relay
        def on_message(self, raw: bytes) -> None:
            self.counts["in"] += 1
            if args.drop > 0 and self.rng.random() < args.drop:
                self.counts["dropped"] += 1
                return
            if self._dive and not self._dive_done:
                raw = self.dive(raw)
            if not self._queue and args.delay <= 0 and args.jitter <= 0:
                self.pub.publish(raw)
                self.counts["out"] += 1
                return
            now = time.monotonic()
            release = now + args.delay + (self.rng.uniform(0.0, args.jitter) if args.jitter > 0 else 0.0)
            release = max(release, self._last_release)          # keep the order
            self._last_release = release
            self._seq += 1
            heapq.heappush(self._queue, (release, self._seq, now, raw))

        def release(self) -> None:
            now = time.monotonic()
            q = self._queue
            while q and q[0][0] <= now:
                _, _, received, raw = heapq.heappop(q)
                self.pub.publish(raw)
                self.counts["out"] += 1
                self.max_delay = max(self.max_delay, now - received)

        def summary(self) -> dict:
            c = dict(self.counts, pending_at_exit=len(self._queue))
            c.update(topic_in=args.inp, topic_out=args.out, drop=args.drop, delay=args.delay, jitter=args.jitter,
                     seed=args.seed, max_delay_measured=round(self.max_delay, 4),
                     dropped_fraction=round(c["dropped"] / c["in"], 4) if c["in"] else 0.0)
            return c

        def destroy_node(self):
            print("fault_relay summary: " + json.dumps(self.summary()), flush=True)
            return super().destroy_node()

    return FaultRelay()


def main(argv=None) -> int:
    argv = sys.argv if argv is None else argv
    args = parse_args(remove_ros_args(argv)[1:])
    return run_node(lambda: make_node(args), argv, events=True)


if __name__ == "__main__":
    raise SystemExit(main())
