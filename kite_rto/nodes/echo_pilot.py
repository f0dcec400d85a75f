"""Echo pilot: the minimal answering client. Answers every /kite/state sample with a constant steering command.

Used to fly the plant in lockstep with neutral steering (the first check of a new install) and by the DDS
lockstep benchmark. Parameter ``delta`` (normalized, [-1, 1], default 0).
"""
from __future__ import annotations

from rclpy.node import Node
from sensor_msgs.msg import JointState

from .common import RELIABLE_10, ParamSpec, declare_params, run_node
from .topics import STATE, STEERING

__all__ = ["EchoPilot", "main"]

PARAMS = (ParamSpec("delta", 0.0, "constant steering command, normalized", -1.0, 1.0),)


class EchoPilot(Node):
    """Answers each state sample with ``delta``, stamped with the sample's stamp (lockstep handshake)."""

    def __init__(self, **kwargs):
        super().__init__("echo_pilot", **kwargs)
        self.delta = declare_params(self, PARAMS)["delta"]
        self.pub = self.create_publisher(JointState, STEERING, RELIABLE_10)
        self.create_subscription(JointState, STATE, self.state_callback, RELIABLE_10)
        self.answered = 0

    def state_callback(self, msg: JointState) -> None:
        cmd = JointState()
        cmd.header.stamp = msg.header.stamp
        cmd.name = ["delta"]
        cmd.position = [self.delta]
        self.pub.publish(cmd)
        self.answered += 1


def main(args=None) -> None:
    raise SystemExit(run_node(EchoPilot, args))


if __name__ == "__main__":
    main()
