"""Optimizer node: Generalized Modifier Adaptation on the flying kite.

Drives :class:`kite_rto.rto.session.RTOSession` (the same per-sample logic as the pure runner): subscribes the
plant's measurements (joined by stamp), runs GMA's nominal and perturbation experiments, publishes
``/rto/setpoints`` (reliable + transient-local) and ``/rto/status`` (diagnostic_msgs), and writes every finished
experiment and iteration to an SQLite database, from which a restarted optimizer resumes. The run's description
(:class:`~kite_rto.rto.run.RunDescription`: its settings and plant) is stored there (meta key ``run``) and published
on ``/rto/run`` (latched JSON), with the plant once the plant's ``/kite/plant_config`` arrives (a resumed run keeps
the stored one until then).

It hands a controller started with ``sync_optimizer:=true`` its decisions as plans on ``/rto/sync``
(sensor_msgs/JointState stamped with a sample's time; :mod:`kite_rto.runtime.plan`): the setpoints in force and where
its next decision can be due (the end of the experiment that starts at that sample). The controller waits only at
those samples, so in lockstep a setpoint change takes effect at the same sample as in the pure runner and the graph
flies the same sequence, while the optimizer works beside the plant and the controller rather than between them.

A ROS 2 lifecycle (managed) node (docs/interface.md *Pausing and overriding the optimizer*): ``configure`` opens the
database and builds the NLPs and directions on a worker thread (services answer meanwhile), ``activate`` starts or
resumes experiments, ``deactivate`` holds the setpoints in force (the kite keeps flying them; from the end of the
plan in force on, ``/rto/sync`` answers every sample; the experiment in progress is flown again after ``activate``),
``cleanup`` and ``shutdown`` close the database (``shutdown`` then ends the process, code 0). While inactive,
``/rto/manual_setpoints`` (:data:`MANUAL_SETPOINTS`, same type as ``/rto/setpoints``) hands it setpoints to continue
from. Every transition and manual setpoint is stored in the database's event log; a restarted optimizer whose last
``activate`` / ``deactivate`` was a ``deactivate`` comes back inactive. With ``autostart`` (default) it configures
and activates itself at start-up.

Storage (docs/storage.md): a damaged database, one that holds a run while ``resume`` is false, or one made with other
settings stops the node at start-up with exit code 2 (the file untouched); a database that stays unwritable for
``storage_timeout`` s stops it with exit code 3 (:data:`STORAGE_EXIT`), nothing stored lost. Test hook:
``KITE_RTO_TEST_STORE_FULL=KIND:N[:ATTEMPTS]`` (:data:`STORE_FULL_ENV`) makes the database's writes fail like a
full disk (:class:`~kite_rto.runtime.store_fault.DiskFull`).
"""
from __future__ import annotations

import os
import sys

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock, ClockType
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from sensor_msgs.msg import JointState

from ..flight.path import Setpoints
from ..gma import GMA
from ..kite.params import ParameterError
from ..rto.builder import make_gma
from ..rto.run import RUN_KEY, RunDescription
from ..gma import StoreError
from ..rto.session import RTOSession
from ..runtime.gma_build import GMABuild
from ..runtime.operator_log import transition_event, was_paused
from ..runtime.optimizer_run import OptimizerRun
from ..runtime.run_db import SETTINGS_KEY, RunDatabaseError, open_run_database
from ..runtime.run_description import stored_description
from ..runtime.store_fault import DiskFull
from .interface import RELIABLE_10
from .optimizer_params import PARAMS, cross_check, run_settings, settings_from_params
from .optimizer_wire import RunWire, status_message
from .parameters import declare_params
from .spin import request_exit, run_node
from .stop_signals import STOP
from .topics import MANUAL_SETPOINTS, STATUS

__all__ = ["OptimizerNode", "PARAMS", "STORAGE_EXIT", "STORE_FULL_ENV", "main"]

STORAGE_EXIT = 3
"""Exit code of an optimizer that could not write its database for ``storage_timeout`` s."""

STORE_FULL_ENV = "KITE_RTO_TEST_STORE_FULL"
"""Test hook ``KIND:N[:ATTEMPTS]``: the database's writes fail like a full disk (see DiskFull.parse)."""


class OptimizerNode(LifecycleNode):
    """Runs GMA experiments on the flying kite and publishes setpoints and status (a lifecycle node)."""

    def __init__(self, **kwargs):
        super().__init__("optimizer", **kwargs)
        v = self.p = declare_params(self, PARAMS, apply=self.apply_params, cross_check=cross_check)
        db_dir = os.path.dirname(os.path.abspath(v["db"]))
        if v["db"] != ":memory:" and not os.path.isdir(db_dir):
            raise ParameterError(f"parameter db = {v['db']!r}: expected a file in an existing directory "
                                 f"({db_dir} is not one)")
        self.settings = settings_from_params(v)
        self.store = None
        self._open_database(v["resume"])
        self.run = None                        # the GMA run, once built (see _build)
        self.wire = None                       # its topics (RunWire), made with it
        self.state = "unconfigured"            # the lifecycle state (also on /rto/status)
        self.pub_status = self.create_publisher(DiagnosticArray, STATUS, RELIABLE_10)
        self.create_subscription(JointState, MANUAL_SETPOINTS, self.manual_callback, RELIABLE_10)
        self.manual_received = 0               # manual setpoint messages handled (status: an operator tool waits on it)
        self.create_timer(1.0, self._every_second, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._builder = None                   # the GMABuild of the last configure
        self._build_timer = None
        self._start_ticks = 0                  # _finish_start calls while starting (status every 5th)
        paused = was_paused(self.store.events())
        if v["autostart"]:
            self.trigger_configure()
            if paused:
                self.get_logger().warning(f"autostart: {v['db']} says this run was paused (its last transition is a "
                                          "deactivate): staying inactive, holding its setpoints; activate to go "
                                          "on (kite_ctl resume, or ros2 lifecycle set /optimizer activate)")
            else:
                self.trigger_activate()
        elif paused:
            self.get_logger().info(f"{v['db']} says this run was paused: configure, then activate to go on")
        self.publish_status()

    def _open_database(self, resume: bool) -> None:
        """Open ``db`` (refusals: :class:`ParameterError`, exit 2 at start-up) and keep the history to resume."""
        v = self.p
        try:
            fault = DiskFull.parse(os.environ[STORE_FULL_ENV]) if os.environ.get(STORE_FULL_ENV) else None
            self.store, self._history, note = open_run_database(v["db"], run_settings(v), resume, fault=fault)
        except RunDatabaseError as err:
            raise ParameterError(str(err)) from None
        except ValueError as err:
            raise ParameterError(f"{STORE_FULL_ENV} = {os.environ[STORE_FULL_ENV]!r}: {err}") from None
        if note:
            self.get_logger().warning(note)
        if fault is not None:
            self.get_logger().warning(f"{STORE_FULL_ENV} = {os.environ[STORE_FULL_ENV]}: writes to {v['db']} "
                                      f"fail like a full disk from {fault.kind} write {fault.nth} on (test hook)")

    # ------------------------------------------------------------ lifecycle
    def _transition(self, label: str, goal: str, action) -> TransitionCallbackReturn:
        """Run ``action()`` for the transition ``label`` to ``goal``, store it in the event log, log it."""
        start, t = self.state, self._sim_time()
        try:
            action()
        except ParameterError as err:
            print(f"[kite_rto] refusing to start: {err}", file=sys.stderr, flush=True)
            request_exit(self, 2)
            return TransitionCallbackReturn.FAILURE
        except Exception as err:  # noqa: BLE001 - rclpy would swallow it silently
            self.get_logger().error(f"{label} failed: {err!r}")
            return TransitionCallbackReturn.FAILURE
        self.state = goal
        if self.store is not None:
            try:
                self.store.save_progress(events=[transition_event(label, start, goal, t)])
            except StoreError as err:
                self.get_logger().error(f"{label}: not stored in the event log: {err}")
        self.get_logger().info(f"lifecycle: {label}: {start} -> {goal}")
        self.publish_status()
        return TransitionCallbackReturn.SUCCESS

    @property
    def starting(self) -> str:
        """What the start-up is doing (the status until the run exists)."""
        b = self._builder
        return "unconfigured: waiting for configure" if b is None or b.cancelled.is_set() else b.phase

    def _sim_time(self) -> float | None:
        """Sim time of the last sample the run processed, s (None before the first)."""
        last = None if self.run is None else self.run.join.last
        return None if last is None or last < 0 else last * 1e-9

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Open the database (again after a cleanup) and start building GMA on the worker thread; returns at once
        (the node is inactive while it builds, /rto/status says what it builds)."""
        def configure():
            if self.store is None:
                self._open_database(True)      # this process's own run (or a new one): resume it
            self._start_ticks = 0
            # seconds of NLP builds on a worker thread: the services and the status answer meanwhile
            self._builder = GMABuild(self.settings, self._history, self.get_logger(), make=make_gma)
            self._builder.start()
            self._build_timer = self.create_timer(0.05, self._finish_start,
                                                  clock=Clock(clock_type=ClockType.STEADY_TIME))
        return self._transition("configure", "inactive", configure)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Start or resume experiments (still building: once built)."""
        return self._transition("activate", "active", lambda: self.run is not None and self.run.resume())

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Hold the setpoints in force; the experiment in progress is discarded, flown again after activate."""
        return self._transition("deactivate", "inactive", lambda: self.run is not None and self.run.pause())

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Drop the run and close the database (configure builds it again from the database)."""
        result = self._transition("cleanup", "unconfigured", self._stop_build)
        self._close()
        return result

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Drop the run, close the database and end the process (code 0) half a second later."""
        result = self._transition("shutdown", "finalized", self._stop_build)
        self._close()
        self._exit_timer = self.create_timer(0.5, lambda: request_exit(self, 0),
                                             clock=Clock(clock_type=ClockType.STEADY_TIME))
        return result

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.get_logger().error(f"lifecycle error in state {state.label}")
        return TransitionCallbackReturn.FAILURE

    def _stop_build(self) -> None:
        """Stop the worker at its next step and wait for it (CasADi must not run on two threads), drop the run."""
        if self._builder is not None:
            self._builder.cancel()
        if self._build_timer is not None:
            self._build_timer.cancel()
        if self.wire is not None:
            self.wire.destroy()
            self.wire = None
        self.run = None

    def _close(self) -> None:
        if self.store is not None:
            self.store.close()
            self.store = None

    def wait_until_started(self, timeout: float | None = None) -> bool:
        """Block until the start-up work is done and the run is set up (for a node used without spinning, e.g.
        composed in a test); True once :attr:`run` exists."""
        b = self._builder
        if b is not None and b.ready.wait(timeout) and self.run is None:
            self._finish_start()
        return self.run is not None

    def _finish_start(self) -> None:
        """Executor thread: once GMA exists, subscribe, publish the first setpoints (or exit 2 on an error)."""
        if self.run is not None:
            return
        if not self._builder.ready.is_set():    # meanwhile, the phase four times a second (a new monitor sees it)
            self._start_ticks += 1
            if self._start_ticks % 5 == 0:
                self.publish_status()
            return
        self._build_timer.cancel()
        built = self._builder.built
        if self._builder.cancelled.is_set():    # cleaned up meanwhile
            return
        if isinstance(built, ParameterError):
            print(f"[kite_rto] refusing to start: {built}", file=sys.stderr, flush=True)
            return request_exit(self, 2)
        if not isinstance(built, GMA):
            self.get_logger().fatal(f"start-up failed: {built!r}")
            return request_exit(self, 1)
        self.gma, v, history = built, self.p, self._history
        description, note = stored_description(history.meta, self.settings) if history is not None else \
            (RunDescription(self.settings), "")
        if note:
            self.get_logger().warning(note)
        self.wire = wire = RunWire(self)
        self.run = OptimizerRun(self.gma, RTOSession(self.gma, self.settings.experiment, self.settings.max_repeats),
                                self.store, self.settings.box.setpoint_box(), n_iter=v["n_iter"],
                                logger=self.get_logger(), send_setpoints=wire.setpoints, processed=wire.processed,
                                status=self.publish_status, finished=self.finished,
                                storage_lost=lambda: request_exit(self, STORAGE_EXIT),
                                storage_timeout=v["storage_timeout"], description=description,
                                run_meta={SETTINGS_KEY: run_settings(v), RUN_KEY: description.to_dict()})
        wire.attach(self.run)
        first = self.gma.next_request()
        if history is not None:
            self.get_logger().info(f"resumed from {v['db']}: {len(history.experiments)} experiments, "
                                   f"{len(history.iterations)} iterations")
        self.run.begin()                     # stores a new run's start first; publishes nothing until it is stored
        wire.description(description)
        if self.state != "active":
            self.run.pause()                 # configured, not activated: hold the first (or the paused) setpoints
        self.get_logger().info(f"optimizer up ({self.state}): first experiment {first.request_id}")

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
    def manual_callback(self, msg: JointState) -> None:
        """Operator setpoints (rad, names as /rto/setpoints), taken only while inactive; a refusal is a throttled
        warning naming the value and what was expected (and ``manual_setpoints`` on /rto/status)."""
        self.manual_received += 1
        names, values = list(msg.name), [float(x) for x in msg.position]
        if names != Setpoints.names() or len(values) != 3:
            why = (f"names {names}, values {values}: expected names {Setpoints.names()} with 3 values (rad)")
        elif self.run is None or self.state != "inactive":
            why = (f"the optimizer is {self.state}{' (still building)' if self.run is None else ''}: manual "
                   "setpoints are taken only while it is inactive (kite_ctl pause)")
        else:
            why = self.run.manual_setpoints(values, self._sim_time())
        if why:
            if self.run is not None:
                self.run.manual_note = f"refused: {why}"
                self.run.reject("manual", f"refusing manual setpoints: {why}")
            else:
                self.get_logger().warning(f"refusing manual setpoints: {why}", throttle_duration_sec=2.0)
        self.publish_status()

    # ----------------------------------------------------------------- output
    def finished(self) -> None:
        """The run has done its ``n_iter`` iterations: exit if ``exit_when_done``."""
        if self.p["exit_when_done"]:
            request_exit(self, 0)

    def _every_second(self) -> None:
        """Steady 1 Hz: retry a failed database write (also when no sample comes), then the status."""
        if self.run is not None:
            self.run.tick()
        self.publish_status()

    def publish_status(self) -> None:
        self.pub_status.publish(status_message(self.run, self.state, self.starting, self.manual_received,
                                               self.get_clock().now().to_msg()))

    def destroy_node(self):
        # The worker may be inside CasADi, which must not run concurrently with anything else touching CasADi
        # (a test or a composed process going on): let it finish its current step (seconds) before going on,
        # unless the process is stopping on a signal (run_node then ends it without waiting for the worker).
        if self._builder is not None:
            self._builder.cancel(wait=STOP.signum is None)
        self._close()
        done = super().destroy_node()
        # rclpy's LifecycleNode leaves its state machine's services (get_state, change_state, ...) on the graph after
        # destroy_node while the object lives: in a process that goes on (a test, a composed process), a later
        # optimizer's clients would find this dead /optimizer/get_state, ask it, and wait in vain.
        self._state_machine.destroy_when_not_in_use()
        return done


def main(args=None) -> None:
    raise SystemExit(run_node(OptimizerNode, args, events=True))


if __name__ == "__main__":
    main()
