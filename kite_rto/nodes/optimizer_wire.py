"""What the optimizer node's run takes from and puts on the wire (:class:`RunWire`), and the node's status message
(:func:`status_message`). Topics, fields and QoS: docs/interface.md."""
from __future__ import annotations

import math

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, Vector3Stamped, WrenchStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import String, UInt32

from ..flight.path import Setpoints
from ..runtime.run_status import status_values
from .interface import LATCHED, LATCHED_10, MEASUREMENTS, ns_to_stamp, stamp_to_ns
from .topics import (CRASHES, PLANT_CONFIG, POSITION, RUN, SETPOINTS, STATE, SYNC, SYNC_NAMES, TENSION, WIND,
                     WIND_ESTIMATE)

__all__ = ["RunWire", "status_message"]


class RunWire:
    """The topics of a configured optimizer's run on ``node``, made once GMA is built and :meth:`destroy` ed at
    cleanup: the publishers (``/rto/setpoints`` and ``/rto/run`` latched, ``/rto/sync``, ``/kite/wind_estimate``) at
    once, the subscriptions to the plant's measurements and configuration by :meth:`attach`, once the run exists."""

    def __init__(self, node):
        self._node = node
        self.run = None
        self._setpoints = node.create_publisher(JointState, SETPOINTS, LATCHED)
        self._sync = node.create_publisher(JointState, SYNC, MEASUREMENTS)
        self._wind_estimate = node.create_publisher(Vector3Stamped, WIND_ESTIMATE, MEASUREMENTS)
        self._run = node.create_publisher(String, RUN, LATCHED)
        self._estimate_stamp = None
        self._subs = []

    def attach(self, run) -> None:
        """Feed the plant's readings, crash counts and configuration to ``run`` (an
        :class:`~kite_rto.runtime.optimizer_run.OptimizerRun`), stamps in ns; publish its description again when
        the plant's configuration changes it."""
        self.run = run

        def plant_config(msg: String):
            described = run.plant_config(msg.data)
            if described is not None:
                self.description(described)

        def state(msg: JointState):
            run.state_reading(stamp_to_ns(msg.header.stamp), msg.name, msg.position, msg.velocity)

        def tension(msg: WrenchStamped):
            run.reading(stamp_to_ns(msg.header.stamp), "tension", msg.wrench.force.x)

        def position(msg: PointStamped):
            run.reading(stamp_to_ns(msg.header.stamp), "position", (msg.point.x, msg.point.y, msg.point.z))

        def wind(msg: Vector3Stamped):
            run.reading(stamp_to_ns(msg.header.stamp), "wind", msg.vector.x)
        sub, deep = self._node.create_subscription, MEASUREMENTS    # the run may fall MAX_LEAD samples behind
        self._subs = [sub(JointState, STATE, state, deep), sub(WrenchStamped, TENSION, tension, deep),
                      sub(PointStamped, POSITION, position, deep), sub(Vector3Stamped, WIND, wind, deep),
                      sub(UInt32, CRASHES, lambda msg: run.crashes(int(msg.data)), LATCHED),
                      sub(String, PLANT_CONFIG, plant_config, LATCHED_10)]

    def setpoints(self, c: list) -> None:
        """Publish checked setpoints ``c`` (rad) on /rto/setpoints (latched), stamped with the node's clock."""
        msg = JointState()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.name = Setpoints.names()
        msg.position = c
        self._setpoints.publish(msg)

    def processed(self, stamp: int, plan) -> None:
        """The run has processed the sample stamped ``stamp`` (ns): the wind the cost normalizes by for it
        (``/kite/wind_estimate``, m/s at z_ref, ``vector.x``; once per sample), then, if ``plan`` is not None, that
        :class:`~kite_rto.runtime.plan.Plan` on ``/rto/sync`` stamped with the sample, for a synchronized
        controller."""
        run = self.run
        w = run.session.evaluator.wind_estimate
        if math.isfinite(w) and stamp != self._estimate_stamp:
            self._estimate_stamp = stamp
            est = Vector3Stamped()
            est.header.stamp = ns_to_stamp(stamp)
            est.header.frame_id = "anchor"
            est.vector.x = float(w)
            self._wind_estimate.publish(est)
        if plan is None:
            return
        msg = JointState()
        msg.header.stamp = ns_to_stamp(stamp)
        msg.name = SYNC_NAMES
        msg.position = plan.values()
        self._sync.publish(msg)

    def description(self, description) -> None:
        """Publish the run's :class:`~kite_rto.rto.run.RunDescription` on /rto/run (latched, JSON)."""
        self._run.publish(String(data=description.to_json()))

    def destroy(self) -> None:
        """Remove the run's publishers and subscriptions from the graph."""
        for pub in (self._setpoints, self._sync, self._wind_estimate, self._run):
            self._node.destroy_publisher(pub)
        for sub in self._subs:
            self._node.destroy_subscription(sub)
        self._subs = []


def status_message(run, lifecycle: str, starting: str, manual_received: int, stamp) -> DiagnosticArray:
    """The optimizer's ``/rto/status``: the status of ``run`` (None while it starts: ``starting`` says what it
    does), its ``lifecycle`` state and the count of manual setpoint messages handled; ``stamp`` a Time message."""
    st = DiagnosticStatus(name="kite_rto/optimizer", hardware_id="kite_rto")
    if run is None:
        st.level, st.message = DiagnosticStatus.OK, starting
        st.values = [KeyValue(key="phase", value=starting)]
    else:
        st.level = DiagnosticStatus.ERROR if run.session.stopped or run.persist.error else DiagnosticStatus.OK
        st.message = run.phase
        st.values = [KeyValue(key=k, value=str(v)) for k, v in status_values(run).items()]
    st.values += [KeyValue(key="lifecycle", value=lifecycle),
                  KeyValue(key="manual_received", value=str(manual_received))]
    msg = DiagnosticArray(status=[st])
    msg.header.stamp = stamp
    return msg
