"""Serve the running graph to the Foxglove app over the Foxglove WebSocket protocol, without a ROS install.

``python -m kite_rto.tools.foxglove_live [--host 127.0.0.1] [--port 8765] [--sample-period 0.05] [--namespace NS]``
(console script
``kite_foxglove``), then in Foxglove: *Open connection* -> *Foxglove WebSocket* -> ``ws://127.0.0.1:8765``, and
*Import layout* ``config/kite_rto.foxglove.json`` (3-D scene, tension, altitude, setpoints, cross-track error).

Built on the vendor's ``foxglove-sdk`` (its WebSocket server). Every project topic is forwarded as it arrives on
DDS, as ROS 2 messages (schema encoding ``ros2msg`` with the same definitions ``kite_record`` writes, message
encoding ``cdr``, the bytes from the wire): topic names and field paths are those of a recording and of a ROS
install, so one layout serves all three. The 3-D scene is computed here, by the same code as ``kite_viz``, and
served as ``/kite/markers`` (visualization_msgs/MarkerArray, frame ``anchor``); a ``kite_viz`` running beside it
is not needed. Log times are simulated time (the rule of :mod:`kite_rto.tools.record_time`), and the server
announces the simulated clock (Foxglove's *Time* capability), so the app's timeline is the flight's.

Per-sample topics (state, tension, position, wind, ...) are thinned to one message every ``--sample-period`` s of
simulated time per topic (default 0.05 s, 20 Hz of flight: smooth plots; 0 = every sample); the others are all
forwarded. The graph is only read: nothing is published on DDS. Ctrl-C stops it (exit code 0). ``--namespace /kite2``
serves the graph in that namespace, its channels named as in any graph (``/kite/state``), so the layout fits.
"""
from __future__ import annotations

import argparse
import sys
import time

import foxglove
from foxglove.websocket import Capability
from rclpy.node import Node
from rclpy.serialization import serialize_message
from rclpy.utilities import remove_ros_args

from ..nodes import topics as T
from ..nodes.namespace import add_namespace_option, namespace_args
from ..nodes.parameters import declare_params
from ..nodes.spin import run_node
from .markers import PointCache, marker_array
from .mcap_writer import message_definition, type_name
from .record import TOPICS, subscriber_qos
from .record_time import PER_SAMPLE, SimLogTime
from .viz import PARAMS as SCENE_PARAMS
from .viz import VIEWER, SceneFeed, tracker_from_params

__all__ = ["FORWARDED", "ros2_channel", "FoxgloveBridge", "main"]

FORWARDED = tuple(t for t in sorted(TOPICS) if t != T.MARKERS)
"""The topics forwarded from DDS (``/kite/markers`` is computed here instead)."""


def ros2_channel(topic: str, cls, context=None) -> foxglove.Channel:
    """A Foxglove channel for ROS 2 messages of ``cls`` on ``topic`` (ros2msg schema, cdr encoding)."""
    schema = foxglove.Schema(name=type_name(cls), encoding="ros2msg", data=message_definition(cls).encode())
    return foxglove.Channel(T.graph_name(topic), schema=schema, message_encoding="cdr", context=context)


class FoxgloveBridge(Node):
    """The rclpy side: raw subscriptions forwarded to the SDK's channels, and the scene (see the module doc)."""

    def __init__(self, args, **kwargs):
        super().__init__("kite_foxglove", **kwargs)
        values = declare_params(self, SCENE_PARAMS)
        self.server = foxglove.start_server(name="kite_rto", host=args.host, port=args.port,
                                            capabilities=[Capability.Time])
        self.period_ns = int(round(args.sample_period * 1e9))
        self.log_time = SimLogTime({t: type_name(TOPICS[t][0]) for t in FORWARDED})
        self.channels = {t: ros2_channel(t, TOPICS[t][0]) for t in FORWARDED}
        self.channels[T.MARKERS] = ros2_channel(T.MARKERS, TOPICS[T.MARKERS][0])
        self.forwarded = dict.fromkeys(self.channels, 0)
        self._last_fwd: dict = {}
        self._last_broadcast = 0.0
        self.points = PointCache()
        for topic in FORWARDED:
            qos = VIEWER if topic in PER_SAMPLE else subscriber_qos(topic)
            self.create_subscription(TOPICS[topic][0], topic, self._forwarder(topic), qos, raw=True)
        self.feed = SceneFeed(self, tracker_from_params(values), self._scene)
        print(f"[kite_foxglove] serving {len(self.channels)} channels on ws://{args.host}:{self.server.port} "
              f"(Foxglove: Open connection -> Foxglove WebSocket)", flush=True)

    def _forwarder(self, topic: str):
        channel = self.channels[topic]
        log_time = self.log_time.log_time
        per_sample = topic in PER_SAMPLE
        period = self.period_ns

        def callback(data):
            t = log_time(topic, data, time.time_ns())
            if t is None:
                return
            if topic == T.CLOCK:
                self._announce(t)
            if per_sample and period:
                last = self._last_fwd.get(topic)
                if last is not None and last <= t < last + period:
                    return
                self._last_fwd[topic] = t
            channel.log(data, log_time=t)
            self.forwarded[topic] += 1
        return callback

    def _announce(self, sim_ns: int) -> None:
        """The server's time = the simulated clock, at most 20 times per wall second."""
        now = time.monotonic()
        if now - self._last_broadcast >= 0.05:
            self._last_broadcast = now
            self.server.broadcast_time(sim_ns)

    def _scene(self, shapes, stamp_ns: int) -> None:
        self.channels[T.MARKERS].log(serialize_message(marker_array(shapes, stamp_ns, cache=self.points)), log_time=stamp_ns)
        self.forwarded[T.MARKERS] += 1

    def destroy_node(self):
        self.server.stop()
        sent = ", ".join(f"{T.graph_name(t)} {n}" for t, n in self.forwarded.items() if n)
        print(f"[kite_foxglove] stopped; forwarded {sum(self.forwarded.values())} messages"
              + (f" ({sent})" if sent else ""), file=sys.stderr, flush=True)
        return super().destroy_node()


def parse_args(argv=None):
    ap = argparse.ArgumentParser(prog="kite_foxglove", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="Scene parameters (as kite_viz's): --ros-args -p NAME:=VALUE with NAME in "
                                        + ", ".join(s.name for s in SCENE_PARAMS))
    ap.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this machine "
                                                        "only; 0.0.0.0 opens it to the network)")
    ap.add_argument("--port", type=int, default=8765, help="TCP port (default 8765; 0 = any free port, printed)")
    ap.add_argument("--sample-period", type=float, default=0.05, metavar="S",
                    help="simulated seconds between two forwarded messages of a per-sample topic (default 0.05; "
                         "0 = every sample)")
    add_namespace_option(ap)
    args = ap.parse_args(argv)
    if not 0 <= args.port <= 65535:
        ap.error(f"--port {args.port}: expected 0..65535")
    if not 0 <= args.sample_period <= 10:
        ap.error(f"--sample-period {args.sample_period}: expected 0..10 s")
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(remove_ros_args(["kite_foxglove", *argv])[1:])
    return run_node(lambda: FoxgloveBridge(args), ["kite_foxglove", *argv, *namespace_args(args.namespace)],
                    events=True)


if __name__ == "__main__":
    sys.exit(main())
