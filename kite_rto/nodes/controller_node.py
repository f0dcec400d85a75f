"""Controller node: follows the figure-eight of the current setpoints and steers the plant.

Subscribes the plant's measurements and ``/rto/setpoints`` (reliable + transient-local: a late controller still
gets the current setpoints); answers every ``/kite/state`` sample on ``/kite/steering`` with the sample's stamp
(the lockstep handshake); publishes the reference path (nav_msgs/Path, for RViz/Foxglove) and per-lap statistics.
With ``sync_optimizer:=true`` (lockstep) it follows the optimizer's plans (``/rto/sync``, :mod:`kite_rto.runtime.plan`):
where the plan says a decision is due it waits for the optimizer's message about that sample and takes the setpoints
from there, so a setpoint change takes effect at the same sample as in the pure runner.
All logic is :class:`kite_rto.runtime.steering_loop.SteeringLoop` (join, timeline, restart, setpoints coalesced per
sample, optimizer sync) around :class:`kite_rto.flight.controller.PathController` and
:class:`kite_rto.flight.laps.LapDetector`. Every 0.5 s wall it looks at the graph: several publishers of an input
(two plants, a foreign setpoint source) are warned about by name (:class:`.graph_watch.InputWatch`).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from geometry_msgs.msg import PointStamped, PoseStamped, Vector3Stamped, WrenchStamped
from nav_msgs.msg import Path
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import UInt32

from ..flight.controller import ControllerSettings, PathController
from ..flight.path import DEFAULT_SETPOINTS, FigureEightPath, SetpointBox, Setpoints, SetpointError
from ..kite.params import KiteParams, ParameterError
from ..runtime.sources import parse_source
from ..runtime.steering_loop import SteeringLoop, fmt_setpoints
from .graph_watch import InputWatch, publishers_of
from .interface import LAP_HISTORY, LATCHED, MEASUREMENTS, RELIABLE_10, ns_to_stamp, stamp_to_ns
from .peer_check import PlantAgreement
from .parameters import ParamSpec, declare_params
from .spin import run_node
from .topics import CRASHES, LAPS, POSITION, REFERENCE_PATH, SETPOINTS, STATE, STEERING, SYNC, TENSION, WIND

__all__ = ["ControllerNode", "PARAMS", "LAP_FIELDS", "main"]

_C = ControllerSettings()
_B = SetpointBox()
_D = DEFAULT_SETPOINTS.degrees()
PARAMS = (
    ParamSpec("theta_0_deg", _D[0], "initial setpoint theta_0 (until /rto/setpoints says otherwise); inside the box",
              1.0, 89.0, unit="deg"),
    ParamSpec("A_phi_deg", _D[1], "initial setpoint A_phi; inside the box", 0.1, 89.0, unit="deg"),
    ParamSpec("A_theta_deg", _D[2], "initial setpoint A_theta; inside the box", -30.0, 30.0, unit="deg"),
    ParamSpec("box_theta_0_deg", [round(math.degrees(v), 9) for v in _B.theta_0],
              "accepted theta_0 range [low, high], low <= high", 1.0, 89.0, unit="deg"),
    ParamSpec("box_A_phi_deg", [round(math.degrees(v), 9) for v in _B.A_phi],
              "accepted A_phi range [low, high], low <= high", 0.1, 89.0, unit="deg"),
    ParamSpec("box_A_theta_deg", [round(math.degrees(v), 9) for v in _B.A_theta],
              "accepted A_theta range [low, high], low <= high", -30.0, 30.0, unit="deg"),
    ParamSpec("dt", _C.dt, "sample time (must equal the plant's)", 0.001, 0.1, unit="s"),
    ParamSpec("dead_time", _C.dead_time, "steering dead time to compensate", 0.0, 5.0, unit="s"),
    ParamSpec("rate_limit", _C.rate_limit, "steering rate limit (normalized delta per second)", 0.01, 1000.0,
              unit="1/s"),
    ParamSpec("delta_max", _C.delta_max, "steering limit (normalized delta)", 0.05, 1.0, unit="dimensionless"),
    ParamSpec("look_ahead", _C.look_ahead, "guidance look-ahead", 0.001, 1.0, unit="rad of arc", runtime=True),
    ParamSpec("k_psi", _C.k_psi, "orientation-error gain", 0.01, 100.0, unit="1/s", runtime=True),
    ParamSpec("k_i", _C.k_i, "integral gain: turn rate per integrated cross-track error (rad/s per rad s)",
              0.0, 100.0, unit="1/s^2", runtime=True),
    ParamSpec("sync_optimizer", False, "lockstep: follow the optimizer's plans (/rto/sync): where a decision is due, "
              "wait until the optimizer has processed the sample and take the setpoints from there, so the graph "
              "flies exactly the pure runner's sequence; it waits as long as an optimizer is in the graph, and "
              "answers at once when none is"),
    ParamSpec("setpoint_source", "*", "the only node whose /rto/setpoints apply, fully qualified (e.g. /optimizer): "
              "while another node publishes /rto/setpoints, and 1 s after, every setpoint message is ignored; "
              "* = any publisher"),
    ParamSpec("blend_time", _C.blend_time, "duration of the blend to new setpoints (0: switch at once)", 0.0, 600.0,
              unit="s", runtime=True),
    ParamSpec("E", KiteParams.E, "model glide ratio (nominal)", 0.5, 30.0, unit="dimensionless"),
    ParamSpec("g_s", KiteParams.g_s, "model turning constant", 0.001, 1.0, unit="rad/m"),
    ParamSpec("shear", KiteParams.shear, "model wind shear exponent", 0.0, 1.0, unit="dimensionless"),
    ParamSpec("r", KiteParams.r, "tether length (must equal the plant's)", 1.0, 5000.0, unit="m"),
    ParamSpec("z_ref", KiteParams.z_ref, "anemometer height (reference height of the model's wind profile)", 0.5,
              200.0, unit="m"),
)
PLANT_SHARED = ("dt", "r", "z_ref", "E", "g_s", "shear", "dead_time", "rate_limit")
"""Parameters the plant has too: checked against the plant's when it appears (:mod:`.peer_check`)."""
LAP_FIELDS = ("lap", "lap_time", "mean_tension", "min_altitude", "rms_cross_track_deg", "tension_coefficient",
              "theta_0", "A_phi", "A_theta")
"""Names of the /kite/laps JointState: lap index, s, N, m, deg, N/(m/s)^2, then the lap's projection (rad)."""


def _box(v: dict) -> SetpointBox:
    """The setpoint box of checked ``box_*_deg`` parameter values (raises ParameterError for an inverted pair)."""
    bounds = {}
    for name in Setpoints.names():
        pair = v[f"box_{name}_deg"]
        if len(pair) != 2 or not pair[0] <= pair[1]:
            raise ParameterError(f"parameter box_{name}_deg = {list(pair)!r}: expected [low, high] in deg "
                                 "with low <= high")
        bounds[name] = (math.radians(pair[0]), math.radians(pair[1]))
    try:
        return SetpointBox(**bounds)
    except SetpointError as err:
        raise ParameterError(f"setpoint box (box_theta_0_deg, box_A_phi_deg, box_A_theta_deg): {err}") from None


class ControllerNode(Node):
    """Answers each plant sample with a steering command; follows /rto/setpoints.

    The per-sample logic (join, timeline, restart, optimizer sync) is :class:`SteeringLoop`; the node converts
    messages, publishes its answers, the reference path and the laps, and asks the graph for publishers.
    """

    def __init__(self, **kwargs):
        super().__init__("controller", **kwargs)
        v = declare_params(self, PARAMS, apply=self.apply_params)
        params = KiteParams(E=v["E"], g_s=v["g_s"], shear=v["shear"], r=v["r"], z_ref=v["z_ref"])
        settings = replace(ControllerSettings(), dt=v["dt"], dead_time=v["dead_time"], rate_limit=v["rate_limit"],
                           delta_max=v["delta_max"], look_ahead=v["look_ahead"], k_psi=v["k_psi"],
                           k_i=v["k_i"], blend_time=v["blend_time"], box=_box(v))
        c0 = Setpoints.from_degrees(v["theta_0_deg"], v["A_phi_deg"], v["A_theta_deg"])
        self.pub_steering = self.create_publisher(JointState, STEERING, MEASUREMENTS)
        self.pub_path = self.create_publisher(Path, REFERENCE_PATH, LATCHED)
        self.pub_laps = self.create_publisher(JointState, LAPS, LAP_HISTORY)
        source = parse_source(v["setpoint_source"], self.get_namespace())
        try:
            self.loop = SteeringLoop(params, settings, c0, answer=self.answer, lap=self.publish_lap,
                                     path=self.publish_path, logger=self.get_logger(), sync=v["sync_optimizer"],
                                     setpoint_sources=lambda: self.count_publishers(SETPOINTS),
                                     sync_sources=lambda: self.count_publishers(SYNC),
                                     state_sources=lambda: self.count_publishers(STATE), setpoint_source=source,
                                     setpoint_publishers=lambda: publishers_of(self, SETPOINTS),
                                     setpoint_matched=lambda: self.sub_setpoints.get_publisher_count())
        except SetpointError as err:
            raise ParameterError(f"initial setpoints (theta_0_deg, A_phi_deg, A_theta_deg): {err}") from None
        self.create_subscription(JointState, STATE, self.state_callback, RELIABLE_10)
        self.create_subscription(Vector3Stamped, WIND, self.wind_callback, RELIABLE_10)
        self.create_subscription(WrenchStamped, TENSION, self.tension_callback, RELIABLE_10)
        self.create_subscription(PointStamped, POSITION, self.position_callback, RELIABLE_10)
        self.sub_setpoints = None
        self.subscribe_setpoints()
        if self.loop.sync:
            self.create_subscription(JointState, SYNC, self.sync_callback, MEASUREMENTS)
            self.create_subscription(UInt32, CRASHES, lambda msg: self.loop.crash_count(int(msg.data)), LATCHED)
            self.create_timer(0.05, self.loop.watchdog, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.plant_agreement = PlantAgreement(self, {n: float(v[n]) for n in PLANT_SHARED},
                                              {s.name: s.unit for s in PARAMS})
        self.inputs = InputWatch(self, self.loop, source, resubscribe=self.subscribe_setpoints)
        self.publish_path()
        self.get_logger().info(f"controller up: setpoints {fmt_setpoints(c0)}")

    @property
    def controller(self) -> PathController:
        """The flying controller (replaced on new setpoints before the first sample and on a plant restart)."""
        return self.loop.controller

    @property
    def settings(self) -> ControllerSettings:
        """Settings of the flying controller and of every later one."""
        return self.loop.settings

    def apply_params(self, changes: dict) -> None:
        """Runtime parameters (``look_ahead``, ``k_psi``, ``k_i``, ``blend_time``): retune the flying controller.

        Every later PathController (plant restart, first setpoints) is built with the new settings too.
        """
        try:
            settings = replace(self.loop.settings, **changes)     # validated (ControllerSettings.__post_init__)
        except ValueError as err:
            raise ParameterError(str(err)) from None
        self.loop.controller.retune(**changes)
        self.loop.settings = settings

    # ------------------------------------------------------------ subscriptions
    def subscribe_setpoints(self) -> None:
        """(Re)subscribe /rto/setpoints: a new subscription gets the latched setpoints of the publishers now."""
        if self.sub_setpoints is not None:
            self.destroy_subscription(self.sub_setpoints)
        self.sub_setpoints = self.create_subscription(JointState, SETPOINTS, self.setpoints_callback, LATCHED)

    def state_callback(self, msg: JointState) -> None:
        self.loop.state_sample(stamp_to_ns(msg.header.stamp), msg.name, msg.position, msg.velocity)

    def wind_callback(self, msg: Vector3Stamped) -> None:
        self.loop.wind_reading(stamp_to_ns(msg.header.stamp), msg.vector.x)

    def tension_callback(self, msg: WrenchStamped) -> None:
        self.loop.tension_reading(stamp_to_ns(msg.header.stamp), msg.wrench.force.x)

    def position_callback(self, msg: PointStamped) -> None:
        self.loop.position_reading(stamp_to_ns(msg.header.stamp), (msg.point.x, msg.point.y, msg.point.z))

    def setpoints_callback(self, msg: JointState) -> None:
        self.loop.setpoints_message(msg.name, msg.position)

    def sync_callback(self, msg: JointState) -> None:
        self.loop.sync_message(stamp_to_ns(msg.header.stamp), msg.name, msg.position)

    # ------------------------------------------------------------------- output
    def answer(self, stamp: int, delta: float) -> None:
        """Publish the steering command ``delta`` answering the sample stamped ``stamp`` (ns)."""
        cmd = JointState()
        cmd.header.stamp = ns_to_stamp(stamp)
        cmd.name = ["delta"]
        cmd.position = [delta]
        self.pub_steering.publish(cmd)

    def publish_path(self) -> None:
        """Publish the target path as Cartesian poses in frame ``anchor`` (m)."""
        path = FigureEightPath(self.loop.controller.setpoints)
        theta, phi = path.point(np.linspace(0.0, 2 * math.pi, 181))
        msg = Path()
        msg.header.frame_id = "anchor"
        r = self.loop.params.r
        for th, ph in zip(theta, phi):
            p = PoseStamped()
            p.header.frame_id = "anchor"
            p.pose.position.x = float(r * math.cos(th))
            p.pose.position.y = float(r * math.sin(th) * math.sin(ph))
            p.pose.position.z = float(r * math.sin(th) * math.cos(ph))
            p.pose.orientation.w = 1.0
            msg.poses.append(p)
        self.pub_path.publish(msg)

    def publish_lap(self, stamp: int, lap) -> None:
        """Publish a finished lap (:data:`LAP_FIELDS`) stamped with the sample that ended it (ns)."""
        msg = JointState()
        msg.header.stamp = ns_to_stamp(stamp)
        msg.name = list(LAP_FIELDS)
        msg.position = [float(lap.index), lap.duration, lap.mean_tension, lap.min_altitude, lap.rms_cross_track_deg,
                        lap.tension_coefficient, *lap.projection]
        self.pub_laps.publish(msg)
        self.get_logger().info(f"lap {lap.index}: {lap.duration:.1f} s, mean tension {lap.mean_tension / 1e3:.0f} kN, "
                               f"min altitude {lap.min_altitude:.0f} m, RMS cross-track {lap.rms_cross_track_deg:.2f} deg")


def main(args=None) -> None:
    raise SystemExit(run_node(ControllerNode, args, events=True))


if __name__ == "__main__":
    main()
