"""Helpers for node tests over real DDS: start node processes, probe topics from an in-process node."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

NODE_MODULES = {"plant": "kite_rto.nodes.plant_node", "echo_pilot": "kite_rto.nodes.echo_pilot",
                "controller": "kite_rto.nodes.controller_node", "optimizer": "kite_rto.nodes.optimizer_node"}


def start_node(name: str, params: dict | None = None, env=None) -> subprocess.Popen:
    """Start ``ros2 run kite_rto <name>``'s entry point as a subprocess with ``-p`` overrides."""
    cmd = [sys.executable, "-m", NODE_MODULES[name], "--ros-args"]
    for k, v in (params or {}).items():
        val = str(v).lower() if isinstance(v, bool) else str(v)
        cmd += ["-p", f"{k}:={val}"]
    return subprocess.Popen(cmd, env=env or dict(os.environ), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True)


def stop(proc: subprocess.Popen, timeout: float = 10.0) -> str:
    """SIGINT the process (like Ctrl-C), wait, kill if needed; return its output."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
    return out or ""


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
