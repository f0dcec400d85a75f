"""Helpers for node tests over real DDS: start node processes, probe topics from an in-process node."""
from __future__ import annotations

import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

# The same launcher the demo uses: ``ros2 run kite_rto <name>``'s entry point in its own process.
from kite_rto.testing import launch as _launch
from kite_rto.testing.launch import stop_node as stop  # noqa: E402,F401
from kite_rto.tools import graph as _graph

DIE_WITH_PARENT = _graph._die_with_parent if _graph._PRCTL is not None else None
"""``preexec_fn`` for a test's subprocess: Linux sends it SIGTERM when the test process dies, even by SIGKILL, so
an interrupted or killed test run leaves no node behind to disturb the next run in the same ROS domain (a lockstep
plant whose controller is gone re-publishes its sample until stopped). Start from the main thread."""


def start_node(name: str, params: dict | None = None, env=None, namespace: str | None = None):
    """``kite_rto.testing.launch.start_node`` (``ros2 run kite_rto <name>``'s entry point in its own process group),
    dying with the test process."""
    return _launch.start_node(name, params, env, die_with_parent=True, namespace=namespace)


class Probe:
    """An in-process rclpy node for tests, spun on demand."""

    def __init__(self, name: str = "probe"):
        if not rclpy.ok():
            rclpy.init()
        self.node = Node(name)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)

    def spin_until(self, predicate, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.01)
        return predicate()

    def close(self):
        self.executor.remove_node(self.node)
        self.node.destroy_node()
