"""Setpoint flood: a foreign publisher of /rto/setpoints, for fault-injection tests.

Publishes valid setpoints on /rto/setpoints (reliable, transient local: the controller's QoS) at ``--rate`` Hz for
``--duration`` wall seconds, alternating between ``--a`` and ``--b`` (degrees ``theta_0,A_phi,A_theta``; both
inside the controller's default box and trackable), then exits and prints one line
``setpoint_flood summary: {json}`` with the count sent, the rate achieved and the system-clock times (ns, the
clock of DDS source timestamps) of the first and last message::

    python -m kite_rto.testing.setpoint_flood --rate 500 --duration 8 --name intruder

The node is named ``--name`` (default ``setpoint_flood``), so that the controller's warning about a second
publisher names it. Publishing is paced on absolute wall times (``time.monotonic``): a late tick is sent at once,
not skipped, so the count is ``rate * duration`` unless the machine cannot keep up (the summary says).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time

import rclpy
from rclpy.node import Node
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import JointState

from ..flight.path import Setpoints
from ..nodes.interface import LATCHED
from ..nodes.topics import SETPOINTS

__all__ = ["main", "parse_args", "flood"]


def _degrees(text: str) -> list[float]:
    vals = [float(v) for v in text.split(",")]
    if len(vals) != 3 or not all(map(math.isfinite, vals)):
        raise argparse.ArgumentTypeError(f"{text!r}: expected three finite numbers theta_0,A_phi,A_theta (deg)")
    return vals


def parse_args(argv):
    ap = argparse.ArgumentParser(prog="python -m kite_rto.testing.setpoint_flood", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rate", type=float, default=500.0, help="messages per wall second, in (0, 10000]")
    ap.add_argument("--duration", type=float, default=8.0, help="wall s of flooding, in (0, 3600]")
    ap.add_argument("--a", type=_degrees, default=[33.0, 46.0, 7.0], help="first setpoints, deg")
    ap.add_argument("--b", type=_degrees, default=[35.0, 52.0, 8.0], help="second setpoints, deg")
    ap.add_argument("--wait", type=float, default=30.0, help="wall s to wait for a subscriber first (0: don't)")
    ap.add_argument("--name", default="setpoint_flood", help="node name")
    args = ap.parse_args(argv)
    if not (0.0 < args.rate <= 10000.0):
        ap.error(f"--rate {args.rate!r}: expected messages per second in (0, 10000]")
    if not (0.0 < args.duration <= 3600.0):
        ap.error(f"--duration {args.duration!r}: expected wall seconds in (0, 3600]")
    return args


def flood(node: Node, rate: float, duration: float, a: list, b: list) -> dict:
    """Publish ``a`` and ``b`` (deg) alternately at ``rate`` Hz for ``duration`` wall s; return the counts and the
    system-clock start and end (``t_start_ns``, ``t_end_ns``)."""
    pub = node.create_publisher(JointState, SETPOINTS, LATCHED)
    msgs = [JointState(name=list(Setpoints.names()), position=Setpoints.from_degrees(*c).as_array().tolist())
            for c in (a, b)]
    period, n = 1.0 / rate, 0
    t0, t0_ns = time.monotonic(), time.time_ns()
    end = t0 + duration
    while True:
        due = t0 + n * period
        if due >= end:
            break
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        pub.publish(msgs[n % 2])
        n += 1
    wall = time.monotonic() - t0
    return {"sent": n, "wall_s": round(wall, 3), "rate_hz": round(n / wall, 1), "target_hz": rate,
            "t_start_ns": t0_ns, "t_end_ns": time.time_ns()}


def main(argv=None) -> int:
    argv = sys.argv if argv is None else argv
    args = parse_args(remove_ros_args(argv)[1:])
    rclpy.init(args=argv)
    node = Node(args.name)
    try:
        if args.wait > 0:
            end = time.monotonic() + args.wait
            while node.count_subscribers(SETPOINTS) == 0 and time.monotonic() < end:
                time.sleep(0.05)
        summary = flood(node, args.rate, args.duration, args.a, args.b)
        print("setpoint_flood summary: " + json.dumps(summary), flush=True)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
