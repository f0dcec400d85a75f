"""Plant node: simulates the real kite, owns the simulation clock, publishes measurements, takes steering.

Modes: ``lockstep`` publishes sample k and advances only when the steering command stamped with sample k's time
arrives (deterministic, as fast as the loop allows; a lost message is recovered by re-publishing the sample);
``realtime`` advances at wall-clock pace times ``rate_factor`` with a zero-order hold on the last command.
Real time: without commands for ``command_timeout`` seconds (wall clock) the kite flies neutral (delta = 0) and says
so. Lockstep: the plant waits for each answer as long as a publisher of /kite/steering is in the graph (so what the
kite flies never depends on how fast the machine is), and flies neutral, keeping its clock going, only once none is
and ``command_timeout`` s have passed (the controller left, or DDS dropped a killed or frozen one); this starts after
the first command, so a run does not depend on how long the controller takes to start.
Real time also measures the lag of the steering commands and lowers a ``rate_factor`` the machine cannot hold
(:mod:`kite_rto.runtime.pace`). One plant per graph: a plant refuses to start where another one runs, and warns when a
second publisher of its topics appears (:mod:`kite_rto.nodes.plant_guard`). At start-up it publishes what it
simulates on ``/kite/plant_config`` (latched: its :class:`~kite_rto.kite.plant.PlantConfig` as JSON), which the
optimizer stores in its run's description. In lockstep it also waits for lossless recorders (``kite_record
--lossless``: :mod:`kite_rto.runtime.recorder_gate`), at most ``recorder_timeout`` s at a time.
"""
from __future__ import annotations

import time

from geometry_msgs.msg import PointStamped, Vector3Stamped, WrenchStamped
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, String, UInt32

from ..kite.plant import KitePlant
from ..runtime.pace import RealtimePacer
from ..runtime.recorder_gate import WINDOW_SAMPLES, RecorderGate
from ..runtime.run_description import plant_json
from ..runtime.sample_join import RejectLog
from ..runtime.sources import node_name
from .interface import LATCHED, MEASUREMENTS, RELIABLE_10, finite_floats, ns_to_stamp, stamp_to_ns
from .parameters import declare_params
from .plant_config import PARAMS, config_from_params
from .plant_guard import WATCH_PERIOD, SecondPublisherWatch, refuse_if_another_plant
from .spin import request_exit, run_node
from .topics import CLOCK, CRASHES, PLANT_CONFIG, POSITION, RECORDED, STATE, STEERING, TENSION, WIND

FLUSH_TIMEOUT = 60.0
"""Wall s the plant waits at the end of its ``duration`` for readers to acknowledge its last samples."""

__all__ = ["PlantNode", "PARAMS", "main"]

_LATE_NS = 500_000_000
"""A steering command stamped up to 0.5 s before the current sample is late, not stale (both modes)."""

def _state_msg(stamp, position, velocity) -> JointState:
    s = JointState(name=["theta", "phi", "psi"], position=position, velocity=velocity)
    s.header.stamp = stamp
    s.header.frame_id = "anchor"
    return s


def _position_msg(stamp, v) -> PointStamped:
    p = PointStamped()
    p.header.stamp = stamp
    p.header.frame_id = "anchor"
    p.point.x, p.point.y, p.point.z = v
    return p


def _tension_msg(stamp, tension: float) -> WrenchStamped:
    w = WrenchStamped()
    w.header.stamp = stamp
    w.header.frame_id = "tether"
    w.wrench.force.x = tension
    return w


def _wind_msg(stamp, wind: float) -> Vector3Stamped:
    w = Vector3Stamped()
    w.header.stamp = stamp
    w.header.frame_id = "anchor"
    w.vector.x = wind
    return w


class PlantNode(Node):
    """Publishes /clock and the kite's measurements; subscribes /kite/steering."""

    def __init__(self, **kwargs):
        super().__init__("plant", **kwargs)
        self.p = declare_params(self, PARAMS, apply=self.apply_params)
        # exit 2 if another plant already publishes our topics (unless one_plant_check:=false)
        silent = refuse_if_another_plant(self) if self.p["one_plant_check"] else set()
        self.plant = KitePlant(config_from_params(self.p), seed=self.p["seed"])
        self._dt_ns = round(self.p["dt"] * 1e9)
        self._lockstep = self.p["mode"] == "lockstep"
        self._end_step = round(self.p["duration"] / self.p["dt"]) if self.p["duration"] > 0 else None
        self.pub_clock = self.create_publisher(ClockMsg, CLOCK, MEASUREMENTS)
        self.pub_state = self.create_publisher(JointState, STATE, MEASUREMENTS)
        self.pub_position = self.create_publisher(PointStamped, POSITION, MEASUREMENTS)
        self.pub_tension = self.create_publisher(WrenchStamped, TENSION, MEASUREMENTS)
        self.pub_wind = self.create_publisher(Vector3Stamped, WIND, MEASUREMENTS)
        self.pub_crashes = self.create_publisher(UInt32, CRASHES, LATCHED)
        self.pub_crashes.publish(UInt32(data=0))
        self.pub_config = self.create_publisher(String, PLANT_CONFIG, LATCHED)    # what the plant is, for the
        self.pub_config.publish(String(data=plant_json(self.plant.config)))      # optimizer's run description
        self.create_subscription(JointState, STEERING, self.steering_callback, RELIABLE_10)
        self._gate = None                  # lockstep: the lossless recorders the next sample waits for
        if self._lockstep:
            self.create_subscription(Header, RECORDED, self.recorded_callback, RELIABLE_10)
            self._gate = RecorderGate(WINDOW_SAMPLES * self._dt_ns, self.p["recorder_timeout"], clock=time.monotonic,
                                      log=self.get_logger(), recorders=self._recorders)
        self._held = None                  # a command whose step waits for a lossless recorder
        self._finished = False             # the duration is reached: no more steps
        self._exiting = False
        self._first_answer = None          # (wall time, step) of the first accepted command: throughput log
        self._delta = 0.0                 # last valid command (realtime zero-order hold)
        self._last_command = time.monotonic()
        self._last_publish = time.monotonic()
        self._neutral = False
        self._commands = 0
        self._sample0_to_all = False     # sample 0 published while every expected subscriber was matched
        self._crashes = 0
        self._reject = RejectLog(self.get_logger())        # throttled warnings about bad steering messages
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._pacer = None if self._lockstep else RealtimePacer(self.p["dt"], self.p["rate_factor"], time.monotonic())
        self._pace_warned = False
        if self._lockstep:
            self._timer = self.create_timer(self._timer_period(self.p), self.watchdog_callback, clock=steady)
        else:
            self._timer = self.create_timer(self._timer_period(self.p), self.realtime_callback, clock=steady)
        self.create_timer(WATCH_PERIOD, SecondPublisherWatch(self, silent).check, clock=steady)
        self.publish_sample()
        self.get_logger().info(f"plant up: mode={self.p['mode']} dt={self.p['dt']} s seed={self.p['seed']}")

    def _timer_period(self, v: dict) -> float:
        """Wall period of the stepping timer: the watchdog (lockstep) or one sample / rate_factor (realtime)."""
        return min(0.05, v["resend_period"]) if self._lockstep else v["dt"] / v["rate_factor"]

    def apply_params(self, changes: dict) -> None:
        """Runtime parameters: ``rate_factor`` and ``resend_period`` re-time the stepping timer, ``duration`` moves
        the end (a time already passed ends the run at the next step); ``command_timeout`` and
        ``wait_subscribers`` are read where they are used."""
        v = {**self.p, **changes}
        if "duration" in changes:
            self._end_step = round(v["duration"] / v["dt"]) if v["duration"] > 0 else None
        if self._pacer is not None and "rate_factor" in changes:
            self._pacer.request(v["rate_factor"], time.monotonic())
            self._pace_warned = False
        period_ns = round(self._timer_period(v) * 1e9)
        if period_ns != self._timer.timer_period_ns:
            self._timer.timer_period_ns = period_ns

    # -------------------------------------------------------------- callbacks
    def steering_callback(self, msg: JointState) -> None:
        """A steering command: ``delta`` stamped with the sample it answers."""
        if self._finished:
            return
        stamp, position = stamp_to_ns(msg.header.stamp), msg.position
        values = finite_floats(position, 1)
        if values is None or abs(values[0]) > 1.0:
            self._reject("steering", f"rejected steering {list(position)!r}: expected one finite delta in [-1, 1]")
            return
        now = self.plant.k * self._dt_ns
        if self._lockstep:
            if stamp != now:
                # A late answer to an earlier sample (a duplicate after a re-publish) is normal: ignore it. A
                # future stamp, or one older than 0.5 s, answers no sample this plant published: reject it.
                if stamp > now or now - stamp > _LATE_NS:
                    self._reject("steering stamp", f"rejected steering stamped {stamp * 1e-9:.3f} s at sim time "
                                                   f"{now * 1e-9:.3f} s (stale or future)")
                return
            if not self._commands and not self._sample0_to_all:
                # Hold sample 0 until every expected observer is connected. A subscriber that the writer matched
                # after the answered copy went out may never get it (volatile durability), so answer only a copy
                # published once all are matched: publish it again now and go on when that one is answered.
                if self.pub_state.get_subscription_count() < self.p["wait_subscribers"]:
                    self._waiting_log()
                else:
                    self.publish_sample()
                return
        elif stamp <= now:
            self._pacer.command((now - stamp) / self._dt_ns)        # accepted or stale: either tells the lag
        if not self._lockstep and (stamp > now or now - stamp > max(5 * self._dt_ns, _LATE_NS)):
            self._reject("steering stamp", f"rejected steering stamped {stamp * 1e-9:.3f} s at sim time "
                                           f"{now * 1e-9:.3f} s (stale or future)")
            return
        self._delta = values[0]
        self._command_received()
        if self._lockstep:
            self._step(self._delta)

    def recorded_callback(self, msg: Header) -> None:
        """A lossless recorder has written every sample through ``msg.stamp``; a held step may go on."""
        self._gate.ack(msg.frame_id, stamp_to_ns(msg.stamp), self.plant.k * self._dt_ns)
        if self._finished:
            self._end()
        elif self._held is not None:
            self._step(self._held)

    def _recorders(self) -> set:
        """The nodes that publish /kite/recorded now."""
        return {node_name(i.node_name, i.node_namespace)
                for i in self.get_publishers_info_by_topic(self.resolve_topic_name(RECORDED))}

    def _step(self, delta: float) -> None:
        """Lockstep: advance with ``delta``, unless a lossless recorder lags a window behind (then hold it)."""
        if not self._gate.may_publish((self.plant.k + 1) * self._dt_ns):
            self._held = delta
            return
        self._held = None
        self.advance(delta)

    def _waiting_log(self) -> None:
        self.get_logger().info(f"waiting for {self.p['wait_subscribers']} subscribers of /kite/state "
                               f"({self.pub_state.get_subscription_count()} connected)", throttle_duration_sec=5.0)

    def watchdog_callback(self) -> None:
        """Lockstep: re-publish an unanswered sample; fly neutral only when no steering writer is in the graph.

        Before the first command ever arrives the plant only waits (and re-publishes), so a lockstep run does
        not depend on how long the controller takes to start. After that it waits for each answer as long as a
        publisher of /kite/steering is in the graph, however long the answer takes (the controller may be waiting
        for a slow optimizer, or the machine may be busy): what the kite flies never depends on wall time. Once
        none is (the controller left, or DDS dropped a killed or frozen one after its participant lease) and
        ``command_timeout`` s have passed without a command, it flies neutral and keeps its clock going.
        """
        if self._finished:
            self._end()
            return
        if self._held is not None:         # the sample is answered; its step waits for a recorder
            self._step(self._held)
            return
        now = time.monotonic()
        silent = now - self._last_command
        if self._commands and silent > self.p["command_timeout"] and self.count_publishers(STEERING) == 0:
            self._fly_neutral()
            self.advance(0.0)
            return
        if self._commands and silent > self.p["command_timeout"]:
            self.get_logger().info(f"lockstep: waiting {silent:.0f} s for the steering of sample "
                                   f"{self.plant.k * self.p['dt']:.2f} s (its controller is in the graph)",
                                   throttle_duration_sec=10.0)
        if now - self._last_publish > self.p["resend_period"]:
            self.publish_sample()

    def realtime_callback(self) -> None:
        if self._finished:
            return
        if time.monotonic() - self._last_command > self.p["command_timeout"]:
            self._fly_neutral()
            self._delta = 0.0
        self.advance(self._delta)
        change = self._pacer.step(time.monotonic())
        if change is not None:
            self._pace(change)

    def _pace(self, change) -> None:
        """The pacer changed the effective rate (or found it too high at its floor): re-time, say so (the first
        time as one warning line, then throttled)."""
        self._timer.timer_period_ns = round(self.p["dt"] / change.rate * 1e9)
        warn = change.slower and not self._pace_warned
        self._pace_warned |= warn
        line = change.message(self.p["dt"], first=warn)
        if warn:
            self.get_logger().warning(line)
        elif change.rate == change.requested:
            self.get_logger().info(line)
        else:
            self.get_logger().info(line, throttle_duration_sec=10.0)

    # ---------------------------------------------------------------- helpers
    def advance(self, delta: float) -> None:
        m = self.plant.step(delta)
        if m.crashes != self._crashes:
            self._crashes = m.crashes
            self.get_logger().error(f"kite crashed at t = {m.t:.2f} s (crash #{m.crashes}): relaunched")
            self.pub_crashes.publish(UInt32(data=m.crashes))
        self.publish_sample()
        if self._end_step is not None and self.plant.k >= self._end_step:
            self._finished = True
            self.get_logger().info(f"duration reached at t = {m.t:.2f} s; crashes: {m.crashes}; "
                                   f"{self._throughput()}")
            self._end()

    def _end(self) -> None:
        """After the last sample: once every lossless recorder has written it (lockstep; at most
        ``recorder_timeout`` s), wait for the readers' acknowledgements and exit."""
        if self._exiting:
            return
        last = self.plant.k * self._dt_ns
        if self._gate is not None and not self._gate.may_publish(last + self._gate.window_ns):
            return                         # a recorder has not written the last sample yet: the next ack or tick
        self._exiting = True
        self._flush()
        request_exit(self, 0)              # SystemExit under rclpy.spin; a flag under run_node's events loop

    def _flush(self) -> None:
        """Before exiting: wait (at most FLUSH_TIMEOUT wall s) until every reader has acknowledged every sample, so
        a recorder or monitor that lags behind on a busy machine still gets the last ones."""
        for pub in (self.pub_clock, self.pub_tension, self.pub_position, self.pub_wind, self.pub_state,
                    self.pub_crashes):
            if not pub.wait_for_all_acked(Duration(seconds=FLUSH_TIMEOUT)):
                self.get_logger().warning(f"{pub.topic_name}: not every reader acknowledged the last samples "
                                          f"within {FLUSH_TIMEOUT:g} s")

    def _throughput(self) -> str:
        if self._first_answer is None:
            return "no steering command received"
        wall, k0 = self._first_answer
        wall = time.monotonic() - wall
        steps = self.plant.k - k0
        return (f"{self.p['mode']}: {steps} steps in {wall:.4f} s wall since the first steering command "
                f"({steps * self.p['dt'] / max(wall, 1e-9):.1f}x real time)")

    def _command_received(self) -> None:
        self._commands += 1
        self._last_command = time.monotonic()
        if self._first_answer is None:
            self._first_answer = (self._last_command, self.plant.k)
        if self._neutral:
            self._neutral = False
            self.get_logger().info("steering commands are back")

    def _fly_neutral(self) -> None:
        if not self._neutral:
            self._neutral = True
            self.get_logger().warning(f"no steering command for {self.p['command_timeout']} s: flying neutral "
                                      "(delta = 0)")

    def publish_sample(self) -> None:
        """Publish /clock and every measurement of the current sample, all stamped with its sim time."""
        m = self.plant.measure()
        stamp = ns_to_stamp(self.plant.k * self._dt_ns)
        self.pub_clock.publish(ClockMsg(clock=stamp))
        self.pub_tension.publish(_tension_msg(stamp, m.tension))
        self.pub_position.publish(_position_msg(stamp, m.position))
        self.pub_wind.publish(_wind_msg(stamp, m.wind_ref))
        # last: in lockstep its arrival means the sample is complete
        self.pub_state.publish(_state_msg(stamp, [m.theta, m.phi, m.psi], [m.theta_dot, m.phi_dot, m.psi_dot]))
        self._last_publish = time.monotonic()
        if not self._sample0_to_all and self.pub_state.get_subscription_count() >= self.p["wait_subscribers"]:
            self._sample0_to_all = True


def main(args=None) -> None:
    raise SystemExit(run_node(PlantNode, args, events=True))


if __name__ == "__main__":
    main()
