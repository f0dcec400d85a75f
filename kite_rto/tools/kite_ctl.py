"""``kite_ctl``: pause, resume and override the optimizer without a ROS install (what ``ros2 lifecycle`` does).

Calls the optimizer's standard lifecycle services (``/optimizer/get_state``, ``/optimizer/change_state``) and
publishes manual setpoints on ``/rto/manual_setpoints``; ``--namespace /kite2`` (or ``--ros-args -r __ns:=/kite2``)
talks to the optimizer of that graph (``/kite2/optimizer``)::

    kite_ctl state                          # unconfigured | inactive | active | finalized
    kite_ctl configure | activate | deactivate | cleanup | shutdown
    kite_ctl pause                          # = deactivate: hold the setpoints in force
    kite_ctl resume                         # = activate: go on with GMA
    kite_ctl setpoint 33 50 7.5             # theta_0, A_phi, A_theta in deg; only while paused

Exit codes: 0 done, 1 refused (the transition is not possible from the current state, the setpoints are refused:
the reason is printed) or no optimizer answered within ``--timeout`` s, 2 bad command line. Docs: docs/interface.md
*Pausing and overriding the optimizer*.
"""
from __future__ import annotations

import argparse
import math
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import JointState

from ..flight.path import Setpoints
from ..nodes.interface import RELIABLE_10
from ..nodes.namespace import add_namespace_option, tool_ros_args
from ..nodes.topics import MANUAL_SETPOINTS, STATUS

__all__ = ["ALIASES", "COMMANDS", "main"]

TRANSITIONS = ("configure", "activate", "deactivate", "cleanup", "shutdown")
ALIASES = {"pause": "deactivate", "resume": "activate"}
GOALS = {"configure": "inactive", "activate": "active", "deactivate": "inactive", "cleanup": "unconfigured",
         "shutdown": "finalized"}
COMMANDS = ("state", *TRANSITIONS, *ALIASES, "setpoint")


class CtlError(Exception):
    """A refusal or a missing optimizer (exit code 1); the message says which."""


def parse_args(argv) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="kite_ctl", description=__doc__.split("\n\n")[0],
                                epilog="pause = deactivate, resume = activate. Use the ROS_DOMAIN_ID the graph runs "
                                       "in. With a ROS install: ros2 lifecycle set /optimizer deactivate (same "
                                       "services).")
    p.add_argument("command", choices=COMMANDS, help="what to do")
    p.add_argument("values", nargs="*", type=float, help="setpoint: theta_0 A_phi A_theta in deg")
    p.add_argument("--node", default="optimizer", help="the optimizer node's name, relative to the namespace "
                                                         "(default optimizer)")
    add_namespace_option(p)
    p.add_argument("--timeout", type=float, default=10.0, help="wall s to wait for the optimizer (default 10)")
    args = p.parse_args(argv)
    if (args.command == "setpoint") != bool(args.values) or (args.values and len(args.values) != 3):
        p.error("setpoint takes exactly 3 values (theta_0 A_phi A_theta, deg); the other commands none")
    if not args.timeout > 0:
        p.error(f"--timeout {args.timeout}: expected a positive number of seconds")
    return args


class Ctl:
    """A short-lived node that talks to one optimizer."""

    def __init__(self, node_name: str, timeout: float):
        self.node = Node("kite_ctl")
        self.executor = SingleThreadedExecutor(context=self.node.context)
        self.executor.add_node(self.node)
        self.name, self.timeout = node_name.rstrip("/"), timeout

    def spin_until(self, predicate) -> bool:
        end = time.monotonic() + self.timeout
        while not predicate() and time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.05)
        return bool(predicate())

    def call(self, srv_type, service: str, request):
        client = self.node.create_client(srv_type, f"{self.name}/{service}")
        full = self.node.resolve_service_name(f"{self.name}/{service}")
        if not self.spin_until(client.service_is_ready):
            raise CtlError(f"no optimizer answers {full} within {self.timeout:g} s (is it running, in this "
                           "ROS_DOMAIN_ID and namespace? --namespace / --node name another one)")
        future = client.call_async(request)
        if not self.spin_until(future.done):
            raise CtlError(f"{full} did not answer within {self.timeout:g} s")
        return future.result()

    def state(self) -> str:
        return self.call(GetState, "get_state", GetState.Request()).current_state.label

    def transition(self, label: str) -> str:
        before = self.state()
        ok = self.call(ChangeState, "change_state", ChangeState.Request(transition=Transition(label=label))).success
        if not ok:
            raise CtlError(f"{label} refused: the optimizer is {self.state()} (was {before}); see its log")
        return f"{label}: {before} -> {GOALS[label]}"      # not asked again: after shutdown the optimizer exits

    def setpoint(self, deg) -> str:
        """Publish manual setpoints (deg in, rad on the topic) and wait for the optimizer's verdict on /rto/status."""
        status = []
        self.node.create_subscription(DiagnosticArray, STATUS, lambda m: status.append(
            {kv.key: kv.value for kv in m.status[0].values}) if m.status else None, RELIABLE_10)
        pub = self.node.create_publisher(JointState, MANUAL_SETPOINTS, RELIABLE_10)
        if not self.spin_until(lambda: status and pub.get_subscription_count() > 0):
            raise CtlError(f"no optimizer status on {STATUS} or subscriber of {MANUAL_SETPOINTS} within "
                           f"{self.timeout:g} s (is it running, in this ROS_DOMAIN_ID?)")
        seen = int(status[-1].get("manual_received", "0"))
        msg = JointState(name=Setpoints.names(), position=[math.radians(v) for v in deg])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        pub.publish(msg)
        if not self.spin_until(lambda: int(status[-1].get("manual_received", "0")) > seen):
            raise CtlError(f"the optimizer did not report on the setpoints within {self.timeout:g} s")
        note = status[-1].get("manual_setpoints", "")
        if not note.startswith("accepted"):
            raise CtlError(f"setpoints {deg} deg {note or 'refused (see the optimizer log)'}")
        return f"setpoints {note}; GMA continues from them after `kite_ctl resume`"

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.node.destroy_node()


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(remove_ros_args(["kite_ctl", *argv])[1:])
    rclpy.init(args=tool_ros_args("kite_ctl", argv, args.namespace))
    ctl = None
    try:
        ctl = Ctl(args.node, args.timeout)
        cmd = ALIASES.get(args.command, args.command)
        if cmd == "state":
            print(ctl.state())
        elif cmd == "setpoint":
            print(ctl.setpoint(args.values))
        else:
            print(ctl.transition(cmd))
        return 0
    except CtlError as err:
        print(f"kite_ctl: {err}", file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        return 130
    finally:
        if ctl is not None:
            ctl.close()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
