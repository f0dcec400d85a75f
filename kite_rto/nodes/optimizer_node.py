"""Optimizer node: Generalized Modifier Adaptation on the flying kite.

Drives :class:`kite_rto.rto.session.RTOSession` (the same per-sample logic as the pure runner): subscribes the
plant's measurements (joined by stamp), runs GMA's nominal and perturbation experiments, publishes
``/rto/setpoints`` (reliable + transient-local) and ``/rto/status`` (diagnostic_msgs), and writes every finished
experiment and iteration to an SQLite database, from which a restarted optimizer resumes.

After each plant sample it has processed it publishes ``/rto/sync`` (sensor_msgs/JointState stamped with the sample's
time: the setpoints in force, rad, and ``updates``, the number of setpoint messages this optimizer has published). A
controller started with ``sync_optimizer:=true`` answers a sample only after its sync message, so in lockstep a
setpoint change takes effect at the same sample as in the pure runner and the graph flies the same sequence.
"""
from __future__ import annotations

import math
import os
from dataclasses import replace

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, Vector3Stamped, WrenchStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import UInt32

from ..rto.session import KiteRTOSettings, RTOSession, make_kite_gma
from ..kite.params import KiteParams, ParameterError
from ..flight.path import Setpoints, SetpointError, ShapeBox, setpoints_from_shape, validate_setpoints
from ..gma import HistoryStore
from .interface import LATCHED, MEASUREMENTS, RELIABLE_10, ns_to_stamp, stamp_to_ns
from .parameters import ParamSpec, declare_params
from .spin import request_exit, run_node
from ..flight.sample_join import POSITION_MAX, TENSION_MAX, WIND_MAX, RejectLog, SampleJoin, state_values
from .topics import CRASHES, POSITION, SETPOINTS, STATE, STATUS, SYNC, SYNC_NAMES, TENSION, WIND

__all__ = ["OptimizerNode", "PARAMS", "main"]

_S = KiteRTOSettings()
_E = _S.experiment
PARAMS = (
    ParamSpec("db", "rto.sqlite", "SQLite file of experiments and iterations (resume source), in an existing "
              "directory"),
    ParamSpec("resume", True, "continue from the database if it holds a run"),
    ParamSpec("n_iter", 10, "GMA iterations to run, then hold the last setpoints (0 = no limit)", 0, 10000,
              unit="iterations", runtime=True),
    ParamSpec("exit_when_done", False, "exit (code 0) once n_iter iterations are done (needs n_iter > 0)",
              runtime=True),
    ParamSpec("n_laps", _E.n_laps, "whole laps averaged per experiment", 1, 100, unit="laps"),
    ParamSpec("settle_laps", _E.settle_laps, "whole laps dropped after a setpoint change", 0, 100, unit="laps"),
    ParamSpec("settle_time", _E.settle_time, "simulated time after a setpoint change before a lap may count "
              "(< max_duration)", 0.0, 600.0, unit="s"),
    ParamSpec("max_duration", _E.max_duration, "simulated time after which an experiment ends with what it has",
              1.0, 1e5, unit="s"),
    ParamSpec("normalize", _E.normalize, "normalize lap tension by the measured reference wind"),
    ParamSpec("h_min", _E.h_min, "minimum altitude (the constraint)", 0.0, 1000.0, unit="m"),
    ParamSpec("gradient", _S.gradient, "plant gradient estimation: directional (DMA: privileged directions "
              "only), or finite differences in every shape coordinate", choices=("directional", "forward",
                                                                                 "central", "least_squares")),
    ParamSpec("n_directions", _S.n_directions, "privileged directions measured per iteration (gradient "
              "directional), at most the setpoints not held at a robustly active bound (2 on the default box, "
              "where theta_0 is held)", 1, 3, unit="directions"),
    ParamSpec("fd_step", float(_S.fd_step[0]), "finite-difference step (directional: along each direction)",
              0.01, 1.0, unit="fraction of the shape box width"),
    ParamSpec("filter_gain", _S.filter_gain, "GMA input filter K", 0.01, 1.0, unit="dimensionless"),
    ParamSpec("modifier_filter", _S.modifier_filter, "GMA filter on the gradient modifiers (1 = none)", 0.01, 1.0,
              unit="dimensionless"),
    ParamSpec("trust_radius", _S.trust_radius, "initial trust radius (not below GMA's minimum trust radius)",
              _S.trust_radius_min, 10.0, unit="fraction of the box width"),
    ParamSpec("box_theta_0_deg", [round(math.degrees(v), 9) for v in _S.box.theta_0], "optimizer's theta_0 range [low, high]",
              1.0, 89.0, unit="deg"),
    ParamSpec("box_A_phi_deg", [round(math.degrees(v), 9) for v in _S.box.A_phi], "optimizer's A_phi range [low, high]",
              0.1, 89.0, unit="deg"),
    ParamSpec("box_aspect", list(_S.box.aspect), "optimizer's aspect range [low, high], aspect = A_theta / "
              "sqrt(sin theta_0 A_phi); every point of the box must be trackable", 0.01, 2.0, unit="dimensionless"),
)


def _cross_check(v: dict) -> None:
    """Checks that involve several parameters (start-up and every runtime change)."""
    if not v["settle_time"] < v["max_duration"]:
        raise ParameterError(f"parameters settle_time = {v['settle_time']!r}, max_duration = {v['max_duration']!r}: "
                             "expected settle_time < max_duration (else no lap can count)")
    if v["exit_when_done"] and v["n_iter"] == 0:
        raise ParameterError(f"parameters exit_when_done = {v['exit_when_done']!r}, n_iter = 0: expected n_iter > 0 "
                             "when exit_when_done is true (n_iter = 0 never ends)")


def _shape_box(v: dict) -> ShapeBox:
    """The optimizer's :class:`ShapeBox` from the box parameters; every point of a 3x3x3 grid must track."""
    pairs = {}
    for name, key, scale in (("theta_0", "box_theta_0_deg", math.pi / 180), ("A_phi", "box_A_phi_deg", math.pi / 180),
                             ("aspect", "box_aspect", 1.0)):
        lo, hi = v[key]
        if not lo < hi:
            raise ParameterError(f"parameter {key} = {list(v[key])!r}: expected [low, high] with low < high")
        pairs[name] = (lo * scale, hi * scale)
    try:
        box = ShapeBox(**pairs)
        for x in box.grid(3):
            validate_setpoints(setpoints_from_shape(x), box.setpoint_box(), KiteParams())
    except SetpointError as err:
        raise ParameterError(f"parameters box_theta_0_deg = {list(v['box_theta_0_deg'])}, box_A_phi_deg = "
                             f"{list(v['box_A_phi_deg'])}, box_aspect = {list(v['box_aspect'])}: expected a box "
                             f"whose every point is a trackable figure-eight: {err}") from None
    return box


class OptimizerNode(Node):
    """Runs GMA experiments on the flying kite and publishes setpoints and status."""

    def __init__(self, **kwargs):
        super().__init__("optimizer", **kwargs)
        v = self.p = declare_params(self, PARAMS, apply=self.apply_params, cross_check=_cross_check)
        db_dir = os.path.dirname(os.path.abspath(v["db"]))
        if v["db"] != ":memory:" and not os.path.isdir(db_dir):
            raise ParameterError(f"parameter db = {v['db']!r}: expected a file in an existing directory "
                                 f"({db_dir} is not one)")
        try:
            spec = replace(_E, n_laps=v["n_laps"], settle_laps=v["settle_laps"], settle_time=v["settle_time"],
                           max_duration=v["max_duration"], normalize=v["normalize"], h_min=v["h_min"])
            self.settings = replace(_S, experiment=spec, box=_shape_box(v), gradient=v["gradient"],
                                    n_directions=v["n_directions"], fd_step=(v["fd_step"],) * 3,
                                    filter_gain=v["filter_gain"], modifier_filter=v["modifier_filter"],
                                    trust_radius=v["trust_radius"])
        except ValueError as err:
            raise ParameterError(str(err)) from None
        self.store = HistoryStore(v["db"])
        history = self.store.load() if v["resume"] else None
        try:   # e.g. more privileged directions than setpoints free to move on this box
            self.gma = make_kite_gma(self.settings, history=history)
        except ValueError as err:
            raise ParameterError(f"parameters gradient = {v['gradient']!r}, n_directions = {v['n_directions']}: "
                                 f"{err}") from None
        if history is None:
            self.store.save_history(self.gma.history)
        self.session = RTOSession(self.gma, spec, self.settings.max_repeats)
        self._saved_exp = len(self.gma.history.experiments)
        self._saved_rec = len(self.gma.records)
        self.join = SampleJoin()
        self.pub_setpoints = self.create_publisher(JointState, SETPOINTS, LATCHED)
        self.pub_status = self.create_publisher(DiagnosticArray, STATUS, RELIABLE_10)
        self.pub_sync = self.create_publisher(JointState, SYNC, MEASUREMENTS)
        self._c_published = None               # setpoints of the last /rto/setpoints message (rad)
        self._updates = 0                      # /rto/setpoints messages published by this process
        self.create_subscription(JointState, STATE, self.state_callback, RELIABLE_10)
        self.create_subscription(WrenchStamped, TENSION, self.tension_callback, RELIABLE_10)
        self.create_subscription(PointStamped, POSITION, self.position_callback, RELIABLE_10)
        self.create_subscription(Vector3Stamped, WIND, self.wind_callback, RELIABLE_10)
        self.create_subscription(UInt32, CRASHES, self.crashes_callback, LATCHED)
        self.create_timer(1.0, self.publish_status, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._reject_log = RejectLog(self.get_logger())
        self._crashes_seen = 0                 # last /kite/crashes count of the current plant
        self._crash_offset = 0                 # counts of plants that restarted (their count starts at 0 again)
        self._started = False
        self.done = False
        self.phase = "waiting for the plant"
        first = self.gma.next_request()
        if history is not None:
            self.get_logger().info(f"resumed from {v['db']}: {len(history.experiments)} experiments, "
                                   f"{len(history.iterations)} iterations")
        self.publish_setpoints(setpoints_from_shape(first.c))
        self.get_logger().info(f"optimizer up: first experiment {first.request_id}")

    def apply_params(self, changes: dict) -> None:
        """Runtime parameters: ``n_iter`` (checked at every sample) and ``exit_when_done`` (checked when done).

        Once the run has ended, ``n_iter`` cannot change (restart the node: it resumes from ``db``), and
        setting ``exit_when_done`` to true makes the node exit (code 0) half a second later.
        """
        if "n_iter" in changes and self.done:
            raise ParameterError(f"parameter n_iter = {changes['n_iter']!r}: the run has ended ({self.phase}); "
                                 f"restart the node to run more iterations (it resumes from {self.p['db']})")
        if changes.get("exit_when_done") and self.done and self.phase == "done":
            self.get_logger().info("exit_when_done set after the run ended: exiting")
            self._exit_timer = self.create_timer(0.5, lambda: request_exit(self, 0),
                                                 clock=Clock(clock_type=ClockType.STEADY_TIME))

    # ------------------------------------------------------------ measurements
    def state_callback(self, msg: JointState) -> None:
        try:
            pos, _ = state_values(msg.name, msg.position, msg.velocity)
        except ValueError as err:
            return self._reject("state", f"rejected state message: {err}")
        self._part(msg.header.stamp, "state", pos)

    def tension_callback(self, msg: WrenchStamped) -> None:
        v = msg.wrench.force.x
        if not (math.isfinite(v) and 0.0 <= v <= TENSION_MAX):
            return self._reject("tension", f"rejected tension message {v!r}: expected a finite force in "
                                           f"[0, {TENSION_MAX:g}] N")
        self._part(msg.header.stamp, "tension", v)

    def position_callback(self, msg: PointStamped) -> None:
        p = (msg.point.x, msg.point.y, msg.point.z)
        if not all(math.isfinite(x) and abs(x) <= POSITION_MAX for x in p):
            return self._reject("position", f"rejected position message {list(p)!r}: expected finite coordinates "
                                            f"within +-{POSITION_MAX:g} m")
        self._part(msg.header.stamp, "position", p)

    def wind_callback(self, msg: Vector3Stamped) -> None:
        v = msg.vector.x
        if not (math.isfinite(v) and 0.0 <= v < WIND_MAX):
            return self._reject("wind", f"rejected wind message {v!r}: expected a finite speed in "
                                        f"[0, {WIND_MAX:g}) m/s")
        self._part(msg.header.stamp, "wind", v)

    def crashes_callback(self, msg: UInt32) -> None:
        n = int(msg.data)
        if n < self._crashes_seen:             # a restarted plant counts from 0 again: not a crash, not un-crashed
            self._crash_offset += self._crashes_seen
        self._crashes_seen = n
        self.join.crashes = self._crash_offset + n

    def _part(self, stamp_msg, part: str, value) -> None:
        m = self.join.add(stamp_to_ns(stamp_msg), part, value)
        if self.join.discarded:
            s, parts = self.join.discarded[-1]
            self._reject("stamp", f"discarded {len(self.join.discarded)} sample(s) off the timeline, the last "
                                  f"stamped {s * 1e-9:.3f} s ({', '.join(parts)}) at sim time "
                                  f"{self.join.last * 1e-9:.3f} s: stale or future stamps")
            self.join.discarded.clear()
        if m is None:
            return
        if m.jumped_back:
            self.get_logger().warning(f"sim time jumped back to {m.t:.2f} s: plant restarted, the current "
                                      "experiment starts again")
            self._started = False
        self.on_sample(m)
        self.publish_sync(m.stamp)

    def on_sample(self, m) -> None:
        if self.done:
            return
        if not self._started:
            self._started = True
            if self.session.request is None:
                self.publish_setpoints(self.session.start(m.t))
            else:                                   # plant restart: same request, measured again
                self.session.evaluator.start(m.t, self.session.c)
            self.phase = "experiment"
            return
        request, repeats = self.session.request, self.session.repeats
        new = self.session.on_measurement(m)
        if self.session.request is request and self.session.repeats > repeats:
            self.get_logger().warning(f"experiment {request.request_id} invalid (kite crashed or no lap) at "
                                      f"t = {m.t:.2f} s: its data is discarded, repeating it "
                                      f"({self.session.repeats}/{self.session.max_repeats})")
        self._persist()
        if self.session.failed:
            self.phase = f"failed: {self.session.failed}"
            self.get_logger().error(self.phase)
            self.done = True
        elif self.p["n_iter"] and len(self.gma.records) >= self.p["n_iter"]:
            self.finish()
        elif new is not None:
            self.publish_setpoints(new)

    def _persist(self) -> None:
        exps = self.gma.history.experiments
        for req, res in exps[self._saved_exp:]:
            self.store.save_experiment(req, res)
            self.get_logger().info(f"experiment {req.request_id}: tension {-res.cost:.1f} kN, "
                                   f"g = {res.constraints[0]:+.1f} m, c = {self._deg(req.c)}")
        self._saved_exp = len(exps)
        for rec in self.gma.records[self._saved_rec:]:
            self.store.save_iteration(rec, self.gma.history.pending)
            self.get_logger().info(f"iteration {rec.k}: c_k = {self._deg(rec.c_k)} -> c_next = {self._deg(rec.c_next)}"
                                   f" ({rec.decision})")
            self.publish_status()
        self._saved_rec = len(self.gma.records)

    def finish(self) -> None:
        rec = self.gma.records[-1]
        self.publish_setpoints(setpoints_from_shape(rec.c_next))
        self.done = True
        self.phase = "done"
        self.publish_status()
        self.get_logger().info(f"done: {len(self.gma.records)} iterations; holding c = {self._deg(rec.c_next)}")
        if self.p["exit_when_done"]:
            request_exit(self, 0)

    # ----------------------------------------------------------------- output
    def publish_setpoints(self, c) -> None:
        """Publish setpoints ``c`` (rad) after checking them against the safe box and the turn limit."""
        box = self.settings.box.setpoint_box()
        try:
            validate_setpoints(np.asarray(c, dtype=float), box, KiteParams())
        except SetpointError as err:
            self.get_logger().error(f"refusing to publish unsafe setpoints: {err}")
            self.session.failed = f"unsafe setpoints requested: {err}"
            self.done = True
            return
        msg = JointState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.name = Setpoints.names()
        msg.position = [float(x) for x in c]
        self.pub_setpoints.publish(msg)
        self._c_published = list(msg.position)
        self._updates += 1

    def publish_sync(self, stamp: int) -> None:
        """Tell a synchronized controller that the sample stamped ``stamp`` (ns) is processed (see the module doc)."""
        if self._c_published is None:          # refused the first setpoints: nothing to fly
            return
        msg = JointState()
        msg.header.stamp = ns_to_stamp(stamp)
        msg.name = SYNC_NAMES
        msg.position = [*self._c_published, float(self._updates)]
        self.pub_sync.publish(msg)

    def publish_status(self) -> None:
        st = DiagnosticStatus(name="kite_rto/optimizer", hardware_id="kite_rto")
        st.level = DiagnosticStatus.ERROR if self.session.failed else DiagnosticStatus.OK
        st.message = self.phase
        req = self.session.request
        kv = {"iteration": len(self.gma.records), "phase": self.phase,
              "experiments_done": len(self.gma.history.experiments)}
        if req is not None:
            kv.update(experiment=req.request_id, purpose=req.purpose, setpoints_deg=self._deg(req.c),
                      experiment_t_start=f"{self.session.evaluator.t_start:.2f}")
        if self.gma.records:
            r = self.gma.records[-1]
            kv.update(measured_cost_kN=f"{r.cost:.2f}", measured_constraint_m=f"{r.constraints[0]:.2f}",
                      grad_cost=self._vec(r.grad_cost), grad_constraint=self._vec(r.jac_constraints.ravel()),
                      eps=self._vec(r.eps), lambda_=self._vec(r.lam), mu=self._vec(r.mu.ravel()),
                      c_star_deg=self._deg(r.c_star), c_next_deg=self._deg(r.c_next), decision=r.decision)
        st.values = [KeyValue(key=k.rstrip("_"), value=str(v)) for k, v in kv.items()]
        msg = DiagnosticArray(status=[st])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_status.publish(msg)

    def _reject(self, key: str, text: str) -> None:
        self._reject_log(key, text)

    @staticmethod
    def _deg(x) -> str:
        """Setpoints in degrees of GMA's shape coordinates ``x``."""
        return "(" + ", ".join(f"{math.degrees(v):.2f}" for v in setpoints_from_shape(x)) + ") deg"

    @staticmethod
    def _vec(v) -> str:
        return "[" + ", ".join(f"{x:.4g}" for x in np.asarray(v, dtype=float).ravel()) + "]"

    def destroy_node(self):
        self.store.close()
        return super().destroy_node()


def main(args=None) -> None:
    raise SystemExit(run_node(OptimizerNode, args, events=True))


if __name__ == "__main__":
    main()
