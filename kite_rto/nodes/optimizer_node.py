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
import sys
import threading
from dataclasses import replace

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, Vector3Stamped, WrenchStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import UInt32

from ..flight.path import Setpoints, SetpointError, validate_setpoints
from ..flight.shape import ShapeBox, setpoints_from_shape
from ..gma import GMA, HistoryStore
from ..kite.params import KiteParams, ParameterError
from ..rto.optimizer_run import OptimizerRun
from ..rto.builder import gma_directions, lap_problem, make_gma, model_only_optimum
from ..rto.ocp import KiteOCPSettings
from ..rto.wind_source import WIND_SOURCES
from ..rto.session import RTOSession
from ..rto.settings import KiteRTOSettings
from .interface import LATCHED, MEASUREMENTS, RELIABLE_10, ns_to_stamp, stamp_to_ns
from .parameters import ParamSpec, declare_params
from .spin import request_exit, run_node
from .topics import CRASHES, POSITION, SETPOINTS, STATE, STATUS, SYNC, SYNC_NAMES, TENSION, WIND, WIND_ESTIMATE

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
    ParamSpec("normalize", _E.normalize, "normalize lap tension by the wind of wind_source (false: raw tension)"),
    ParamSpec("wind_source", _E.wind_source, "the wind the lap tension is normalized by: the ground anemometer "
              "(as is, or delayed by the transport lag to the kite) or the observer that estimates the wind at the "
              "kite from its own motion (published on /kite/wind_estimate)", choices=WIND_SOURCES),
    ParamSpec("h_min", _E.h_min, "minimum altitude (the constraint)", 0.0, 1000.0, unit="m"),
    ParamSpec("gradient", _S.gradient, "plant gradient estimation: directional (DMA: privileged directions "
              "only), or finite differences in every shape coordinate", choices=("directional", "forward",
                                                                                 "central", "least_squares")),
    ParamSpec("n_directions", _S.n_directions, "privileged directions measured per iteration (gradient "
              "directional), at most the setpoints not held at a robustly active bound (2 on the default box, "
              "where theta_0 is held)", 1, 3, unit="directions"),
    ParamSpec("fd_step", float(_S.fd_step[0]), "finite-difference step (directional: along each direction)",
              0.01, 1.0, unit="fraction of the shape box width"),
    ParamSpec("filter_gain", _S.gma.filter_gain, "GMA input filter K", 0.01, 1.0, unit="dimensionless"),
    ParamSpec("modifier_filter", _S.gma.modifier_filter, "GMA filter on the gradient modifiers (1 = none)", 0.01, 1.0,
              unit="dimensionless"),
    ParamSpec("trust_radius", _S.gma.trust_radius, "initial trust radius (not below GMA's minimum trust radius)",
              _S.gma.trust_radius_min, 10.0, unit="fraction of the box width"),
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
                           max_duration=v["max_duration"], normalize=v["normalize"], wind_source=v["wind_source"],
                           h_min=v["h_min"])
            self.settings = replace(_S, experiment=spec, box=_shape_box(v), gradient=v["gradient"],
                                    n_directions=v["n_directions"], fd_step=(v["fd_step"],) * 3
                                    ).with_gma(filter_gain=v["filter_gain"], modifier_filter=v["modifier_filter"],
                                               trust_radius=v["trust_radius"])
        except ValueError as err:
            raise ParameterError(str(err)) from None
        self.store = HistoryStore(v["db"])
        history = self.store.load() if v["resume"] else None
        self.run = None                        # the GMA run, once built (see _build)
        self.starting = "starting"             # what the start-up is doing (``/rto/status`` phase meanwhile)
        self.pub_status = self.create_publisher(DiagnosticArray, STATUS, RELIABLE_10)
        self.create_timer(1.0, self.publish_status, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.publish_status()
        # The NLP builds and the model's optimum and directions take seconds (10-14 s when nothing is cached): they
        # run on a worker thread, so parameter services and the status answer from the first second.
        self._built = None
        self._history = history
        self._builder = threading.Thread(target=self._build, args=(history,), name="optimizer-build", daemon=True)
        self._builder.start()
        self._build_timer = self.create_timer(0.05, self._finish_start,
                                              clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _build(self, history) -> None:
        """Worker thread: the model's problem, optimum, directions and GMA (disk-cached where possible)."""
        try:
            s = self.settings
            ocp = KiteOCPSettings(h_min=s.experiment.h_min)
            for what, step in (("building the lap OCP", lambda: lap_problem(s.box, KiteParams(), ocp)),
                               ("solving for the model's optimum", lambda: model_only_optimum(s.box, KiteParams(), ocp)),
                               ("computing the privileged directions", lambda: s.gradient != "directional" or
                                gma_directions(s, KiteParams(), ocp)),
                               ("building GMA's NLPs", lambda: None)):
                self.starting = f"starting: {what}"
                step()
            self._built = make_gma(s, history=history)
        except ValueError as err:       # e.g. more privileged directions than setpoints free to move on this box
            self._built = ParameterError(f"parameters gradient = {self.p['gradient']!r}, n_directions = "
                                         f"{self.p['n_directions']}: {err}")
        except Exception as err:  # noqa: BLE001 - reported and turned into a clean exit by _finish_start
            self._built = err

    def wait_until_started(self, timeout: float | None = None) -> bool:
        """Block until the start-up work is done and the run is set up (for a node used without spinning, e.g.
        composed in a test); True once :attr:`run` exists."""
        self._builder.join(timeout)
        if self.run is None and not self._builder.is_alive():
            self._finish_start()
        return self.run is not None

    def _finish_start(self) -> None:
        """Executor thread: once the worker is done, subscribe, publish the first setpoints (or exit 2 on an error)."""
        if self._builder.is_alive() or self.run is not None:
            return
        self._build_timer.cancel()
        built = self._built
        if isinstance(built, ParameterError):
            print(f"[kite_rto] refusing to start: {built}", file=sys.stderr, flush=True)
            return request_exit(self, 2)
        if not isinstance(built, GMA):
            self.get_logger().fatal(f"start-up failed: {built!r}")
            return request_exit(self, 1)
        self.gma, v, history = built, self.p, self._history
        if history is None:
            self.store.save_history(self.gma.history)
        self.pub_setpoints = self.create_publisher(JointState, SETPOINTS, LATCHED)
        self.pub_sync = self.create_publisher(JointState, SYNC, MEASUREMENTS)
        self.pub_wind_estimate = self.create_publisher(Vector3Stamped, WIND_ESTIMATE, MEASUREMENTS)
        self.run = OptimizerRun(self.gma, RTOSession(self.gma, self.settings.experiment, self.settings.max_repeats),
                                self.store, self.settings.box.setpoint_box(), n_iter=v["n_iter"],
                                logger=self.get_logger(), send_setpoints=self.publish_setpoints,
                                sync=self.publish_sync, status=self.publish_status, finished=self.finished)
        self.session = self.run.session
        self.create_subscription(JointState, STATE, self.state_callback, RELIABLE_10)
        self.create_subscription(WrenchStamped, TENSION, self.tension_callback, RELIABLE_10)
        self.create_subscription(PointStamped, POSITION, self.position_callback, RELIABLE_10)
        self.create_subscription(Vector3Stamped, WIND, self.wind_callback, RELIABLE_10)
        self.create_subscription(UInt32, CRASHES, self.crashes_callback, LATCHED)
        first = self.gma.next_request()
        if history is not None:
            self.get_logger().info(f"resumed from {v['db']}: {len(history.experiments)} experiments, "
                                   f"{len(history.iterations)} iterations")
        self.run.setpoints(setpoints_from_shape(first.c))
        self.get_logger().info(f"optimizer up: first experiment {first.request_id}")

    def apply_params(self, changes: dict) -> None:
        """Runtime parameters: ``n_iter`` (checked at every sample) and ``exit_when_done`` (checked when done).

        Once the run has ended, ``n_iter`` cannot change (restart the node: it resumes from ``db``), and
        setting ``exit_when_done`` to true makes the node exit (code 0) half a second later.
        """
        run = self.run
        if run is None:                        # still starting: the run takes the values when it is built
            return
        if "n_iter" in changes and run.done:
            raise ParameterError(f"parameter n_iter = {changes['n_iter']!r}: the run has ended ({run.phase}); "
                                 f"restart the node to run more iterations (it resumes from {self.p['db']})")
        if "n_iter" in changes:
            run.n_iter = changes["n_iter"]
        if changes.get("exit_when_done") and run.done and run.phase == "done":
            self.get_logger().info("exit_when_done set after the run ended: exiting")
            self._exit_timer = self.create_timer(0.5, lambda: request_exit(self, 0),
                                                 clock=Clock(clock_type=ClockType.STEADY_TIME))

    # ------------------------------------------------------------ subscriptions
    def state_callback(self, msg: JointState) -> None:
        self.run.state_reading(stamp_to_ns(msg.header.stamp), msg.name, msg.position, msg.velocity)

    def tension_callback(self, msg: WrenchStamped) -> None:
        self.run.reading(stamp_to_ns(msg.header.stamp), "tension", msg.wrench.force.x)

    def position_callback(self, msg: PointStamped) -> None:
        self.run.reading(stamp_to_ns(msg.header.stamp), "position", (msg.point.x, msg.point.y, msg.point.z))

    def wind_callback(self, msg: Vector3Stamped) -> None:
        self.run.reading(stamp_to_ns(msg.header.stamp), "wind", msg.vector.x)

    def crashes_callback(self, msg: UInt32) -> None:
        self.run.crashes(int(msg.data))

    # ----------------------------------------------------------------- output
    def finished(self) -> None:
        """The run has done its ``n_iter`` iterations: exit if ``exit_when_done``."""
        if self.p["exit_when_done"]:
            request_exit(self, 0)

    def publish_setpoints(self, c: list) -> None:
        """Publish checked setpoints ``c`` (rad) on /rto/setpoints (latched)."""
        msg = JointState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.name = Setpoints.names()
        msg.position = c
        self.pub_setpoints.publish(msg)

    def publish_sync(self, stamp: int) -> None:
        """Tell a synchronized controller that the sample stamped ``stamp`` (ns) is processed (see the module doc);
        publish the wind the cost normalizes by for it (``/kite/wind_estimate``, m/s at z_ref, ``vector.x``)."""
        w = self.session.evaluator.wind_estimate
        if math.isfinite(w):
            est = Vector3Stamped()
            est.header.stamp = ns_to_stamp(stamp)
            est.header.frame_id = "anchor"
            est.vector.x = float(w)
            self.pub_wind_estimate.publish(est)
        if self.run.c_published is None:        # refused the first setpoints: nothing to fly
            return
        msg = JointState()
        msg.header.stamp = ns_to_stamp(stamp)
        msg.name = SYNC_NAMES
        msg.position = [*self.run.c_published, float(self.run.updates)]
        self.pub_sync.publish(msg)

    def publish_status(self) -> None:
        st = DiagnosticStatus(name="kite_rto/optimizer", hardware_id="kite_rto")
        if self.run is None:
            st.level, st.message = DiagnosticStatus.OK, self.starting
            st.values = [KeyValue(key="phase", value=self.starting)]
        else:
            st.level = DiagnosticStatus.ERROR if self.session.stopped else DiagnosticStatus.OK
            st.message = self.run.phase
            st.values = [KeyValue(key=k, value=str(v)) for k, v in self.run.status_values().items()]
        msg = DiagnosticArray(status=[st])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_status.publish(msg)

    def destroy_node(self):
        self.store.close()
        return super().destroy_node()


def main(args=None) -> None:
    raise SystemExit(run_node(OptimizerNode, args, events=True))


if __name__ == "__main__":
    main()
