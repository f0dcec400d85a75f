"""Start kite_rto nodes as separate processes (no ROS launch system needed) and stop them cleanly."""
from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import threading

__all__ = ["NodeProcess", "isolated_ros_env", "node_command", "start_node", "stop_node"]

MODULES = {"plant": "kite_rto.nodes.plant_node", "controller": "kite_rto.nodes.controller_node",
           "optimizer": "kite_rto.nodes.optimizer_node", "echo_pilot": "kite_rto.nodes.echo_pilot"}


def node_command(name: str, params: dict | None = None) -> list[str]:
    """The command line of ``ros2 run kite_rto <name> --ros-args -p k:=v ...`` for this interpreter."""
    cmd = [sys.executable, "-m", MODULES[name], "--ros-args"]
    for k, v in (params or {}).items():
        cmd += ["-p", f"{k}:={str(v).lower() if isinstance(v, bool) else v}"]
    return cmd


def start_node(name: str, params: dict | None = None, env=None) -> subprocess.Popen:
    """Start a node in its own process group, output (stdout + stderr) on a text pipe."""
    return subprocess.Popen(node_command(name, params), env=env or dict(os.environ), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)


def stop_node(proc: subprocess.Popen, timeout: float = 10.0) -> str:
    """Ctrl-C the node (SIGINT), wait, kill its process group if it hangs; return its remaining output."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
    return out or ""


def isolated_ros_env(domain_id: int | None = None) -> dict:
    """Set (in os.environ, before rclpy.init) a ROS domain and localhost-only discovery; return the env."""
    if domain_id is None:
        domain_id = int(os.environ.get("ROS_DOMAIN_ID", random.Random(os.getpid()).randint(1, 100)))
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ["PYTHONUNBUFFERED"] = "1"
    return dict(os.environ)


class NodeProcess:
    """One node in its own process, the same entry point as ``ros2 run kite_rto <name>``.

    Its output lines go to ``log`` (a file object) and are kept in ``lines``.
    """

    def __init__(self, name: str, params: dict | None = None, log=None, env=None):
        self.name = name
        self.lines: list[str] = []
        self.proc = start_node(name, params, env)
        self._log = log
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line.rstrip())
            if self._log is not None:
                self._log.write(f"[{self.name}] {line}")
                self._log.flush()

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self, timeout: float = 10.0) -> int:
        """Ctrl-C the node, wait, kill it if it hangs; return its exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
        self._reader.join(timeout=2.0)
        return self.proc.returncode
