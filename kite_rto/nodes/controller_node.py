"""Controller node: follows the figure-eight of the current setpoints and steers the plant.

Subscribes the plant's measurements and ``/rto/setpoints`` (reliable + transient-local: a late controller still
gets the current setpoints); answers every ``/kite/state`` sample on ``/kite/steering`` with the sample's stamp
(the lockstep handshake); publishes the reference path (nav_msgs/Path, for RViz/Foxglove) and per-lap statistics.
All computation is :class:`kite_rto.core.controller.PathController` and :class:`kite_rto.core.laps.LapDetector`.
"""
from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
from geometry_msgs.msg import PointStamped, PoseStamped, Vector3Stamped, WrenchStamped
from nav_msgs.msg import Path
from rclpy.node import Node
from sensor_msgs.msg import JointState

from ..core.controller import ControllerSettings, PathController
from ..core.laps import LapDetector
from ..core.params import KiteParams, ParameterError
from ..core.path import DEFAULT_SETPOINTS, FigureEightPath, SetpointBox, Setpoints, SetpointError
from ..core.plant import shared_model
from .common import (LATCHED, RELIABLE_10, ParamSpec, declare_params, finite_floats, run_node,
                     stamp_to_ns)
from .topics import LAPS, POSITION, REFERENCE_PATH, SETPOINTS, STATE, STEERING, TENSION, WIND

__all__ = ["ControllerNode", "PARAMS", "LAP_FIELDS", "main"]

_C = ControllerSettings()
_B = SetpointBox()
_D = DEFAULT_SETPOINTS.degrees()
PARAMS = (
    ParamSpec("theta_0_deg", _D[0], "initial setpoint theta_0 (until /rto/setpoints says otherwise), deg", 1.0, 89.0),
    ParamSpec("A_phi_deg", _D[1], "initial setpoint A_phi, deg", 0.1, 89.0),
    ParamSpec("A_theta_deg", _D[2], "initial setpoint A_theta, deg", -30.0, 30.0),
    ParamSpec("box_theta_0_deg", [math.degrees(v) for v in _B.theta_0], "accepted theta_0 range [low, high], deg"),
    ParamSpec("box_A_phi_deg", [math.degrees(v) for v in _B.A_phi], "accepted A_phi range [low, high], deg"),
    ParamSpec("box_A_theta_deg", [math.degrees(v) for v in _B.A_theta], "accepted A_theta range [low, high], deg"),
    ParamSpec("dt", _C.dt, "sample time, s (must equal the plant's)", 0.001, 0.1),
    ParamSpec("dead_time", _C.dead_time, "steering dead time to compensate, s", 0.0, 5.0),
    ParamSpec("rate_limit", _C.rate_limit, "steering rate limit, 1/s", 0.01, 1000.0),
    ParamSpec("delta_max", _C.delta_max, "steering limit, normalized", 0.05, 1.0),
    ParamSpec("look_ahead", _C.look_ahead, "guidance look-ahead, rad of arc", 0.001, 1.0),
    ParamSpec("k_psi", _C.k_psi, "orientation-error gain, 1/s", 0.01, 100.0),
    ParamSpec("k_i", _C.k_i, "integral gain", 0.0, 100.0),
    ParamSpec("blend_time", _C.blend_time, "setpoint blend duration, s", 0.0, 600.0),
    ParamSpec("E", KiteParams.E, "model glide ratio (nominal)", 0.5, 30.0),
    ParamSpec("g_s", KiteParams.g_s, "model turning constant, rad/m", 0.001, 1.0),
    ParamSpec("shear", KiteParams.shear, "model wind shear exponent", 0.0, 1.0),
    ParamSpec("r", KiteParams.r, "tether length, m", 1.0, 5000.0),
    ParamSpec("z_ref", KiteParams.z_ref, "anemometer height, m", 0.5, 200.0),
)
LAP_FIELDS = ("lap", "lap_time", "mean_tension", "min_altitude", "rms_cross_track_deg", "tension_coefficient",
              "theta_0", "A_phi", "A_theta")
"""Names of the /kite/laps JointState: lap index, s, N, m, deg, N/(m/s)^2, then the lap's projection (rad)."""


def _box(v: dict) -> SetpointBox:
    bounds = {}
    for name in Setpoints.names():
        pair = v[f"box_{name}_deg"]
        if len(pair) != 2:
            raise ParameterError(f"parameter box_{name}_deg = {list(pair)!r}: expected [low, high] in deg")
        bounds[name] = (math.radians(pair[0]), math.radians(pair[1]))
    try:
        return SetpointBox(**bounds)
    except SetpointError as err:
        raise ParameterError(f"setpoint box: {err}") from None


class ControllerNode(Node):
    """Answers each plant sample with a steering command; follows /rto/setpoints."""

    def __init__(self, **kwargs):
        super().__init__("controller", **kwargs)
        v = declare_params(self, PARAMS)
        self.params = KiteParams(E=v["E"], g_s=v["g_s"], shear=v["shear"], r=v["r"], z_ref=v["z_ref"])
        self.settings = replace(ControllerSettings(), dt=v["dt"], dead_time=v["dead_time"], rate_limit=v["rate_limit"],
                                delta_max=v["delta_max"], look_ahead=v["look_ahead"], k_psi=v["k_psi"],
                                k_i=v["k_i"], blend_time=v["blend_time"], box=_box(v))
        c0 = Setpoints.from_degrees(v["theta_0_deg"], v["A_phi_deg"], v["A_theta_deg"])
        try:
            self.controller = PathController(shared_model(), self.params, c0, self.settings)
        except SetpointError as err:
            raise ParameterError(f"initial setpoints (theta_0_deg, A_phi_deg, A_theta_deg): {err}") from None
        self.laps = LapDetector()
        self.pub_steering = self.create_publisher(JointState, STEERING, RELIABLE_10)
        self.pub_path = self.create_publisher(Path, REFERENCE_PATH, LATCHED)
        self.pub_laps = self.create_publisher(JointState, LAPS, RELIABLE_10)
        self.create_subscription(JointState, STATE, self.state_callback, RELIABLE_10)
        self.create_subscription(Vector3Stamped, WIND, self.wind_callback, RELIABLE_10)
        self.create_subscription(WrenchStamped, TENSION, self.tension_callback, RELIABLE_10)
        self.create_subscription(PointStamped, POSITION, self.position_callback, RELIABLE_10)
        self.create_subscription(JointState, SETPOINTS, self.setpoints_callback, LATCHED)
        self._wind, self._tension, self._altitude = self.params.w_ref, math.nan, math.nan
        self._last_stamp = None
        self._last_delta = 0.0
        self._wind_stamp = None
        self._pending = None
        self.publish_path()
        self.get_logger().info(f"controller up: setpoints {self._fmt(c0)}")

    # -------------------------------------------------------------- measurements
    def wind_callback(self, msg: Vector3Stamped) -> None:
        v = msg.vector.x
        if not (math.isfinite(v) and 0.0 <= v < 100.0):
            self._reject("wind", v, "a finite speed in [0, 100) m/s")
            return
        self._wind, self._wind_stamp = v, stamp_to_ns(msg.header.stamp)
        if self._pending is not None and stamp_to_ns(self._pending.header.stamp) == self._wind_stamp:
            self._process(self._pending)

    def tension_callback(self, msg: WrenchStamped) -> None:
        v = msg.wrench.force.x
        if math.isfinite(v) and v >= 0.0:
            self._tension = v
        else:
            self._reject("tension", v, "a finite, non-negative force in N")

    def position_callback(self, msg: PointStamped) -> None:
        v = msg.point.z
        if math.isfinite(v):
            self._altitude = v
        else:
            self._reject("position", v, "a finite altitude in m")

    def state_callback(self, msg: JointState) -> None:
        """Answer the sample once its anemometer reading (same stamp) is in: DDS does not order across topics,
        and waiting for the matching reading makes the loop as deterministic as the pure runner. If the reading
        is lost, the next sample releases the waiting one with the latest reading."""
        if self._pending is not None:
            self._process(self._pending)
        if stamp_to_ns(msg.header.stamp) == self._wind_stamp:
            self._process(msg)
        else:
            self._pending = msg

    def _process(self, msg: JointState) -> None:
        self._pending = None
        pos, vel = finite_floats(msg.position, 3), finite_floats(msg.velocity, 3)
        if pos is None or vel is None or list(msg.name) != ["theta", "phi", "psi"]:
            self._reject("state", (list(msg.name), list(msg.position), list(msg.velocity)),
                         "names [theta, phi, psi] with 3 finite positions (rad) and velocities (rad/s)")
            return
        stamp = stamp_to_ns(msg.header.stamp)
        if self._last_stamp is not None and stamp == self._last_stamp:
            self._answer(msg.header.stamp, self._last_delta)      # re-published sample: same answer
            return
        if self._last_stamp is not None and stamp < self._last_stamp:
            self.get_logger().warning(f"sim time jumped back ({self._last_stamp * 1e-9:.2f} s -> {stamp * 1e-9:.2f} s):"
                                      " plant restarted, re-synchronizing")
            self.controller = PathController(shared_model(), self.params, self.controller.setpoints, self.settings)
            self.laps.reset()
        t = stamp * 1e-9
        m = SimpleNamespace(t=t, theta=pos[0], phi=pos[1], psi=pos[2], theta_dot=vel[0], phi_dot=vel[1],
                            psi_dot=vel[2], wind_ref=self._wind)
        delta = self.controller.command(m)
        self._last_stamp, self._last_delta = stamp, delta
        self._answer(msg.header.stamp, delta)
        lap = self.laps.update(t, pos[0], pos[1], self._tension, self._altitude,
                               self.controller.status.cross_track, self._wind)
        if lap is not None:
            self.publish_lap(msg.header.stamp, lap)

    def _answer(self, stamp, delta: float) -> None:
        cmd = JointState()
        cmd.header.stamp = stamp
        cmd.name = ["delta"]
        cmd.position = [delta]
        self.pub_steering.publish(cmd)

    # ----------------------------------------------------------------- setpoints
    def setpoints_callback(self, msg: JointState) -> None:
        names = list(msg.name)
        if sorted(names) != sorted(Setpoints.names()) or len(msg.position) != 3:
            self._reject("setpoints", (names, list(msg.position)), "names theta_0, A_phi, A_theta with 3 values (rad)")
            return
        values = dict(zip(names, msg.position))
        c = [values[n] for n in Setpoints.names()]
        try:
            if self._last_stamp is None:       # nothing flown yet: start on the new path, no blend
                self.controller = PathController(shared_model(), self.params, c, self.settings)
                accepted = self.controller.setpoints
            else:
                accepted = self.controller.set_setpoints(c)
        except SetpointError as err:
            self.get_logger().warning(f"rejected setpoints: {err}; keeping {self._fmt(self.controller.setpoints)}",
                                      throttle_duration_sec=2.0)
            return
        self.laps.reset()
        self.get_logger().info(f"new setpoints {self._fmt(accepted)}")
        self.publish_path()

    # ------------------------------------------------------------------- output
    def publish_path(self) -> None:
        """Publish the target path as Cartesian poses in frame ``anchor`` (m)."""
        path = FigureEightPath(self.controller.setpoints)
        theta, phi = path.point(np.linspace(0.0, 2 * math.pi, 181))
        msg = Path()
        msg.header.frame_id = "anchor"
        r = self.params.r
        for th, ph in zip(theta, phi):
            p = PoseStamped()
            p.header.frame_id = "anchor"
            p.pose.position.x = float(r * math.cos(th))
            p.pose.position.y = float(r * math.sin(th) * math.sin(ph))
            p.pose.position.z = float(r * math.sin(th) * math.cos(ph))
            p.pose.orientation.w = 1.0
            msg.poses.append(p)
        self.pub_path.publish(msg)

    def publish_lap(self, stamp, lap) -> None:
        msg = JointState()
        msg.header.stamp = stamp
        msg.name = list(LAP_FIELDS)
        msg.position = [float(lap.index), lap.duration, lap.mean_tension, lap.min_altitude, lap.rms_cross_track_deg,
                        lap.tension_coefficient, *lap.projection]
        self.pub_laps.publish(msg)
        self.get_logger().info(f"lap {lap.index}: {lap.duration:.1f} s, mean tension {lap.mean_tension / 1e3:.0f} kN, "
                               f"min altitude {lap.min_altitude:.0f} m, RMS cross-track {lap.rms_cross_track_deg:.2f} deg")

    def _reject(self, what: str, value, expected: str) -> None:
        self.get_logger().warning(f"rejected {what} message {value!r}: expected {expected}", throttle_duration_sec=2.0)

    @staticmethod
    def _fmt(c: Setpoints) -> str:
        return "theta_0 {:.1f} deg, A_phi {:.1f} deg, A_theta {:.1f} deg".format(*c.degrees())


def main(args=None) -> None:
    raise SystemExit(run_node(ControllerNode, args, events=True))


if __name__ == "__main__":
    main()
