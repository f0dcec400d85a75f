"""Controller node: follows the figure-eight of the current setpoints and steers the plant.

Subscribes the plant's measurements and ``/rto/setpoints`` (reliable + transient-local: a late controller still
gets the current setpoints); answers every ``/kite/state`` sample on ``/kite/steering`` with the sample's stamp
(the lockstep handshake); publishes the reference path (nav_msgs/Path, for RViz/Foxglove) and per-lap statistics.
With ``sync_optimizer:=true`` (lockstep) it answers a sample only after the optimizer's ``/rto/sync`` message for it
and takes the setpoints from there, so a setpoint change takes effect at the same sample as in the pure runner.
All computation is :class:`kite_rto.flight.controller.PathController` and :class:`kite_rto.flight.laps.LapDetector`.
"""
from __future__ import annotations

import math
import time
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
from geometry_msgs.msg import PointStamped, PoseStamped, Vector3Stamped, WrenchStamped
from nav_msgs.msg import Path
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState

from ..flight.controller import ControllerSettings, PathController
from ..flight.laps import LapDetector
from ..kite.params import KiteParams, ParameterError
from ..flight.path import DEFAULT_SETPOINTS, FigureEightPath, SetpointBox, Setpoints, SetpointError
from ..kite.model import shared_model
from .common import (LATCHED, MEASUREMENTS, RELIABLE_10, ParamSpec, declare_params, run_node,
                     stamp_to_ns)
from ..flight.sample_join import MAX_STAMP_GAP_NS, POSITION_MAX, TENSION_MAX, WIND_MAX, RejectLog, state_values
from .topics import LAPS, POSITION, REFERENCE_PATH, SETPOINTS, STATE, STEERING, SYNC, SYNC_NAMES, TENSION, WIND

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
    ParamSpec("sync_optimizer", False, "lockstep: answer each sample only after the optimizer has processed it "
              "(/rto/sync) and take the setpoints from there, so the graph flies exactly the pure runner's sequence; "
              "without an optimizer publishing /rto/sync it answers at once"),
    ParamSpec("sync_timeout", 10.0, "wall time to wait for /rto/sync before answering with the current setpoints "
              "(then unsynchronized until the optimizer is back); longer than a GMA iteration's solve", 0.1, 3600.0,
              unit="s", runtime=True),
    ParamSpec("blend_time", _C.blend_time, "duration of the blend to new setpoints (0: switch at once)", 0.0, 600.0,
              unit="s", runtime=True),
    ParamSpec("E", KiteParams.E, "model glide ratio (nominal)", 0.5, 30.0, unit="dimensionless"),
    ParamSpec("g_s", KiteParams.g_s, "model turning constant", 0.001, 1.0, unit="rad/m"),
    ParamSpec("shear", KiteParams.shear, "model wind shear exponent", 0.0, 1.0, unit="dimensionless"),
    ParamSpec("r", KiteParams.r, "tether length (must equal the plant's)", 1.0, 5000.0, unit="m"),
    ParamSpec("z_ref", KiteParams.z_ref, "anemometer height (reference height of the model's wind profile)", 0.5,
              200.0, unit="m"),
)
SYNC_ABSENT = 1.0
"""Wall s a sample waits for /rto/sync before the controller asks whether an optimizer is in the graph at all."""
SETPOINTS_GRACE, SETPOINTS_WAIT = 1.0, 3.0
"""Wall s after start-up during which the controller waits for /rto/setpoints before steering (see
:meth:`ControllerNode._await_setpoints`): always for the first, while an optimizer is known for the second."""
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
    """Answers each plant sample with a steering command; follows /rto/setpoints."""

    def __init__(self, **kwargs):
        super().__init__("controller", **kwargs)
        v = declare_params(self, PARAMS, apply=self.apply_params)
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
        self.pub_steering = self.create_publisher(JointState, STEERING, MEASUREMENTS)
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
        self._winds = {}                  # anemometer readings by stamp (ns), until their sample is answered
        self._pending = None              # (stamp, stamp msg, position, velocity) waiting for its wind reading
        self._jump = None                 # the same for a stale or future sample (plant restart or junk)
        self._candidate = None            # (stamp, fresh controller or None, its answer): complete, off the timeline
        self._setpoints_in = False        # accepted /rto/setpoints yet (see _await_setpoints)
        self._t_up = time.monotonic()
        self._reject_log = RejectLog(self.get_logger())
        self._setpoints_msg = None        # last valid /rto/setpoints values (rad); applied at once unless synchronized
        self._sync = v["sync_optimizer"]
        self._sync_timeout = v["sync_timeout"]
        self._syncs = {}                  # /rto/sync entries by stamp (ns): (setpoints rad, updates)
        self._sync_held = None            # (stamp, stamp msg, measurement, position, wall time): waits for /rto/sync
        self._sync_lost = False           # timed out: answer at once until a /rto/sync message arrives again
        self._sync_updates = None         # `updates` of the last applied /rto/sync
        if self._sync:
            self.create_subscription(JointState, SYNC, self.sync_callback, MEASUREMENTS)
            self.create_timer(0.05, self._sync_watchdog, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.publish_path()
        self.get_logger().info(f"controller up: setpoints {self._fmt(c0)}")

    def apply_params(self, changes: dict) -> None:
        """Runtime parameters (``look_ahead``, ``k_psi``, ``k_i``, ``blend_time``): retune the flying controller.

        Every later PathController (plant restart, first setpoints) is built with the new settings too.
        """
        if "sync_timeout" in changes:
            self._sync_timeout = changes.pop("sync_timeout")
            if not changes:
                return
        try:
            settings = replace(self.settings, **changes)          # validated (ControllerSettings.__post_init__)
        except ValueError as err:
            raise ParameterError(str(err)) from None
        self.controller.retune(**changes)
        self.settings = settings

    # -------------------------------------------------------------- measurements
    # Every reading carries the stamp of its plant sample. A /kite/state sample is answered once the anemometer
    # reading with the same stamp is in: DDS does not order across topics, and waiting for it makes the loop as
    # deterministic as the pure runner; if that reading is lost, the next sample releases the waiting one with the
    # previous reading. A state stamped before the last answered sample (plant restart: sim time jumped back) or
    # more than MAX_STAMP_GAP_NS after it (samples lost) moves the timeline only as a complete sample (with the
    # anemometer reading of the same stamp) that the next complete sample continues (_new_timeline); otherwise it is
    # rejected as stale or future. Readings with bad values, or (tension, position) stamped far from the last
    # sample, are rejected with throttled warnings.
    def wind_callback(self, msg: Vector3Stamped) -> None:
        v = msg.vector.x
        if not (math.isfinite(v) and 0.0 <= v < WIND_MAX):
            self._reject("wind", f"rejected wind message {v!r}: expected a finite speed in [0, {WIND_MAX:g}) m/s")
            return
        stamp = stamp_to_ns(msg.header.stamp)
        winds = self._winds
        if len(winds) >= 64:
            del winds[next(iter(winds))]
        winds[stamp] = v
        for held in (self._pending, self._jump):
            if held is not None and held[0] == stamp:
                self._process(held)
                return

    def tension_callback(self, msg: WrenchStamped) -> None:
        v = msg.wrench.force.x
        if not (math.isfinite(v) and 0.0 <= v <= TENSION_MAX):
            self._reject("tension", f"rejected tension message {v!r}: expected a finite force in "
                                    f"[0, {TENSION_MAX:g}] N")
        elif self._stamp_near("tension", msg.header.stamp):
            self._tension = v

    def position_callback(self, msg: PointStamped) -> None:
        p = msg.point
        if not all(math.isfinite(x) and abs(x) <= POSITION_MAX for x in (p.x, p.y, p.z)):
            self._reject("position", f"rejected position message {[p.x, p.y, p.z]!r}: expected finite coordinates "
                                     f"within +-{POSITION_MAX:g} m")
        elif self._stamp_near("position", msg.header.stamp):
            self._altitude = p.z

    def _stamp_near(self, what: str, stamp_msg) -> bool:
        last = self._last_stamp
        stamp = stamp_to_ns(stamp_msg)
        if last is None or abs(stamp - last) <= MAX_STAMP_GAP_NS:
            return True
        self._reject(f"{what} stamp", f"rejected {what} message stamped {stamp * 1e-9:.3f} s at sim time "
                                      f"{last * 1e-9:.3f} s: stale or future")
        return False

    def state_callback(self, msg: JointState) -> None:
        try:
            pos, vel = state_values(msg.name, msg.position, msg.velocity)
        except ValueError as err:
            self._reject("state", f"rejected state message: {err}")
            return
        if not self._setpoints_in and self._await_setpoints():
            return
        stamp = stamp_to_ns(msg.header.stamp)
        if self._sync_held is not None:
            held = self._sync_held[0]
            if stamp == held:
                return                              # re-published while the optimizer works on it
            if held < stamp <= held + MAX_STAMP_GAP_NS:
                self._release_unsynced("the next sample arrived first")
        held = (stamp, msg.header.stamp, pos, vel)
        last = self._last_stamp
        if self._jump is not None:
            self._reject_jump()
        if last is not None and not last <= stamp <= last + MAX_STAMP_GAP_NS:
            if stamp in self._winds:
                self._process(held)                 # complete: the plant restarted or samples were lost
            else:
                self._jump = held                   # wait for its anemometer reading
            return
        if self._pending is not None and self._pending[0] < stamp:
            self._process(self._pending)            # its anemometer reading was lost
        if stamp == last or stamp in self._winds:
            self._process(held)
        else:
            self._pending = held

    def _await_setpoints(self) -> bool:
        """True (do not steer yet) while the optimizer's setpoints may still be on their way.

        A controller started into a running loop (e.g. restarted after a crash) would otherwise steer the kite
        towards its initial setpoints until the latched /rto/setpoints arrive. It waits while a publisher of
        /rto/setpoints is known, or for the first SETPOINTS_GRACE s after start-up (discovery), at most
        SETPOINTS_WAIT s; without an optimizer it then flies its initial setpoints. A lockstep plant waits
        meanwhile; a plant that had been steered flies neutral (command_timeout).
        """
        age = time.monotonic() - self._t_up
        if age < SETPOINTS_WAIT and (age < SETPOINTS_GRACE or self.count_publishers(SETPOINTS) > 0):
            self.get_logger().info("waiting for the setpoints on /rto/setpoints before steering",
                                   throttle_duration_sec=2.0)
            return True
        if self.count_publishers(SETPOINTS) > 0:
            self.get_logger().warning(f"no valid setpoints on /rto/setpoints within {SETPOINTS_WAIT:g} s: flying "
                                      f"{self._fmt(self.controller.setpoints)}")
        self._setpoints_in = True                       # stop waiting (and asking the graph)
        return False

    def _reject_jump(self) -> None:
        stamp = self._jump[0]
        self._jump = None
        self._reject("state stamp", f"rejected state message stamped {stamp * 1e-9:.3f} s at sim time "
                                    f"{self._last_stamp * 1e-9:.3f} s: stale or future, and no anemometer reading "
                                    "with that stamp (not a plant restart)")

    def _process(self, held) -> None:
        if held is self._pending:
            self._pending = None
        elif held is self._jump:
            self._jump = None
        stamp, stamp_msg, pos, vel = held
        last = self._last_stamp
        if stamp == last:
            self._answer(stamp_msg, self._last_delta)      # re-published sample: same answer
            return
        wind = self._winds.pop(stamp, None)
        if last is not None and not last < stamp <= last + MAX_STAMP_GAP_NS:
            if not self._new_timeline(stamp, stamp_msg, pos, vel, wind):
                return
        elif self._candidate is not None:
            self._drop_candidate()
        if wind is not None:
            self._wind = wind
        if self._winds:
            self._drop_winds(stamp)
        m = SimpleNamespace(t=stamp * 1e-9, theta=pos[0], phi=pos[1], psi=pos[2], theta_dot=vel[0], phi_dot=vel[1],
                            psi_dot=vel[2], wind_ref=self._wind)
        if self._sync and self._wait_for_sync(stamp):
            self._sync_held = (stamp, stamp_msg, m, pos, time.monotonic())
            return
        self._steer(stamp, stamp_msg, m, pos)

    def _steer(self, stamp: int, stamp_msg, m, pos) -> None:
        """Answer the sample ``m`` (stamp in ns) with a steering command and update the lap statistics."""
        delta = self.controller.command(m)
        self._last_stamp, self._last_delta = stamp, delta
        self._answer(stamp_msg, delta)
        lap = self.laps.update(m.t, pos[0], pos[1], self._tension, self._altitude,
                               self.controller.status.cross_track, m.wind_ref)
        if lap is not None:
            self.publish_lap(stamp_msg, lap)

    def _new_timeline(self, stamp: int, stamp_msg, pos, vel, wind) -> bool:
        """A complete sample off the timeline (stamped before the last one, or far after it): True to fly on with it.

        The first one is only a candidate; the next complete sample confirms it when it continues the candidate
        (a later stamp within MAX_STAMP_GAP_NS), and the old timeline going on instead drops it as junk. A restart
        candidate is answered by a fresh controller (a restarted lockstep plant waits for that answer), which is
        kept if the restart is confirmed; the flying controller never sees the candidate.
        """
        last, cand = self._last_stamp, self._candidate
        if cand is not None and cand[0] < stamp <= cand[0] + MAX_STAMP_GAP_NS:
            self._candidate = self._pending = None
            if stamp < last:
                self.get_logger().warning(f"sim time jumped back ({last * 1e-9:.2f} s -> {cand[0] * 1e-9:.2f} s): "
                                          "plant restarted, re-synchronizing")
                self.controller = cand[1]
                self.laps.reset()
            else:
                self.get_logger().warning(f"sim time jumped forward ({last * 1e-9:.2f} s -> {cand[0] * 1e-9:.2f} s): "
                                          "samples were lost")
            return True
        if cand is not None and cand[0] == stamp:           # the candidate re-published: the same answer
            if cand[1] is not None:
                self._answer(stamp_msg, cand[2])
            return False
        if cand is not None:
            self._drop_candidate()
        if stamp < last:
            fresh = PathController(shared_model(), self.params, self.controller.setpoints, self.settings)
            m = SimpleNamespace(t=stamp * 1e-9, theta=pos[0], phi=pos[1], psi=pos[2], theta_dot=vel[0],
                                phi_dot=vel[1], psi_dot=vel[2], wind_ref=self._wind if wind is None else wind)
            delta = fresh.command(m)
            self._candidate = (stamp, fresh, delta)
            self._answer(stamp_msg, delta)
        else:
            self._candidate = (stamp, None, 0.0)
        return False

    def _drop_candidate(self) -> None:
        stamp = self._candidate[0]
        self._candidate = None
        self._reject("state stamp", f"rejected state sample stamped {stamp * 1e-9:.3f} s at sim time "
                                    f"{self._last_stamp * 1e-9:.3f} s: stale or future, and the timeline went on "
                                    "(not a plant restart)")

    def _drop_winds(self, stamp: int) -> None:
        """Forget readings older than the answered sample; reject those far from it (stale or future junk)."""
        winds = self._winds
        for s in list(winds):
            if s < stamp or s > stamp + MAX_STAMP_GAP_NS:
                v = winds.pop(s)
                if abs(s - stamp) > MAX_STAMP_GAP_NS:
                    self._reject("wind stamp", f"rejected wind message {v!r} stamped {s * 1e-9:.3f} s at sim "
                                               f"time {stamp * 1e-9:.3f} s: stale or future (no state sample has "
                                               "that stamp)")

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
            self._reject("setpoints", f"rejected setpoints message {(names, list(msg.position))!r}: expected names "
                                      "theta_0, A_phi, A_theta with 3 values (rad)")
            return
        values = dict(zip(names, msg.position))
        c = [values[n] for n in Setpoints.names()]
        if self._synchronized():               # applied with the sample the optimizer decided them at
            if not self._setpoints_in:
                self.get_logger().info(f"new setpoints {self._fmt(Setpoints.from_array(c))} received; synchronized "
                                       "with the optimizer: setpoints apply at the sample of its /rto/sync")
            self._setpoints_msg = c
            self._setpoints_in = True
            return
        if self._apply_setpoints(c):
            self._setpoints_msg = c
            self._setpoints_in = True

    def _apply_setpoints(self, c) -> bool:
        """Fly the setpoints ``c`` (rad): at once before the first sample, else blended; False if refused."""
        try:
            if self._last_stamp is None:       # nothing flown yet: start on the new path, no blend
                self.controller = PathController(shared_model(), self.params, c, self.settings)
                accepted = self.controller.setpoints
            else:
                accepted = self.controller.set_setpoints(c)
        except SetpointError as err:
            self._reject("setpoints value", f"rejected setpoints: {err}; keeping "
                                            f"{self._fmt(self.controller.setpoints)}")
            return False
        self.laps.reset()
        self.get_logger().info(f"new setpoints {self._fmt(accepted)}")
        self.publish_path()
        return True

    # ------------------------------------------------------- optimizer synchronization
    # /rto/sync (sync_optimizer:=true): the optimizer publishes, after each sample it has processed, the setpoints
    # in force and the count of its setpoint messages. A sample is answered once its sync message is in; a changed
    # count applies the setpoints first (the pure runner's order: the optimizer sees sample k, then the controller
    # answers it). A held sample is released unsynchronized after sync_timeout, or after SYNC_ABSENT s when no
    # optimizer is in the graph (no publisher of /rto/sync or /rto/setpoints); from then on samples are answered at
    # once and /rto/setpoints applies directly, until a sync message arrives again. The graph is never asked
    # before a sample has waited: a late discovery must not let samples through unsynchronized.
    def _synchronized(self) -> bool:
        return self._sync and not self._sync_lost

    def _optimizer_in_graph(self) -> bool:
        return self.count_publishers(SYNC) > 0 or self.count_publishers(SETPOINTS) > 0

    def _wait_for_sync(self, stamp: int) -> bool:
        """True to hold the sample stamped ``stamp`` for its /rto/sync; applies the sync message if it is in."""
        entry = self._syncs.pop(stamp, None)
        if self._syncs:
            for s in [s for s in self._syncs if s < stamp]:
                del self._syncs[s]
        if entry is not None:
            self._apply_sync(*entry)
            return False
        return not self._sync_lost

    def _apply_sync(self, c, updates: float) -> None:
        if updates != self._sync_updates or c != self.controller.setpoints.as_array().tolist():
            self._sync_updates = updates
            self._apply_setpoints(c)

    def sync_callback(self, msg: JointState) -> None:
        vals = [float(x) for x in msg.position]
        if list(msg.name) != SYNC_NAMES or len(vals) != 4 or not all(map(math.isfinite, vals)):
            self._reject("sync", f"rejected sync message {(list(msg.name), vals)!r}: expected names {SYNC_NAMES} "
                                 "with 4 finite values")
            return
        stamp = stamp_to_ns(msg.header.stamp)
        if not self._stamp_near("sync", msg.header.stamp):
            return
        if self._sync_lost:
            self._sync_lost = False
            self.get_logger().info("/rto/sync is back: answering each sample after the optimizer again")
        held = self._sync_held
        if held is not None and held[0] == stamp:
            self._sync_held = None
            self._apply_sync(vals[:3], vals[3])
            self._steer(*held[:4])
        elif self._last_stamp is None or stamp > self._last_stamp:
            if len(self._syncs) >= 64:
                del self._syncs[next(iter(self._syncs))]
            self._syncs[stamp] = (vals[:3], vals[3])

    def _sync_watchdog(self) -> None:
        held = self._sync_held
        if held is None:
            return
        waited = time.monotonic() - held[4]
        if waited > self._sync_timeout:
            self._release_unsynced(f"no /rto/sync within sync_timeout = {self._sync_timeout:g} s")
        elif waited > SYNC_ABSENT and not self._optimizer_in_graph():
            self._release_unsynced(f"no optimizer in the graph after {SYNC_ABSENT:g} s")

    def _release_unsynced(self, why: str) -> None:
        """Answer the held sample with the latest /rto/setpoints; answer at once until /rto/sync is back."""
        stamp, stamp_msg, m, pos, _ = self._sync_held
        self._sync_held = None
        self._sync_lost = True
        self.get_logger().warning(f"sample at {stamp * 1e-9:.2f} s: {why}; steering unsynchronized until the "
                                  "optimizer's /rto/sync is back")
        c = self._setpoints_msg
        if c is not None and c != self.controller.setpoints.as_array().tolist():
            self._apply_setpoints(c)
        self._steer(stamp, stamp_msg, m, pos)

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

    def _reject(self, key: str, text: str) -> None:
        self._reject_log(key, text)

    @staticmethod
    def _fmt(c: Setpoints) -> str:
        return "theta_0 {:.1f} deg, A_phi {:.1f} deg, A_theta {:.1f} deg".format(*c.degrees())


def main(args=None) -> None:
    raise SystemExit(run_node(ControllerNode, args, events=True))


if __name__ == "__main__":
    main()
