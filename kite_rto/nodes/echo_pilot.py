"""Echo pilot: the minimal answering client. Answers every /kite/state sample with a constant steering command.

Used to fly the plant in lockstep with neutral steering (the first check of a new install) and by the DDS
lockstep benchmark. Parameter ``delta`` (normalized, [-1, 1], default 0).

It answers as fast as rclpy allows: spun by the C++ events executor (``run_node(..., events=True)``);
``rclpy.spin(EchoPilot())`` works as well.
"""
from __future__ import annotations

from rclpy.node import Node
from sensor_msgs.msg import JointState

from .interface import MEASUREMENTS, RELIABLE_10
from .parameters import ParamSpec, declare_params
from .spin import run_node
from .topics import STATE, STEERING

__all__ = ["EchoPilot", "main", "steering_msg"]

PARAMS = (ParamSpec("delta", 0.0, "constant steering command (normalized delta)", -1.0, 1.0,
                    unit="dimensionless", runtime=True),)


def steering_msg(stamp, delta: float) -> JointState:
    """The steering command ``delta`` (normalized) answering the state sample stamped ``stamp``."""
    cmd = JointState(name=["delta"], position=[delta])
    cmd.header.stamp = stamp
    return cmd


class EchoPilot(Node):
    """Answers each state sample with ``delta``, stamped with the sample's stamp (lockstep handshake)."""

    def __init__(self, **kwargs):
        super().__init__("echo_pilot", **kwargs)
        self.delta = declare_params(self, PARAMS, apply=self.apply_params)["delta"]
        self.pub = self.create_publisher(JointState, STEERING, MEASUREMENTS)
        self.create_subscription(JointState, STATE, self.state_callback, RELIABLE_10)
        self.answered = 0

    def apply_params(self, changes: dict) -> None:
        """Runtime parameter ``delta``: the next answers carry the new command."""
        self.delta = changes["delta"]

    def state_callback(self, msg: JointState) -> None:
        """A state sample: answer it with ``delta`` and the sample's stamp."""
        self.pub.publish(steering_msg(msg.header.stamp, self.delta))
        self.answered += 1


def main(args=None) -> None:
    raise SystemExit(run_node(EchoPilot, args, events=True))


if __name__ == "__main__":
    main()
