"""Helpers for node tests over real DDS: start node processes, probe topics from an in-process node."""
from __future__ import annotations

import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

# The same launcher the demo uses: ``ros2 run kite_rto <name>``'s entry point in its own process.
from kite_rto.tools.graph import start_node, stop_node as stop  # noqa: E402,F401


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
