"""In-process observer of a running graph: keeps the samples, laps and setpoints it hears (for reports)."""
from __future__ import annotations

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from ..nodes.interface import LATCHED, RELIABLE_10, stamp_to_ns
from ..nodes.topics import LAPS, SETPOINTS, STATE, STATUS

__all__ = ["Recorder"]

DEEP = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)


class Recorder(Node):
    """Records /kite/state (t, theta, phi), /kite/laps and /rto/setpoints; keeps the last /rto/status."""

    def __init__(self):
        super().__init__("kite_rto_recorder")
        self.samples: list[tuple] = []
        self.laps: list[dict] = []
        self.setpoints: list[tuple] = []
        self.status: dict = {}
        self.create_subscription(JointState, STATE, self.state_callback, DEEP)
        self.create_subscription(JointState, LAPS, self.lap_callback, DEEP)
        self.create_subscription(JointState, SETPOINTS, self.setpoints_callback, LATCHED)
        self.create_subscription(DiagnosticArray, STATUS, self.status_callback, RELIABLE_10)

    def state_callback(self, msg: JointState) -> None:
        t = stamp_to_ns(msg.header.stamp) * 1e-9
        if not self.samples or t > self.samples[-1][0]:
            self.samples.append((t, msg.position[0], msg.position[1]))

    def lap_callback(self, msg: JointState) -> None:
        lap = dict(zip(msg.name, msg.position))
        lap["t_end"] = stamp_to_ns(msg.header.stamp) * 1e-9
        self.laps.append(lap)

    def setpoints_callback(self, msg: JointState) -> None:
        values = dict(zip(msg.name, msg.position))
        t = self.samples[-1][0] if self.samples else 0.0
        self.setpoints.append((t, values.get("theta_0"), values.get("A_phi"), values.get("A_theta")))

    def status_callback(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            if st.name == "kite_rto/optimizer":
                self.status = {kv.key: kv.value for kv in st.values}

    @property
    def sim_time(self) -> float:
        """Stamp of the last sample heard, s (0 before the first)."""
        return self.samples[-1][0] if self.samples else 0.0

    def arrays(self):
        """(t, theta, phi) as arrays."""
        a = np.array(self.samples, dtype=float).reshape(-1, 3)
        return a[:, 0], a[:, 1], a[:, 2]
