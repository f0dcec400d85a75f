"""Live 3-D view of the flight: ``kite_viz`` publishes ``/kite/markers`` (visualization_msgs/MarkerArray, frame
``anchor``) for RViz2 and Foxglove.

``python -m kite_rto.tools.viz [--ros-args -p period:=0.1 -p max_rate:=20.0 -p h_min:=100.0 ...]`` (console script
``kite_viz``; ``ros2 run kite_rto kite_viz`` after colcon build). It subscribes ``/kite/state``, ``/kite/position``,
``/kite/wind`` (best effort: a viewer may miss a sample, it never slows the loop) and the latched
``/kite/reference_path``, and publishes the whole scene (kite, tether, reference path, flown trail, wind arrow, the
``h_min`` plane, a label) as one MarkerArray, stamped with the sample's time:

* once every ``period`` s of **simulated** time (default 0.1 s, i.e. 10 Hz of flight): a recording then holds one
  scene per 0.1 s of the flight whatever the machine's speed, and a real-time plant gives 10 Hz on the screen;
* at most ``max_rate`` times per **wall** second (default 20 Hz; 0 = no limit): a lockstep run flies 10-50 times
  faster than real time, and 10 Hz of simulated time would then be 100-500 arrays a second that no screen shows.

The control nodes are not touched: the geometry is :mod:`kite_rto.flight.scene` (pure, unit-tested), the messages
:mod:`kite_rto.tools.markers`. A bad parameter stops it with exit code 2.
"""
from __future__ import annotations

import argparse
import sys
import time

from geometry_msgs.msg import PointStamped, Vector3Stamped
from nav_msgs.msg import Path
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from ..flight.scene import ScenePacer, SceneStyle, SceneTracker, Trail
from ..nodes import topics as T
from ..nodes.interface import LATCHED, RELIABLE_10, stamp_to_ns
from ..nodes.namespace import add_namespace_option, namespace_args
from ..nodes.parameters import ParamSpec, declare_params
from ..nodes.spin import run_node
from .markers import PointCache, marker_array

__all__ = ["PARAMS", "VIEWER", "SceneFeed", "VizNode", "tracker_from_params", "main"]

PARAMS = (
    ParamSpec("period", 0.1, "simulated time between two scenes", 0.001, 10.0, unit="s"),
    ParamSpec("max_rate", 20.0, "most scenes per wall second (0 = no limit)", 0.0, 1000.0, unit="Hz"),
    ParamSpec("trail", 40.0, "length of the flown trail (about one lap)", 0.1, 3600.0, unit="s"),
    ParamSpec("trail_step", 0.2, "simulated time between two trail points", 0.001, 10.0, unit="s"),
    ParamSpec("h_min", 100.0, "height of the minimum-altitude plane (the optimizer's h_min)", 0.0, 1000.0, unit="m"),
    ParamSpec("z_ref", 10.0, "anemometer height, where the wind arrow starts", 0.0, 1000.0, unit="m"),
    ParamSpec("wind_scale", 5.0, "wind arrow length per wind speed", 0.0, 100.0, unit="m/(m/s)"),
    ParamSpec("wing_span", 24.0, "span of the drawn kite (exaggerated to be seen)", 0.1, 200.0, unit="m"),
)

VIEWER = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
"""Per-sample subscriptions of a viewer: best effort (a missed sample is a skipped frame, never a stall); a deep
queue rides out a burst while a scene is being built."""


def tracker_from_params(v: dict) -> SceneTracker:
    """A :class:`SceneTracker` from the values of :data:`PARAMS` (ParameterError for a bad combination)."""
    return SceneTracker(ScenePacer(v["period"], v["max_rate"]), Trail(v["trail"], v["trail_step"]),
                        h_min=v["h_min"], z_ref=v["z_ref"],
                        style=SceneStyle(wind_scale=v["wind_scale"], wing_span=v["wing_span"],
                                         wing_length=v["wing_span"] * 2.0 / 3.0))


class SceneFeed:
    """Subscriptions on ``node`` that keep a :class:`SceneTracker` up to date and call ``emit(shapes, stamp_ns)``
    whenever a scene is due (used by ``kite_viz`` and by ``kite_foxglove``)."""

    def __init__(self, node, tracker: SceneTracker, emit):
        self.tracker, self.emit = tracker, emit
        node.create_subscription(JointState, T.STATE, self._state, VIEWER)
        node.create_subscription(PointStamped, T.POSITION, self._position, VIEWER)
        node.create_subscription(Vector3Stamped, T.WIND, self._wind, VIEWER)
        node.create_subscription(Path, T.REFERENCE_PATH, self._reference, LATCHED)

    def _position(self, msg: PointStamped) -> None:
        p = msg.point
        self.tracker.position(stamp_to_ns(msg.header.stamp) * 1e-9, (p.x, p.y, p.z))

    def _wind(self, msg: Vector3Stamped) -> None:
        self.tracker.wind(stamp_to_ns(msg.header.stamp) * 1e-9, msg.vector.x)

    def _reference(self, msg: Path) -> None:
        self.tracker.reference([(q.pose.position.x, q.pose.position.y, q.pose.position.z) for q in msg.poses])

    def _state(self, msg: JointState) -> None:
        if len(msg.position) < 3:
            return
        ns = stamp_to_ns(msg.header.stamp)
        psi = dict(zip(msg.name, msg.position)).get("psi", float("nan"))
        shapes = self.tracker.state(ns * 1e-9, psi, time.monotonic())
        if shapes is not None:
            self.emit(shapes, ns)


class VizNode(Node):
    """``kite_viz``: the scene of the running flight on ``/kite/markers`` (see the module doc)."""

    def __init__(self, **kwargs):
        super().__init__("kite_viz", **kwargs)
        values = declare_params(self, PARAMS)
        self.pub = self.create_publisher(MarkerArray, T.MARKERS, RELIABLE_10)
        self.points = PointCache()
        self.feed = SceneFeed(self, tracker_from_params(values), self._publish)
        self.get_logger().info(f"publishing the 3-D scene on {T.MARKERS} (frame anchor) every "
                               f"{values['period']:g} s of simulated time, at most {values['max_rate']:g} per wall s")

    def _publish(self, shapes, stamp_ns: int) -> None:
        self.pub.publish(marker_array(shapes, stamp_ns, cache=self.points))


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    ours = argv[:argv.index("--ros-args")] if "--ros-args" in argv else argv
    if any(a in ("-h", "--help") for a in ours):
        print(__doc__.strip() + "\n\nOptions: --namespace NS (the graph's ROS namespace, e.g. /kite2; same as "
              "--ros-args -r __ns:=NS)\n\nParameters (--ros-args -p NAME:=VALUE):\n"
              + "\n".join(f"  {s.name:<11} {s.default!s:<7} {s.doc}" for s in PARAMS))
        return 0
    ap = argparse.ArgumentParser(prog="kite_viz")
    add_namespace_option(ap)
    args, rest = ap.parse_known_args(ours)
    return run_node(VizNode, ["kite_viz", *rest, *argv[len(ours):], *namespace_args(args.namespace)], events=True)


if __name__ == "__main__":
    sys.exit(main())
